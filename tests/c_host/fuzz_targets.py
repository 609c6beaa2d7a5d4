"""The FMUs the state fuzzer (tests/c_host/fuzz_fmu.c) runs on, and its arguments.

One FMU per integrator (the paper's planar_f45_wo4 with dopri5, dop853, rk4 and radau) and the
quaternion door (door_h1_wo_hinge2), built for the C runtime. ``fuzz_args(unzipdir)`` gives the
arguments after SECONDS: ``-p VR:LO:HI`` for every Real parameter with its rule's range
(overcon.params.RULES: an accepted state must hold parameters within them), ``-b VR`` of
solver.max_wall_time, ``-v VR`` of the first output (the bits compared after a refused state).

Used by ci/sanitize.sh (``python tests/c_host/fuzz_targets.py OUT``: builds the FMUs into OUT and
prints one line per FMU: ``id guid args...``) and by tests/test_untrusted.py.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MECH = ROOT / "mechanisms"
TARGETS = ("f45_dopri5", "f45_dop853", "f45_rk4", "f45_radau", "door_h1_wo_hinge2")


def scenes(out: Path) -> list[Path]:
    """The scene files of TARGETS, written into out (the integrator in each one's [solver])."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "planar_sliders.toml").write_text((MECH / "planar_sliders.toml").read_text())
    text = (MECH / "planar_f45_wo4.toml").read_text()
    paths = []
    for method in ("dopri5", "dop853", "rk4", "radau"):
        p = out / f"f45_{method}.toml"
        p.write_text(text.replace('name = "planar_f45_wo4"', f'name = "f45_{method}"')
                     .replace("[solver]", f'[solver]\nmethod = "{method}"'))
        paths.append(p)
    return paths + [MECH / "examples" / "door_h1_wo_hinge2.toml"]


def build(out: Path) -> dict[str, Path]:
    """TARGETS built (runtime c) into out/fmus; their .fmu paths by id."""
    from overcon.fmu.build import build_all
    lines: list[str] = []
    code, results = build_all([str(p) for p in scenes(out / "scenes")], out / "fmus", refs=False, validate=False,
                              runtime="c", allow_nonunique=True, echo=lines.append, echo_err=lines.append)
    if code:
        raise RuntimeError("\n".join(lines))
    return {r.name: r.fmu for r in results}


def fuzz_args(unzipdir: Path) -> tuple[str, list[str]]:
    """The GUID and the fuzzer's options for the unzipped FMU."""
    import fmpy
    from overcon.params import RULES
    md = fmpy.read_model_description(str(unzipdir))
    args: list[str] = []
    first_output = None
    for v in md.modelVariables:
        if v.causality == "output" and first_output is None and v.type == "Real":
            first_output = v.valueReference
        if v.causality != "parameter" or v.type != "Real":
            continue
        rule = RULES.get(v.name) or RULES.get(v.name.rsplit(".", 1)[-1])
        if rule is None:
            continue
        lo = -math.inf if rule.low is None else math.nextafter(rule.low, math.inf) if rule.low_open else rule.low
        hi = math.inf if rule.high is None else rule.high
        args += ["-p", f"{v.valueReference}:{lo!r}:{hi!r}"]
        if v.name == "solver.max_wall_time":
            args += ["-b", str(v.valueReference)]
    return md.guid, args + ["-v", str(first_output)]


if __name__ == "__main__":
    import fmpy
    out = Path(sys.argv[1])
    for name, fmu in build(out).items():
        d = Path(fmpy.extract(str(fmu), str(out / name)))
        guid, args = fuzz_args(d)
        print(name, d, guid, *args)
