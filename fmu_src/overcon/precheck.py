"""The pre-check: which joint reactions are unique, and is the scene's motion unique?

Paper §2.2 and §3.2: a joint's reaction is unique iff span(J) = span(J_X) (+) span(J_-X); the
motion with friction in a set K of joints is unique when Eq. 17 holds for K, i.e. every friction
joint has a unique reaction. The analysis runs at the scene's initial configuration q0 (any
non-singular configuration gives the same answer, paper App. B); a singular q0 is reported.
"""
from __future__ import annotations

from . import analysis
from .model import Model, frames, jacobian_h


def joint_groups(model: Model) -> dict[str, list[int]]:
    """0-based equation (J column) indices per joint name."""
    return {c.name: list(c.rows) for c in model.joints}


def analyse_model(model: Model):
    f = frames(model, model.q0, model.h0)
    J = jacobian_h(model, f).T
    return analysis.analyse(J, joint_groups(model))


def friction_warnings(model: Model) -> list[str]:
    """Warnings (not errors) about the friction set: a friction joint whose constraint equations
    are all eliminated carries lam = 0, so its friction force is exactly zero. That is one
    legitimate outcome of a joint with a non-unique reaction (another elimination gives it a
    reaction and a friction force), so it is not refused, only said (``check``, ``simulate``,
    and the pre-check report's ``warnings`` for the FMU)."""
    out = []
    eliminated = set(model.eliminated)
    for j in model.friction_joints:
        c = model.joints[j]
        eqs = [r + 1 for r in c.rows]
        if eliminated.issuperset(eqs):
            out.append(f"friction on joint {c.name}, whose equations {', '.join('Phi%d' % i for i in eqs)} are all "
                       "eliminated: its multipliers are 0, so its friction force is 0 throughout (one outcome "
                       "of a non-unique reaction; keep one of its equations to give it a reaction)")
    return out


def precheck(model: Model, source: str = "") -> dict:
    """JSON-ready report. Keys: file, scene, kind, n_coordinates, n_equations, rank, dof,
    redundant, joints (name, type, unique, methods {rank, svd, qr}, rank_defect, agree),
    methods_agree, friction, friction_on_nonunique, friction_set_unique, motion_unique,
    eliminated, elimination_mode, problems (human-readable reasons), warnings (human-readable,
    not affecting the verdict: :func:`friction_warnings`)."""
    res = analyse_model(model)
    report = analysis.to_json(res)
    types = {c.name: c.type for c in model.joints}
    for j in report["joints"]:
        j["type"] = types[j["name"]]
    friction = [model.joints[j].name for j in model.friction_joints]
    nonunique = [name for name in friction if not res.joints[name].unique]
    problems = []
    for name in nonunique:
        v = res.joints[name]
        problems.append(
            f"friction on joint {name}, whose reaction is not unique: its Jacobian columns are not "
            f"a direct summand of span(J) (rank(J_X) + rank(J_-X) - rank(J) = {v.rank_defect}); the "
            "friction force, and so the motion, depends on which redundant equation is eliminated")
    disagree = [j["name"] for j in report["joints"] if not j["agree"]]
    for name in disagree:
        problems.append(f"joint {name}: the rank, SVD and QR tests disagree {res.joints[name].methods}")
    set_unique = True
    if friction:
        sv = res.set_unique(friction)
        set_unique = bool(sv.unique)
    report.update({
        "file": source, "scene": model.scene.name, "kind": model.kind,
        "methods_agree": not disagree, "friction": friction, "friction_on_nonunique": nonunique,
        "friction_set_unique": set_unique, "motion_unique": not nonunique and set_unique,
        "eliminated": list(model.eliminated), "elimination_mode": model.elimination_mode,
        "problems": problems, "warnings": friction_warnings(model),
    })
    return report


def format_table(report: dict) -> str:
    lines = [
        f"{report['file'] or report['scene']}: {report['kind']} mechanism, "
        f"{report['n_coordinates']} coordinates, {report['n_equations']} equations, rank {report['rank']}, "
        f"DOF {report['dof']}, {report['redundant']} redundant",
        f"eliminated: {', '.join('Phi%d' % i for i in report['eliminated']) or 'none'} ({report['elimination_mode']})",
        "",
    ]
    w = max([10, *(len(j["name"]) for j in report["joints"])])  # 10, or the longest name
    lines.append(f"{'joint':<{w}} {'type':<14} {'unique':<7} {'rank':<6} {'svd':<6} {'qr':<6} friction")
    yn = {True: "yes", False: "no"}
    for j in report["joints"]:
        m = j["methods"]
        fr = "ON" if j["name"] in report["friction"] else ""
        flag = "  <-- friction on a non-unique reaction" if j["name"] in report["friction_on_nonunique"] else ""
        lines.append(f"{j['name']:<{w}} {j['type']:<14} {yn[j['unique']]:<7} {yn[m['rank']]:<6} "
                     f"{yn[m['svd']]:<6} {yn[m['qr']]:<6} {fr}{flag}")
    lines.append("")
    if report["friction"]:
        verdict = "UNIQUE" if report["motion_unique"] else "NOT UNIQUE (depends on the elimination)"
        lines.append(f"motion with friction in {', '.join(report['friction'])}: {verdict}")
    else:
        lines.append("no friction: motion unique (reactions of non-unique joints depend on the elimination)")
    lines += [f"problem: {p}" for p in report["problems"]]
    lines += [f"warning: {p}" for p in report.get("warnings", [])]
    return "\n".join(lines)
