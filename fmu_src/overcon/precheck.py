"""The pre-check: which joint reactions are unique, and is the scene's motion unique?

Paper §2.2 and §3.2: a joint's reaction is unique iff span(J) = span(J_X) (+) span(J_-X); the
motion with friction in a set K of joints is unique when Eq. 17 holds for K, i.e. every friction
joint has a unique reaction. The analysis runs at the scene's initial configuration q0 (any
non-singular configuration gives the same answer, paper App. B); a singular q0 is reported.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace

from . import analysis
from .checks import analysed_rows, factored_q0
from .joints import TYPES
from .model import Model
from .spec import frozen_coordinates


def joint_groups(model: Model) -> dict[str, list[int]]:
    """0-based equation (J column) indices per joint name."""
    return {c.name: list(c.rows) for c in model.joints}


AUTO_ALL_JOINTS = 50
"""``methods = "auto"`` runs every test up to this many joints, the one-factorisation test alone
above (decided: the three tests' verdicts and JSON keys stay as they were for the mechanisms of a
usual size, where the cross-check costs well under a second; docs/benchmarks.md, "Input limits")."""


def resolve_methods(model: Model, methods: str = "auto") -> str:
    """``"svd"`` or ``"all"`` for ``methods`` ``"auto"`` (:data:`AUTO_ALL_JOINTS`), else ``methods``."""
    if methods == "auto":
        return "all" if len(model.joints) <= AUTO_ALL_JOINTS else "svd"
    return methods


def analyse_model(model: Model, methods: str = "auto"):
    """The analysis at q0. ``methods``: ``"svd"``, the one-factorisation test (one factorisation
    of the Jacobian for every joint: the joints whose reaction is decided locally peeled off,
    one SVD per independent block of loops left, :func:`overcon.analysis._factorise`),
    ``"all"``, with the rank and QR tests as a cross-check (two SVDs of the Jacobian per joint),
    or ``"auto"`` (:func:`resolve_methods`)."""
    fz = factored_q0(model)  # shared with the elimination's choice when admission made it
    rows = analysed_rows(model)
    if rows is None:
        return analysis.analyse(fz, joint_groups(model), methods=resolve_methods(model, methods))
    # redundancy "compliant": the compliant joints' equations are forces; the rigid rest is analysed
    compliant = compliant_joints(model)
    position = {row: k for k, row in enumerate(rows)}
    groups = {c.name: [position[r] for r in c.rows] for c in model.joints if c.name not in compliant}
    return analysis.analyse(fz, groups, methods=resolve_methods(model, methods))


def compliant_joints(model: Model) -> set[str]:
    """Names of the joints whose equations are compliant (redundancy "compliant"): their
    reactions come from their deformation, so they are unique."""
    rows = set(int(r) for r in model.compliant_rows)
    return {c.name for c in model.joints if rows.intersection(c.rows)}


def frictionless(law) -> bool:
    """A friction law with every coefficient zero (mu = 0, and mu_static 0 or none) exerts no
    friction force at all: such a joint does not count in the motion verdict (Eq. 17 concerns
    joints with friction forces)."""
    return law.mu == 0 and not law.mu_static


def friction_warnings(model: Model) -> list[str]:
    """Warnings (not errors) about the friction set: a friction joint whose constraint equations
    are all eliminated carries lam = 0, so its friction force is exactly zero. That is one
    legitimate outcome of a joint with a non-unique reaction (another elimination gives it a
    reaction and a friction force), so it is not refused, only said (``check``, ``simulate``,
    and the pre-check report's ``warnings`` for the FMU). A friction joint with mu = 0 is said
    too: it does not count in the verdict (:func:`frictionless`)."""
    out = []
    eliminated = set(model.eliminated)
    for j in model.friction_joints:
        c = model.joints[j]
        if frictionless(c.law):
            out.append(f"friction on joint {c.name} has mu = 0: it exerts no friction force and does not count "
                       "in the motion verdict (a scene or FMU that sets mu > 0 there needs the pre-check again)")
            continue
        eqs = [r + 1 for r in c.rows]
        if eliminated.issuperset(eqs):
            out.append(f"friction on joint {c.name}, whose equations {', '.join('Phi%d' % i for i in eqs)} are all "
                       "eliminated: its multipliers are 0, so its friction force is 0 throughout (one outcome "
                       "of a non-unique reaction; keep one of its equations to give it a reaction)")
    return out


def redundancy_warnings(model: Model) -> list[str]:
    """Under a redundancy method other than "eliminate", a scene's ``eliminate`` does not apply:
    said, not refused (a scene group switches method by one line)."""
    sc = model.scene
    if sc.redundancy == "eliminate" or sc.eliminate in ((), "auto"):
        return []
    listed = ", ".join(f"Phi{i}" if isinstance(i, int) else str(i) for i in sc.eliminate)
    return [f"scene.eliminate ({listed}) does not apply under redundancy = {sc.redundancy!r}, which chooses "
            "the equations itself"]


@dataclass(frozen=True)
class JointVerdict:
    """Pre-check verdict of one joint: its reaction is ``unique`` (all three tests ``methods``
    {rank, svd, qr} say so when they ``agree``); ``rank_defect`` = rank(J_X) + rank(J_-X) -
    rank(J)."""

    name: str
    unique: bool
    methods: dict[str, bool]
    rank_defect: int
    agree: bool
    type: str
    equations: tuple[int, ...] = ()  # its 1-based equation numbers (Phi_k, what ``eliminate`` counts)


@dataclass(frozen=True)
class PrecheckResult:
    """The pre-check of a scene (typed; :meth:`to_json` is the ``check --json`` document, its keys
    in this field order). ``problems`` are human-readable reasons against uniqueness;
    ``warnings`` do not affect the verdict (:func:`friction_warnings`)."""

    n_coordinates: int
    n_equations: int
    rank: int
    dof: int
    redundant: int
    joints: tuple[JointVerdict, ...]
    file: str
    scene: str
    kind: str
    methods_agree: bool
    friction: tuple[str, ...]
    friction_on_nonunique: tuple[str, ...]
    friction_set_unique: bool
    motion_unique: bool
    eliminated: tuple[int, ...]
    elimination_mode: str
    problems: tuple[str, ...]
    warnings: tuple[str, ...]
    methods_run: tuple[str, ...] = ("rank", "svd", "qr")  # the tests that ran (each joint's ``methods`` keys)
    redundancy: str = "eliminate"  # the scene's method (spec.REDUNDANCY_METHODS); the verdicts are the rigid theory's
    drivers: tuple[str, ...] = ()  # scene [[drivers]]: their equations are in the numbers and the joints above
    effort_unique: bool = True  # every driver's effort is unique (effort_verdicts)

    def to_json(self) -> dict:
        """JSON-ready dict (lists, plain types), keys in field order."""
        return _plain(self)

    @property
    def reaction_unique(self) -> dict[str, bool]:
        """Joint name -> its reaction is unique."""
        return {j.name: j.unique for j in self.joints}


def _plain(x):
    """Dataclasses to dicts (keys in field order), tuples to lists, recursively: the JSON
    document's types (``dataclasses.asdict`` with tuples as lists, without its deep copies of
    the leaves, which are immutable here: a 10,000-joint report spent 0.4 s in them)."""
    if isinstance(x, (PrecheckResult, JointVerdict)):
        return {name: _plain(getattr(x, name)) for name in _FIELDS[type(x)]}
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x


_FIELDS = {cls: tuple(f.name for f in fields(cls)) for cls in (PrecheckResult, JointVerdict)}


def precheck(model: Model, source: str = "", methods: str = "auto") -> PrecheckResult:
    """The pre-check of ``model`` (``source``: the file name reported; ``methods``: see
    :func:`analyse_model`)."""
    res = analyse_model(model, methods)
    summary = analysis.to_json(res)
    # a particle's frozen orientation (spec.BodySpec) is no coordinate of the mechanism: its
    # columns of the Jacobian are zero, so the rank stays and the count and DOF leave it out
    frozen = frozen_coordinates(model.scene.mechanism)
    summary["n_coordinates"] -= frozen
    summary["dof"] -= frozen
    types = {c.name: "driver" if c.type == "driver" else TYPES[c.type].name for c in model.joints}  # the files'
    verdicts = {j["name"]: JointVerdict(type=types[j["name"]], **j) for j in summary.pop("joints")}
    # under redundancy "compliant" the numbers and verdicts are the rigid joints' (the compliant
    # joints' equations are forces there); a compliant joint's reaction is unique (no tests run)
    compliant = compliant_joints(model)
    joints = tuple(replace(verdicts.get(c.name) or JointVerdict(c.name, True, {}, 0, True, types[c.name]),
                           equations=tuple(r + 1 for r in c.rows))
                   for c in model.joints)
    friction = [model.joints[j].name for j in model.friction_joints]
    acting = [model.joints[j].name for j in model.friction_joints if not frictionless(model.joints[j].law)]
    nonunique = [name for name in acting if name not in compliant and not res.joints[name].unique]
    acting = [name for name in acting if name not in compliant]
    problems = []
    for name in nonunique:
        v = res.joints[name]
        problems.append(
            f"friction on joint {name}, whose reaction is not unique: its Jacobian columns are not "
            f"a direct summand of span(J) (rank(J_X) + rank(J_-X) - rank(J) = {v.rank_defect}); the "
            "friction force, and so the motion, can depend on which redundant equation is eliminated (it does "
            "whenever the loads reach the non-unique part of the reaction)")
    disagree = [j.name for j in joints if not j.agree]
    for name in disagree:
        problems.append(f"joint {name}: the rank, SVD and QR tests disagree {res.joints[name].methods}")
    set_unique = True
    if acting:
        set_unique = bool(res.set_unique(acting).unique)
    drivers, efforts = effort_verdicts(model, res, nonunique, set_unique)
    for d, why in efforts.items():
        problems.append(f"effort not unique: driver {d}: {why}")
    return PrecheckResult(
        drivers=tuple(drivers), effort_unique=not efforts,
        **summary, joints=joints, file=source, scene=model.scene.name, kind=model.kind,
        methods_agree=not disagree, friction=tuple(friction), friction_on_nonunique=tuple(nonunique),
        friction_set_unique=set_unique,
        motion_unique=(not nonunique and set_unique) or bool(drivers and summary["dof"] == 0),
        eliminated=tuple(model.eliminated), elimination_mode=model.elimination_mode,
        problems=tuple(problems), warnings=tuple(friction_warnings(model) + redundancy_warnings(model)),
        methods_run=analysis.METHOD_SETS[resolve_methods(model, methods)], redundancy=model.scene.redundancy)


def effort_verdicts(model: Model, res, nonunique: list[str], set_unique: bool) -> tuple[list[str], dict[str, str]]:
    """(the drivers, driver -> why its effort is not unique) (decided, issue 38: under a drive the
    prescribed motion leaves the multipliers to carry the elimination's choice): a driver's effort,
    the multiplier of its equation, depends on the elimination when its own column is not a direct
    summand of span(J) (its reaction is not unique), or when friction acts on a joint whose reaction
    is not unique (the friction force then depends on the elimination, and the effort balances it)."""
    drivers = [c for c in model.joints if c.type == "driver"]
    out = {}
    for c in drivers:
        joint = model.joints[c.p["joint"]].name
        if not res.joints[c.name].unique:
            out[c.name] = (f"its equation on joint {joint} is not a direct summand of span(J): the effort depends "
                           "on the eliminated equations")
        elif nonunique or not set_unique:
            names = ", ".join(nonunique) or "the friction joints together"
            out[c.name] = (f"on joint {joint}, friction on joint(s) {names}, whose reaction is not unique, makes "
                           "the effort depend on which redundant equation is eliminated")
    return [c.name for c in drivers], out


def motion_verdict(result: PrecheckResult) -> str:
    """The verdict line of ``check`` (also the first warning of ``simulate`` when not unique)."""
    if result.drivers and result.dof == 0:
        return ("motion prescribed by the drivers (DOF 0: a kinematic analysis): unique; with friction on a "
                "non-unique reaction the efforts depend on the elimination instead")
    if not result.friction:
        return "no friction: motion unique (reactions of non-unique joints depend on the elimination)"
    verdict = "UNIQUE" if result.motion_unique else "NOT UNIQUE (depends on the elimination)"
    return f"motion with friction in {', '.join(result.friction)}: {verdict}"


def run_warnings(result: PrecheckResult) -> list[str]:
    """What ``overcon simulate`` says on stderr before a run (decided: the run still goes ahead,
    exit 0, because a non-unique motion is one legitimate motion of the scene): the verdict and
    the problems when the motion is not unique or the tests disagree (the same text as
    ``check``), naming the elimination the run uses, then the pre-check's warnings."""
    out = []
    if not result.motion_unique or not result.methods_agree:
        eliminated = ", ".join("Phi%d" % i for i in result.eliminated) or "none"
        if result.elimination_mode == "min-norm":
            out.append(f"{motion_verdict(result)}: this run uses the minimum-norm multipliers (redundancy = "
                       "'min-norm'): one motion, chosen without physical ground; the eliminations give others")
        else:
            out.append(f"{motion_verdict(result)}: this run shows the motion with {eliminated} eliminated "
                       f"({result.elimination_mode}); another elimination can give another motion")
        out += list(result.problems)
    return out + list(result.warnings)


def _equations_text(eqs) -> str:
    """A joint's 1-based equations for the table: ``3``, or ``3-5`` (a joint's are consecutive)."""
    if not eqs:
        return "-"
    return str(eqs[0]) if len(eqs) == 1 else f"{eqs[0]}-{eqs[-1]}"


def format_table(result: PrecheckResult) -> str:
    """The human-readable table of ``check`` (from the JSON document of ``result``)."""
    report = result.to_json()
    lines = [
        f"{report['file'] or report['scene']}: {report['kind']} mechanism, "
        f"{report['n_coordinates']} coordinates, {report['n_equations']} equations, rank {report['rank']}, "
        f"DOF {report['dof']}, {report['redundant']} redundant",
        f"eliminated: {', '.join('Phi%d' % i for i in report['eliminated']) or 'none'} ({report['elimination_mode']})",
        "",
    ]
    w = max([10, *(len(j["name"]) for j in report["joints"])])  # 10, or the longest name
    eqs = {j["name"]: _equations_text(j["equations"]) for j in report["joints"]}
    we = max([9, *(len(e) for e in eqs.values())])
    lines.append(f"{'joint':<{w}} {'type':<14} {'equations':<{we}} {'unique':<7} {'rank':<6} {'svd':<6} {'qr':<6} "
                 "friction")
    yn = {True: "yes", False: "no"}
    for j in report["joints"]:
        m = {k: yn[v] for k, v in j["methods"].items()}  # a test that did not run: "-"
        fr = "ON" if j["name"] in report["friction"] else ""
        flag = "  <-- friction on a non-unique reaction" if j["name"] in report["friction_on_nonunique"] else ""
        if report["redundancy"] == "compliant" and not j["methods"]:
            flag += "  (compliant: its reaction comes from its deformation)"
        lines.append(f"{j['name']:<{w}} {j['type']:<14} {eqs[j['name']]:<{we}} {yn[j['unique']]:<7} "
                     f"{m.get('rank', '-'):<6} "
                     f"{m.get('svd', '-'):<6} {m.get('qr', '-'):<6} {fr}{flag}")
    lines.append("")
    lines.append(motion_verdict(result))
    for d in result.drivers:
        bad = [p for p in result.problems if p.startswith(f"effort not unique: driver {d}:")]
        lines.append(f"driver {d}: effort {'NOT UNIQUE (depends on the elimination)' if bad else 'UNIQUE'}")
    if result.redundancy == "min-norm" and result.friction:
        lines.append("redundancy = 'min-norm': the runs use the minimum-norm multipliers, one motion chosen without "
                     "physical ground (the verdict above is the rigid theory's)")
    lines += [f"problem: {p}" for p in report["problems"]]
    lines += [f"warning: {p}" for p in report.get("warnings", [])]
    return "\n".join(lines)
