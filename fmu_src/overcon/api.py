"""The Python API a script uses: load and check a scene, simulate it in process, build FMUs, run
and compare them, check them against baselines. Everything here is re-exported by
:mod:`overcon` (``overcon.load``, ``overcon.check``, ...), the public surface named in its
``__all__``; the other modules of the package are internal (their names may change).

Each function does what the command of the same name does, without printing, and raises instead
of exiting: :class:`SceneError` for a file the loader refuses (every problem, each naming file and
field), :class:`ValueError` for a bad argument, :class:`SimulationError` for a run that stops.
"""
from __future__ import annotations

from pathlib import Path

from .precheck import PrecheckResult
from .scene import SceneError
from .simulate import Result, SimulationError
from .spec import MechanismSpec, SceneSpec
from .tooling import InputError, SimulationFailed

__all__ = ["load", "check", "simulate_scene", "build", "run", "compare", "regress",
           "SceneError", "SimulationError", "InputError", "SimulationFailed", "PrecheckResult", "Result",
           "MechanismSpec", "SceneSpec"]


def load(path) -> MechanismSpec | SceneSpec:
    """Read and validate a mechanism or scene file (TOML, see the scene format): a
    :class:`MechanismSpec` or a :class:`SceneSpec` (a scene loads its mechanism, path relative to
    the scene file). Raises :class:`SceneError` listing every problem."""
    from . import scene

    return scene.load(Path(path))


def _scene(source, friction=None, eliminate=None, stop_time=None, **solver) -> SceneSpec:
    """A scene from a path or a loaded spec, with the overrides of the command line."""
    from . import scene

    spec = source if isinstance(source, (MechanismSpec, SceneSpec)) else scene.load(Path(source))
    if isinstance(friction, (list, tuple)):
        friction = ",".join(friction) or "none"
    if isinstance(eliminate, (list, tuple)):
        eliminate = ",".join(str(e) for e in eliminate)
    return scene.as_scene(spec, friction=None if friction is None else scene.parse_joint_list(friction),
                          eliminate=None if eliminate is None else scene.parse_eliminate(eliminate),
                          stop_time=stop_time, solver={k: v for k, v in solver.items() if v is not None})


def check(source, *, friction=None, eliminate=None, methods: str = "auto") -> PrecheckResult:
    """The reaction-uniqueness pre-check (``overcon check``) of a file or a loaded spec at its
    initial configuration. ``friction``: joint names (or ``"none"``) overriding the scene's
    friction set; ``eliminate``: equation numbers and joint names, or ``"auto"``. The result's
    ``motion_unique`` is the paper's Eq. 17; ``to_json()`` is ``check --json``."""
    from .checks import compile_checked
    from .precheck import precheck

    spec = _scene(source, friction, eliminate)
    name = source.name if isinstance(source, (MechanismSpec, SceneSpec)) else str(source)
    return precheck(compile_checked(spec), name, methods)


def simulate_scene(source, *, friction=None, eliminate=None, stop_time=None, **solver) -> Result:
    """Integrate a scene (or a bare mechanism) in process, as ``overcon simulate`` does (named
    ``simulate_scene`` because ``overcon.simulate`` is the internal module of the engine): a
    :class:`Result` with ``names``, ``time``, ``values`` (rows by time) and ``column(name)``.
    Keyword arguments named like the scene's ``[solver]`` keys (``tolerance``, ``method``,
    ``step``, ``output_interval``, ...) override it, checked against their envelopes. Raises
    :class:`SimulationError` (with ``partial``, the rows computed before the stop) when the run
    stops."""
    from .checks import compile_checked
    from .simulate import run

    spec = _scene(source, friction, eliminate, stop_time, **solver)
    return run(compile_checked(spec), spec.solver)


def build(paths, out="dist/fmus", *, allow_nonunique: bool = False, refs: bool = False, validate: bool = False,
          fmi: int = 2, kind: str | None = None, jobs: int | None = None) -> list[Path]:
    """Build one FMU per scene file (``paths``: files or directories), as ``overcon build``, into
    ``out``; returns the FMU paths. A scene with friction on a non-unique reaction is refused unless
    ``allow_nonunique``; any scene not built raises :class:`InputError` with the build's messages.
    ``refs``: also write the reference results ``<scene>_ref.csv``; ``validate``: ``fmpy validate``."""
    from .fmu.build import build_all

    lines: list[str] = []
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    code, results = build_all(paths, Path(out), allow_nonunique=allow_nonunique, refs=refs, validate=validate,
                              jobs=jobs, echo=lambda s: None, echo_err=lines.append, fmi=fmi, kind=kind)
    failed = [r for r in results if r.status != "built"]
    if code != 0 or failed:
        raise InputError("build failed (exit %d): %s" % (code, "; ".join(
            [f"{r.source}: {r.status}: {'; '.join(r.messages)}" for r in failed] + lines)))
    return [r.fmu for r in results]


def run(fmus, out="results", *, stop_time=None, step=None, jobs: int = 2, settings: dict | None = None) -> list:
    """Simulate FMUs with fmpy (``overcon run``), one process each; returns one record per FMU
    with ``csv`` (``out/<model>.csv``: time and every Real output). ``settings``: FMU parameters set
    in every run, e.g. ``{"solver.method": "radau"}``. Raises :class:`SimulationFailed`."""
    from .tooling.pipeline import run_paths

    fmus = [fmus] if isinstance(fmus, (str, Path)) else list(fmus)
    return run_paths(fmus, out, stop_time=stop_time, step=step, jobs=jobs, echo=lambda s: None,
                     settings={k: str(v) for k, v in (settings or {}).items()})


def compare(fmus, out="comparison", *, group=None, one_group: bool = False, stop_time=None, jobs: int = 2):
    """Run the FMUs of each scene group adaptively and in lockstep and compare them, as ``overcon
    compare``; writes ``out/report.md``. The outcome's ``comparisons`` carry per group ``group``,
    ``observed_unique``, ``predicted_unique`` and ``matches``."""
    from .tooling.pipeline import compare_paths

    fmus = [fmus] if isinstance(fmus, (str, Path)) else list(fmus)
    return compare_paths(fmus, out, group=group, one_group=one_group, stop_time=stop_time, jobs=jobs,
                         echo=lambda s: None)


def regress(directory="mechanisms", *, baselines="ci/baselines", tolerances="ci/tolerances.toml",
            out="dist/regress", scenes=None, junit=None, jobs: int | None = None):
    """The regression check (``overcon regress``) of every scene of ``directory`` against
    ``baselines``; returns the outcome (``code`` 0, 1 or 2 as the command's exit code, ``checks``
    per scene); ``junit``: also write JUnit XML there."""
    from .tooling import regress as rg

    outcome = rg.regress(scenes, mechanisms=directory, baselines=baselines, tolerances=tolerances, out=out,
                         jobs=jobs, echo=lambda s: None)
    if junit is not None:
        rg.write_junit(outcome, junit)
    return outcome
