"""What the tooling needs to know about an FMU before running it, read without loading its binary.

From ``modelDescription.xml`` (fmpy's reader): model identifier, DefaultExperiment, the Real
outputs with their units, and the Boolean verdicts an overcon FMU carries (constants, or discrete outputs whose start value is the pre-check's)
(``motion_unique``, ``<joint>.reaction_unique``: the pre-check's predictions). From an overcon
FMU's facts record ``resources/overcon_facts.json`` (:mod:`overcon.fmu.facts`, versioned): group,
friction set, eliminated equations, mechanism and predictions, and the paper-style label
(:func:`overcon.verdict.variant_label`). FMUs of other tools (no ``resources/overcon_fmu.json``)
form one group, :data:`OTHER_GROUP`, are labelled with their model name and carry no prediction;
an overcon FMU without a readable facts record of this format is refused, naming the file.

An FMU is untrusted input (docs/untrusted-input.md): before anything is read from it, the archive's
file count and total uncompressed size are checked against :func:`archive_limits` (defaults
:data:`MAX_UNZIPPED_MB` MiB and :data:`MAX_UNZIPPED_FILES` files; ``--max-unzipped-mb`` and
``--max-unzipped-files`` of run and compare raise them), its entry names must stay inside the
archive, and its ``modelIdentifier`` must be an identifier (the FMI standard requires a C
identifier; file names are made from it): else :class:`InputError` (exit 2). :func:`extract`
unzips it under those checks.
"""
from __future__ import annotations

import os
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

from . import InputError

POSITION_UNITS = ("m", "rad")
QUATERNION_SUFFIXES = (".e0", ".e1", ".e2", ".e3")
"""Dimensionless (unit "1") outputs with these suffixes are the orientation quaternions of
spatial bodies with ``rotation = "quaternion"``: positions too (they decide a verdict)."""
OTHER_GROUP = "fmus"  # the group of FMUs without an overcon scene (other tools): compared together
REACTION_UNITS = ("N", "N.m")
MAX_UNZIPPED_MB = 2048  # an overcon FMU is a few MB; a foreign one with large resources fits too
MAX_UNZIPPED_FILES = 10_000
LIMIT_ENV = ("OVERCON_MAX_UNZIPPED_MB", "OVERCON_MAX_UNZIPPED_FILES")  # set by the flags, read by the workers too
IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def archive_limits() -> tuple[int, int]:
    """(bytes, files) an FMU archive may unzip to: the defaults, or the flags' values (passed on
    to the worker processes in the environment, :data:`LIMIT_ENV`)."""
    mb = float(os.environ.get(LIMIT_ENV[0]) or MAX_UNZIPPED_MB)
    files = int(os.environ.get(LIMIT_ENV[1]) or MAX_UNZIPPED_FILES)
    return int(mb * 1024 * 1024), files


def check_archive(path: Path, zf: zipfile.ZipFile) -> None:
    """:class:`InputError` for an archive over the limits or with an entry outside itself."""
    max_bytes, max_files = archive_limits()
    infos = zf.infolist()
    if len(infos) > max_files:
        raise InputError(f"{path}: {len(infos)} files in the archive, more than the limit of {max_files} "
                         "(--max-unzipped-files raises it)")
    total = sum(i.file_size for i in infos)
    if total > max_bytes:
        raise InputError(f"{path}: unzips to {total / 2 ** 20:.1f} MiB, more than the limit of "
                         f"{max_bytes / 2 ** 20:g} MiB (--max-unzipped-mb raises it)")
    for i in infos:
        parts = i.filename.replace("\\", "/").split("/")
        if i.filename.startswith(("/", "\\")) or ".." in parts or ":" in parts[0]:
            raise InputError(f"{path}: archive entry {i.filename!r} points outside the FMU")


def extract(path, dest) -> Path:
    """The FMU ``path`` unzipped into the directory ``dest`` (made by the caller, who removes it),
    after :func:`check_archive`; zipfile stops every entry at its declared size."""
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as zf:
            check_archive(path, zf)
            zf.extractall(dest)
    except zipfile.BadZipFile as exc:
        raise InputError(f"{path}: corrupt FMU archive: {exc}") from exc
    return Path(dest)


@dataclass(frozen=True)
class Output:
    """A Real output. ``kind``: "position" (unit m or rad, or a quaternion component
    :data:`QUATERNION_SUFFIXES` of unit 1), "reaction" (N or N.m) or "other"."""

    name: str
    unit: str | None
    kind: str

    @property
    def joint(self) -> str:
        return self.name.rsplit(".", 1)[0]


@dataclass(frozen=True)
class FmuInfo:
    path: Path
    model: str  # co-simulation model identifier (= scene name for overcon FMUs)
    start: float
    stop: float
    step: float | None  # DefaultExperiment stepSize (None: not given)
    tolerance: float | None  # DefaultExperiment tolerance
    outputs: tuple[Output, ...]
    group: str
    label: str  # legend label, e.g. "without eq. 4"
    mechanism: str = ""
    friction: tuple[str, ...] = ()
    eliminate: tuple[int, ...] | str | None = None
    motion_unique: bool | None = None  # pre-check prediction (None: not an overcon FMU)
    effort_unique: bool | None = None  # a driven scene's prediction for its efforts (None: no drivers)
    reaction_unique: dict = field(default_factory=dict)  # joint -> bool
    # parameters solver.method and solver.step: can run on the lockstep grid (rk4); an overcon FMU
    # with inputs refuses rk4 (its fixed steps could step over the instant an input changes)
    lockstep: bool = False
    parameters: dict = field(default_factory=dict)  # causality parameter: name -> FMI type (Real, Integer, ...)
    inputs: dict = field(default_factory=dict)  # causality input: name -> FMI type (an --input table sets the Real ones)
    enumerations: dict = field(default_factory=dict)  # Enumeration parameters: name -> {item name: value}
    fmi_version: str = "2.0"
    can_interpolate_inputs: bool = False  # FMI 2.0 co-simulation's canInterpolateInputs (input derivatives)

    @property
    def real_inputs(self) -> list[str]:
        """The Real (Float64) inputs, in the model's order: the columns of an ``--input`` table."""
        return [n for n, t in self.inputs.items() if t == "Real"]

    @property
    def output_names(self) -> list[str]:
        return [o.name for o in self.outputs]

    def eliminate_text(self) -> str:
        if self.eliminate is None:
            return ""
        if self.eliminate == "auto":
            return "auto"
        return ", ".join(f"Φ{k}" for k in self.eliminate) or "none"


def fmu_paths(paths) -> list[Path]:
    """FMU files given, and the ``*.fmu`` files of directories given (sorted, not recursive)."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(p.glob("*.fmu"))
            if not found:
                raise InputError(f"{p}: directory contains no .fmu files")
            out.extend(found)
        else:
            out.append(p)
    return out


def _bool(text) -> bool | None:
    if text is None:
        return None
    return str(text).strip().lower() in ("true", "1")


def _overcon_facts(path: Path, zf: zipfile.ZipFile) -> dict:
    """Group, label, friction, eliminate, mechanism and the predictions from an overcon FMU's facts
    record (:mod:`overcon.fmu.facts`); ``{}`` for an FMU of another tool (no ``resources/overcon_fmu.json``).
    An overcon FMU without the record (built by an older overcon) or with a record of another
    format is refused with :class:`InputError`: its facts cannot be read."""
    from ..fmu import facts as facts_mod
    from ..verdict import variant_label

    names = set(zf.namelist())
    if facts_mod.PATH not in names:
        if facts_mod.MANIFEST in names:
            raise InputError(f"{path}: an overcon FMU without its facts record {facts_mod.PATH} (built by an "
                             "older overcon): rebuild it with this overcon (overcon build)")
        return {}
    try:
        facts = facts_mod.decode(zf.read(facts_mod.PATH), str(path))
    except facts_mod.FactsError as exc:
        raise InputError(str(exc)) from exc
    return dict(facts, label=variant_label(facts["eliminate"], facts["equation_joints"]))


_FMI2_TYPE = {"Float64": "Real", "Float32": "Real", "Int8": "Integer", "UInt8": "Integer", "Int16": "Integer",
              "UInt16": "Integer", "Int32": "Integer", "UInt32": "Integer", "Int64": "Integer", "UInt64": "Integer"}


def type_name(variable) -> str:
    """The FMI 2.0 type name (Real, Integer, Boolean, String) of an fmpy model variable of FMI 2.0 or
    3.0 (Float64 is Real, the integer types Integer): the tooling speaks FMI 2.0's names."""
    return _FMI2_TYPE.get(variable.type, variable.type)


def interface(md) -> str:
    """The interface the tooling runs an FMU through: co-simulation where the FMU offers it, else
    Model Exchange (fmpy integrates it, with CVode by default)."""
    return "CoSimulation" if md.coSimulation is not None else "ModelExchange"


def inspect_fmu(path) -> FmuInfo:
    """Read an FMU's description (FMI 2.0 or 3.0); :class:`InputError` naming the file if it is
    missing, not a zip archive, has no readable modelDescription.xml, offers neither co-simulation
    nor Model Exchange or has no Real outputs. Array variables (FMI 3.0) are not recorded: their
    elements are scalar outputs of their own."""
    from fmpy import read_model_description

    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such FMU file")
    if not path.is_file():
        raise InputError(f"{path}: not a file")
    if not zipfile.is_zipfile(path):
        raise InputError(f"{path}: not an FMU (not a zip archive; corrupt or truncated file?)")
    try:
        with zipfile.ZipFile(path) as zf:
            check_archive(path, zf)
    except zipfile.BadZipFile as exc:
        raise InputError(f"{path}: corrupt FMU archive: {exc}") from exc
    try:
        md = read_model_description(str(path), validate=False)
    except Exception as exc:  # fmpy raises plain Exceptions, lxml errors, KeyError, BadZipFile
        raise InputError(f"{path}: cannot read modelDescription.xml: {type(exc).__name__}: {exc}") from exc
    if md.coSimulation is None and md.modelExchange is None:
        raise InputError(f"{path}: neither co-simulation nor Model Exchange (only those FMUs are run)")
    outputs, constants, params, inputs, enums = [], {}, {}, {}, {}
    for v in md.modelVariables:
        typ = type_name(v)
        if v.causality == "parameter":
            params[v.name] = typ
            if typ == "Enumeration" and v.declaredType is not None:
                enums[v.name] = {i.name: int(i.value) for i in v.declaredType.items
                                 if str(i.value).lstrip("-").isdigit()}
        if v.causality == "input" and not getattr(v, "dimensions", None):
            inputs[v.name] = typ
        if v.causality != "output" or getattr(v, "dimensions", None):
            continue
        if typ == "Real" and v.variability != "constant":
            unit = v.unit or (v.declaredType.unit if v.declaredType is not None else None)
            position = unit in POSITION_UNITS or (unit == "1" and v.name.endswith(QUATERNION_SUFFIXES))
            kind = "position" if position else "reaction" if unit in REACTION_UNITS else "other"
            outputs.append(Output(v.name, unit, kind))
        elif typ == "Boolean" and (v.variability == "constant" or v.start is not None):
            # the pre-check's verdicts: constants, or (FMUs that judge them along the motion)
            # discrete outputs whose start value is the pre-check's at t = 0
            constants[v.name] = _bool(v.start)
    if not outputs:
        raise InputError(f"{path}: the FMU has no Real outputs to record")
    if "effort_unique" in constants:  # a driven scene: its drivers' efforts (N or N.m) decide a group
        outputs = [Output(o.name, o.unit, "effort") if o.name.endswith(".effort") else o for o in outputs]
    ex = md.defaultExperiment
    start = float(ex.startTime) if ex is not None and ex.startTime is not None else 0.0
    stop = float(ex.stopTime) if ex is not None and ex.stopTime is not None else start + 1.0
    step = float(ex.stepSize) if ex is not None and ex.stepSize is not None else None
    tol = float(ex.tolerance) if ex is not None and ex.tolerance is not None else None
    try:
        with zipfile.ZipFile(path) as zf:
            facts = _overcon_facts(path, zf)
    except zipfile.BadZipFile as exc:
        raise InputError(f"{path}: corrupt FMU archive: {exc}") from exc
    model = (md.coSimulation or md.modelExchange).modelIdentifier
    if not isinstance(model, str) or not IDENTIFIER.match(model):
        raise InputError(f"{path}: modelIdentifier {model!r} is not an identifier (letters, digits and _, not "
                         "starting with a digit, as the FMI standard requires): refused, the output file names "
                         "are made from it")
    reaction_unique = {name[: -len(".reaction_unique")]: val for name, val in constants.items()
                       if name.endswith(".reaction_unique")} or facts.get("reaction_unique", {})
    motion_unique = constants.get("motion_unique", facts.get("motion_unique"))
    return FmuInfo(path=path, model=model, start=start, stop=stop, step=step, tolerance=tol,
                   outputs=tuple(outputs), group=facts.get("group", OTHER_GROUP), label=facts.get("label", model),
                   mechanism=facts.get("mechanism", ""), friction=facts.get("friction", ()),
                   eliminate=facts.get("eliminate"), motion_unique=motion_unique,
                   effort_unique=constants.get("effort_unique"),
                   reaction_unique=reaction_unique,
                   lockstep=(params.get("solver.method") == "String" and params.get("solver.step") == "Real"
                             and not (facts and any(t == "Real" for t in inputs.values()))),
                   parameters=params, inputs=inputs, fmi_version=str(md.fmiVersion),
                   can_interpolate_inputs=bool(md.coSimulation is not None and md.fmiVersion.startswith("2")
                                               and getattr(md.coSimulation, "canInterpolateInputs", False)),
                   enumerations=enums)


def inspect_all(paths) -> list[FmuInfo]:
    """:func:`inspect_fmu` for every FMU of :func:`fmu_paths`; all problems in one InputError."""
    infos, problems = [], []
    for p in fmu_paths(paths):
        try:
            infos.append(inspect_fmu(p))
        except InputError as exc:
            problems.append(str(exc))
    if problems:
        raise InputError("\n".join(problems))
    if not infos:
        raise InputError("no FMU given")
    return infos
