"""FMI 3.0 and Model Exchange from the same C core (``overcon build --fmi 2|3 --kind cs|me|both``,
C runtime): fmpy simulates every kind (FMI 2 CS, FMI 2 ME with CVode, FMI 3 CS, FMI 3 ME) and the
positions agree with the in-process run; Model Exchange and co-simulation agree to 1e-6 m on the
paper's friction scenes at tolerance 1e-9; FMU states round-trip bit for bit; the derivatives do
not depend on the host's call history (cold friction start); the quaternion event; the reaction
arrays; the flags' refusals; ``fmpy validate`` of the 20 paper scenes in both versions; the plain
C host for FMI 3.0 without Python."""
from __future__ import annotations

import concurrent.futures
import dataclasses
import shutil
import subprocess
from ctypes import c_double
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

from fmpy.fmi2 import FMU2Model  # noqa: E402
from fmpy.fmi3 import FMU3Model, FMU3Slave  # noqa: E402
from test_fmu import Logs  # noqa: E402

from overcon import scene as scene_mod  # noqa: E402
from overcon.checks import compile_checked  # noqa: E402
from overcon.fmu import build as fmu_build  # noqa: E402
from overcon.simulate import run  # noqa: E402

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
MECH = ROOT / "mechanisms"
PAPER = sorted(p for p in MECH.glob("*.toml") if scene_mod.is_scene_file(p) is not False)
FRICTION = [p for p in PAPER if "_none_" not in p.stem]
KIND_SCENES = {"planar_f45_wo4": MECH / "planar_f45_wo4.toml", "spatial_MN_wo5": MECH / "spatial_MN_wo5.toml",
               "door_h1_wo_hinge2": MECH / "examples" / "door_h1_wo_hinge2.toml"}
POSITION = ("x", "y", "z", "phi", "alpha", "beta", "gamma", "e0", "e1", "e2", "e3")
TOL = 1e-9
ME_CS = 1e-6  # m: the acceptance bound between Model Exchange (CVode) and co-simulation (dopri5), both at TOL


def _build(paths, out, **kw):
    lines = []
    code, results = fmu_build.build_all([str(p) for p in paths], out, refs=False, allow_nonunique=True,
                                        echo=lines.append, echo_err=lines.append, **kw)
    assert code == 0, lines
    return {r.name: r.fmu for r in results if r.status == "built"}, lines


@pytest.fixture(scope="module")
def paper(tmp_path_factory):
    """The 20 paper scenes as FMI 2.0 and FMI 3.0 FMUs offering both kinds (C runtime), built once
    without validation (test_fmpy_validate_paper_scenes validates them all)."""
    out = tmp_path_factory.mktemp("fmi_paper")
    fmi2, _ = _build(PAPER, out / "fmi2", runtime="c", fmi=2, validate=False)
    fmi3, _ = _build(PAPER, out / "fmi3", runtime="c", fmi=3, validate=False)
    assert len(fmi2) == len(fmi3) == len(PAPER) == 20
    return {2: fmi2, 3: fmi3}


@pytest.fixture(scope="module")
def kinds(tmp_path_factory):
    """KIND_SCENES as FMI 2.0 and 3.0 FMUs with both kinds (validated at the build)."""
    out = tmp_path_factory.mktemp("fmi_kinds")
    return {v: _build(KIND_SCENES.values(), out / f"fmi{v}", runtime="c", fmi=v)[0] for v in (2, 3)}


def _positions(md):
    return [v.name for v in md.modelVariables if v.causality == "output" and v.type in ("Real", "Float64")
            and not v.dimensions and v.name.rsplit(".", 1)[1] in POSITION]


def _interfaces(fmu: Path) -> tuple[str, str, str]:
    md = fmpy.read_model_description(str(fmu))
    return md.fmiVersion, "me" if md.modelExchange is not None else "", "cs" if md.coSimulation is not None else ""


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("kind", ["CoSimulation", "ModelExchange"])
@pytest.mark.parametrize("name", list(KIND_SCENES))
def test_each_kind_agrees_with_the_in_process_run(kinds, version, kind, name):
    """fmpy runs every kind at tolerance 1e-9 (co-simulation: the FMU's dopri5; Model Exchange:
    fmpy's CVode, rtol 1e-9, atol 1e-9 x nominal 1): co-simulation gives the in-process run's
    positions (the same C arithmetic, 1e-12 m), Model Exchange agrees with it to 1e-6 m."""
    fmu = kinds[version][name]
    assert _interfaces(fmu) == (f"{version}.0", "me", "cs")
    spec = scene_mod.load(KIND_SCENES[name])
    md = fmpy.read_model_description(str(fmu))
    pos = _positions(md)
    got = fmpy.simulate_fmu(str(fmu), fmi_type=kind, relative_tolerance=TOL, output=pos,
                            output_interval=spec.solver.output_interval)
    ref = run(compile_checked(spec), dataclasses.replace(spec.solver, tolerance=TOL))
    assert len(got) == len(ref.time) and np.allclose(got["time"], ref.time, rtol=0, atol=1e-12)
    bound = 1e-12 if kind == "CoSimulation" else ME_CS
    worst = max(float(np.max(np.abs(got[p] - ref.column(p)))) for p in pos)
    assert worst <= bound, (name, kind, worst)


@pytest.mark.parametrize("path", FRICTION, ids=[p.stem for p in FRICTION])
def test_model_exchange_equals_co_simulation_on_the_paper_friction_scenes(paper, path):
    """The acceptance: Model Exchange (CVode) and co-simulation agree to 1e-6 m in every position
    of every paper scene with friction, both at tolerance 1e-9 (FMI 3.0: the FMI 2.0 FMU has the
    same binary code under other names, checked on three scenes above)."""
    fmu = str(paper[3][path.stem])
    pos = [p for p in _positions(fmpy.read_model_description(fmu)) if p.rsplit(".", 1)[1] in ("x", "y", "z")]
    cs = fmpy.simulate_fmu(fmu, fmi_type="CoSimulation", relative_tolerance=TOL, output=pos)
    me = fmpy.simulate_fmu(fmu, fmi_type="ModelExchange", relative_tolerance=TOL, output=pos)
    assert np.array_equal(cs["time"], me["time"])
    worst = max(float(np.max(np.abs(cs[p] - me[p]))) for p in pos)
    assert worst <= ME_CS, (path.stem, worst)


def _validate(fmu: str) -> tuple[str, list]:
    from fmpy.validation import validate_fmu

    return fmu, validate_fmu(fmu)


def test_fmpy_validate_paper_scenes(paper):
    """The acceptance: fmpy validate finds no problem in the 20 paper scenes as FMI 2.0 (ME+CS) and
    FMI 3.0 (ME+CS): 40 FMUs, two processes (fmpy parses every variable name)."""
    fmus = [str(f) for v in (2, 3) for f in paper[v].values()]
    for f in fmus:
        assert _interfaces(Path(f))[1:] == ("me", "cs")
    with concurrent.futures.ProcessPoolExecutor(2) as pool:
        problems = {f: p for f, p in pool.map(_validate, fmus) if p}
    assert not problems


def _model3(fmu: Path, tmp: Path):
    d = fmpy.extract(str(fmu), str(tmp / f"{fmu.stem}_3"))
    md = fmpy.read_model_description(d)
    m = FMU3Model(guid=md.guid, unzipDirectory=d, modelIdentifier=md.modelExchange.modelIdentifier,
                  instanceName="me")
    m.instantiate()
    m.enterInitializationMode(startTime=0.0)
    m.exitInitializationMode()
    n = sum(v.derivative is not None for v in md.modelVariables)
    return m, md, n


def _array(values):
    return (c_double * len(values))(*values)


def _der(m, n):
    buf = (c_double * n)()
    m.getContinuousStateDerivatives(buf, n)
    return np.array(buf[:])


def _states(m, n):
    buf = (c_double * n)()
    m.getContinuousStates(buf, n)
    return np.array(buf[:])


def test_derivatives_do_not_depend_on_the_call_history(kinds, tmp_path):
    """The decision: the friction solve starts cold at every (t, x), so the derivatives at a point
    are the same bits whatever the host evaluated before (another point, a perturbed state)."""
    m, md, n = _model3(kinds[3]["planar_f45_wo4"], tmp_path)
    m.enterContinuousTimeMode()
    x0 = _states(m, n)
    m.setTime(0.3)
    first = _der(m, n)
    assert np.all(np.isfinite(first)) and np.any(first != 0.0)
    for scale in (1.01, 0.97, 1.2):  # elsewhere, with sliding velocities of other size
        m.setContinuousStates(_array(list(x0 * scale)), n)
        m.setTime(0.3 * scale)
        assert not np.array_equal(_der(m, n), first)
    m.setTime(0.3)
    m.setContinuousStates(_array(list(x0)), n)
    assert np.array_equal(_der(m, n), first)
    m.terminate()
    m.freeInstance()


def test_model_exchange_state_round_trip_bit_exact(kinds, tmp_path):
    """fmi3GetFMUState / serialise / deserialise / fmi3SetFMUState in continuous-time mode restore
    time and states: the derivatives and outputs there are the same bits."""
    m, md, n = _model3(kinds[3]["door_h1_wo_hinge2"], tmp_path)
    m.enterContinuousTimeMode()
    x = _states(m, n)
    m.setTime(0.2)
    m.setContinuousStates(_array(list(x + 1e-3 * np.arange(n) / n)), n)
    vrs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Float64"
           and not v.dimensions]
    before = (_der(m, n), np.array(m.getFloat64(vrs)))
    state = m.deserializeFMUState(m.serializeFMUState(m.getFMUState()))
    m.setTime(0.5)
    m.setContinuousStates(_array(list(x)), n)
    assert not np.array_equal(_der(m, n), before[0])
    m.setFMUState(state)
    after = (_der(m, n), np.array(m.getFloat64(vrs)))
    assert np.array_equal(after[0], before[0]) and np.array_equal(after[1], before[1])
    m.freeFMUState(state)
    m.terminate()
    m.freeInstance()


@pytest.mark.parametrize("version", [2, 3])
def test_co_simulation_state_round_trip_bit_exact(kinds, tmp_path, version):
    """Co-simulation: a state taken half-way, serialised and restored continues to the same bits."""
    fmu = kinds[version]["spatial_MN_wo5"]
    d = fmpy.extract(str(fmu), str(tmp_path / "cs"))
    md = fmpy.read_model_description(d)
    vrs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type in ("Real", "Float64")
           and not v.dimensions]
    if version == 3:
        s = FMU3Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="cs")
        s.instantiate()
        s.enterInitializationMode(startTime=0.0)
        get, step = s.getFloat64, lambda t, h: s.doStep(t, h)
    else:
        from fmpy.fmi2 import FMU2Slave

        s = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="cs")
        s.instantiate()
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        get, step = s.getReal, lambda t, h: s.doStep(t, h)
    s.exitInitializationMode()
    t, h = 0.0, 0.05
    for _ in range(10):
        step(t, h)
        t += h
    get_state = s.getFMUState if version == 3 else s.getFMUstate
    set_state = s.setFMUState if version == 3 else s.setFMUstate
    ser = s.serializeFMUState if version == 3 else s.serializeFMUstate
    deser = s.deserializeFMUState if version == 3 else s.deSerializeFMUstate
    state, t_half = deser(ser(get_state())), t
    for _ in range(10):
        step(t, h)
        t += h
    end = np.array(get(vrs))
    set_state(state)
    t = t_half
    for _ in range(10):
        step(t, h)
        t += h
    assert np.array_equal(np.array(get(vrs)), end)
    s.terminate()
    s.freeInstance()


def test_quaternion_event_renormalises(kinds, tmp_path):
    """A quaternion off unit norm: fmi3CompletedIntegratorStep asks for an event, the event
    re-normalises it and says the states changed; at unit norm no event is asked for."""
    m, md, n = _model3(kinds[3]["door_h1_wo_hinge2"], tmp_path)
    names = [v.name for v in md.modelVariables if v.derivative is None and v.name.startswith("q.")]
    assert any(name.endswith(".e0") for name in names)
    m.enterContinuousTimeMode()
    x = _states(m, n)
    assert m.completedIntegratorStep() == (False, False)
    e = [i for i, name in enumerate(names) if name.rsplit(".", 1)[1] in ("e0", "e1", "e2", "e3")][:4]
    x[e] *= 1.001
    m.setContinuousStates(_array(list(x)), n)
    assert m.completedIntegratorStep() == (True, False)
    m.enterEventMode()
    changed = m.updateDiscreteStates()[3]
    assert changed
    fixed = _states(m, n)
    assert abs(np.linalg.norm(fixed[e]) - 1.0) <= 1e-15
    m.enterContinuousTimeMode()
    assert m.completedIntegratorStep() == (False, False)
    m.terminate()
    m.freeInstance()


def test_reaction_arrays_equal_the_scalars(kinds, tmp_path):
    """FMI 3.0's <joint>.reaction holds the joint's scalar reaction outputs, in their order."""
    fmu = kinds[3]["planar_f45_wo4"]
    d = fmpy.extract(str(fmu), str(tmp_path / "arr"))
    md = fmpy.read_model_description(d)
    by_name = {v.name: v for v in md.modelVariables}
    arrays = [v for v in md.modelVariables if v.dimensions]
    assert [v.name for v in arrays] == [f"joint{k}.reaction" for k in range(1, 7)]
    s = FMU3Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier, instanceName="a")
    s.instantiate()
    s.enterInitializationMode(startTime=0.0)
    s.exitInitializationMode()
    s.doStep(0.0, 0.5)
    for a in arrays:
        comps = [by_name[f"{a.name[:-len('.reaction')]}.{c}"].valueReference for c in ("Fx", "Fy", "T", "Fx0", "Fy0")]
        assert np.array_equal(np.array(s.getFloat64([a.valueReference], nValues=5)), np.array(s.getFloat64(comps)))
    s.terminate()
    s.freeInstance()


def test_flags(tmp_path):
    """The deprecated --runtime python builds what --runtime c builds with --fmi 3 and every kind
    (both by default). An FMU of a scene with energy outputs is co-simulation only by default
    (said) and refused with an explicit --kind me. --kind cs and me give one interface; a
    co-simulation-only FMU refuses Model Exchange instantiation."""
    planar, energy = MECH / "planar_f45_wo4.toml", ROOT / "tests" / "data" / "bricard" / "bricard_wo2.toml"
    for kw, want in (({"fmi": 3}, ("3.0", "me", "cs")), ({"kind": "me"}, ("2.0", "me", "")), ({}, ("2.0", "me", "cs"))):
        built, lines = _build([planar], tmp_path / f"py{len(kw)}{kw.get('fmi', kw.get('kind', ''))}", runtime="python",
                              validate=False, **kw)
        assert any("--runtime python is deprecated" in line for line in lines), lines
        assert _interfaces(built["planar_f45_wo4"]) == want
    built, lines = _build([energy], tmp_path / "energy", runtime="c", validate=False)
    assert any("co-simulation only (Model Exchange does not carry the energy" in line for line in lines), lines
    assert _interfaces(built["bricard_wo2"])[1:] == ("", "cs")
    lines = []
    code, _ = fmu_build.build_all([str(energy)], tmp_path / "energy_me", refs=False, validate=False, runtime="c",
                                  kind="me", echo=lines.append, echo_err=lines.append)
    assert code == fmu_build.EXIT_INPUT and any("--kind cs" in line for line in lines), lines
    for kind, want in (("cs", ("", "cs")), ("me", ("me", ""))):
        built, _ = _build([planar], tmp_path / kind, runtime="c", fmi=3, kind=kind)
        assert _interfaces(built["planar_f45_wo4"])[1:] == want
    built, _ = _build([planar], tmp_path / "cs2", runtime="c", kind="cs", validate=False)
    d = fmpy.extract(str(built["planar_f45_wo4"]), str(tmp_path / "cs2x"))
    md = fmpy.read_model_description(d)
    m = FMU2Model(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier, instanceName="m")
    logs = Logs()  # the FMU's own callbacks (tests/_fmpy_logger.py: not fmpy's logging proxy)
    # fmpy raises a bare Exception with this text when fmi2Instantiate returns NULL; the reason is
    # the FMU's logged error
    with pytest.raises(Exception, match="^Failed to instantiate model$"):
        m.instantiate(callbacks=logs.callbacks)
    assert any(status == 3 and "fmi2Instantiate: this FMU supports co-simulation only (built with --kind cs" in text
               for status, _, text in logs.records), logs.records


@pytest.fixture(scope="module")
def host3(tmp_path_factory):
    cc = shutil.which("cc")
    if cc is None:
        pytest.skip("needs a C compiler (cc) for the test host")
    exe = tmp_path_factory.mktemp("c_host3") / "fmu_host3"
    subprocess.run([cc, "-O2", "-Wall", "-Wextra", "-Werror", "-o", str(exe), str(ROOT / "tests" / "c_host" / "fmu_host3.c"),
                    "-ldl", "-lm"], check=True, capture_output=True)
    return exe


@pytest.mark.parametrize("name", ["planar_f45_wo4", "door_h1_wo_hinge2"])
def test_plain_c_host_fmi3_without_python(kinds, host3, tmp_path, name):
    """The plain FMI 3.0 host from an empty environment (env -i): exit 0, every row, no libpython in
    the process (-n), the FMU state through its bytes restores the second half bit for bit (-S),
    and the values equal fmpy's FMI 3.0 co-simulation (the same bits; the issue asks 1e-9)."""
    fmu = kinds[3][name]
    d = Path(fmpy.extract(str(fmu), str(tmp_path / name)))
    md = fmpy.read_model_description(str(d))
    ex = md.defaultExperiment
    outs = [v for v in md.modelVariables if v.causality == "output" and v.type == "Float64" and not v.dimensions]
    args = ["-q", "-w", "-n", "-S", str(d), md.coSimulation.modelIdentifier, md.guid, ex.startTime, ex.stopTime,
            ex.stepSize, ex.tolerance, *(f"{v.valueReference}:{v.name}" for v in outs)]
    proc = subprocess.run(["env", "-i", str(host3), *map(str, args)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    rows = np.array([[float(x) for x in line.split(",")] for line in proc.stdout.splitlines()[1:]])
    n_rows = round((float(ex.stopTime) - float(ex.startTime)) / float(ex.stepSize)) + 1
    assert rows.shape == (n_rows, 1 + len(outs))
    ref = fmpy.simulate_fmu(str(fmu), output_interval=float(ex.stepSize), output=[v.name for v in outs])
    assert np.array_equal(rows[:, 1:], np.column_stack([ref[v.name] for v in outs]))


def test_tooling_runs_fmi3_and_model_exchange_only_fmus(kinds, tmp_path):
    """overcon's runner (run, compare, reproduce, sweep) reads an FMI 3.0 FMU (Float64 outputs, no
    arrays recorded) and runs it through co-simulation; an FMU with Model Exchange only runs through
    fmpy's CVode at the DefaultExperiment tolerance: the CSVs equal fmpy's own runs."""
    from fmpy.util import read_csv

    from overcon.tooling.fmus import inspect_fmu
    from overcon.tooling.run import simulate

    me_only, _ = _build([KIND_SCENES["planar_f45_wo4"]], tmp_path / "me", runtime="c", kind="me")
    for fmu, kind in ((kinds[3]["planar_f45_wo4"], "CoSimulation"), (me_only["planar_f45_wo4"], "ModelExchange")):
        info = inspect_fmu(fmu)
        names = [o.name for o in info.outputs]
        assert "joint4.Fx" in names and not any(n.endswith(".reaction") for n in names)
        csv = tmp_path / f"{kind}.csv"
        simulate(fmu, csv, start=info.start, stop=info.stop, step=info.step, outputs=names, progress=False)
        got = read_csv(str(csv))
        ref = fmpy.simulate_fmu(str(fmu), fmi_type=kind, output=names, output_interval=info.step)
        for n in names:
            assert np.array_equal(got[n], ref[n]), (kind, n)
