"""Uniqueness along the motion: the core's stage (core/unique.c, ``Kernel.unique``) decides the
rank and every joint's reaction as the pre-check does; a run records ``rank-change`` and
``uniqueness-change`` where the mechanism says they happen (the flat parallelogram of
tests/data/flat_parallelogram reaches its flat position at t = 1 s), in process, in C and in the
FMU's discrete outputs."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from overcon import kernel, scene
from overcon.checks import compile_checked
from overcon.precheck import precheck
from overcon.simulate import SimulationError, run

ROOT = Path(__file__).resolve().parents[1]
FILES = (sorted((ROOT / "mechanisms").glob("*.toml")) + sorted((ROOT / "mechanisms" / "examples").glob("*.toml"))
         + sorted((ROOT / "tests" / "data").glob("*/*.toml")))
FLAT = ROOT / "tests" / "data" / "flat_parallelogram" / "flat_parallelogram_f.toml"
T_FLAT = 1.0  # s: (pi - pi/3) / (2 pi / 3), the flat position of the frictionless linkage


def _spec(path):
    return scene.as_scene(scene.load(path))


def _core_against_precheck(model, solver):
    """The core's (rank, verdicts) at q0 and the one-factorisation pre-check's."""
    lib, reason = kernel.library()
    assert lib is not None, reason
    k = kernel.Kernel(lib, model, solver)
    rank, unique = k.unique(np.concatenate([model.q0, model.h0]))
    report = precheck(model, methods="svd")
    return (rank, [bool(u) for u in unique]), (report.rank, [report.reaction_unique[c.name] for c in model.joints])


def _compiled(path):
    try:
        spec = _spec(path)
        return compile_checked(spec), spec
    except Exception as exc:  # noqa: BLE001 - data files that are refused on purpose (two_pins)
        pytest.skip(f"{path.name}: {exc}")


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_the_core_decides_as_the_precheck_on_every_mechanism_of_the_repository(path):
    model, spec = _compiled(path)
    if kernel.support(model) is not None:
        pytest.skip(f"the core does not cover it: {kernel.support(model)}")
    core, pre = _core_against_precheck(model, spec.solver)
    assert core == pre


def _linkage(path: Path, rng, kind: str) -> Path:
    """A random planar linkage consistent at q0: ``"loop"``, a closed chain of 3 to 6 links through
    random points with both ends on the ground (no redundancy: every reaction unique), or
    ``"parallelogram"``, a coupler on 3 to 8 parallel cranks of one random length and angle from
    random pivots (k - 2 redundant: the cranks' and the coupler's reactions not unique)."""
    lines = ['[mechanism]', 'name = "random"', 'kind = "planar"', 'gravity = [0.0, -9.81]']
    joints = []
    if kind == "loop":
        n = int(rng.integers(3, 7))
        steps = rng.uniform(0.5, 2.0, size=n)[:, None] * np.stack([np.cos(a := rng.uniform(0, 2 * np.pi, n)),
                                                                    np.sin(a)], axis=1)
        pts = np.vstack([rng.uniform(-2.0, 2.0, size=(1, 2)), np.zeros((n, 2))])
        pts[1:] = pts[0] + np.cumsum(steps, axis=0)
        for i in range(n):
            a, b = pts[i], pts[i + 1]
            mid, d = [float(v) for v in (a + b) / 2], b - a
            phi = math.atan2(d[1], d[0])
            half = float(np.hypot(*d)) / 2
            lines += ['[[bodies]]', f'name = "L{i}"', 'mass = 1.0', 'inertia = 0.1', f'q0 = [{mid[0]!r}, {mid[1]!r}, {phi!r}]']
            joints.append((f"J{i}", f"L{i}", "base" if i == 0 else f"L{i - 1}", [-half, 0.0],
                           list(a) if i == 0 else [float(np.hypot(*(pts[i] - pts[i - 1]))) / 2, 0.0]))
        joints.append((f"J{n}", f"L{n - 1}", "base", [half, 0.0], list(pts[n])))
    else:
        k, length = int(rng.integers(3, 9)), float(rng.uniform(0.5, 2.0))
        theta = float(rng.uniform(0.2, math.pi - 0.2))
        xs = np.sort(rng.uniform(0.0, 5.0, size=k))
        c, s = math.cos(theta), math.sin(theta)
        centre = float(xs.mean())
        lines += ['[[bodies]]', 'name = "coupler"', 'mass = 1.0', 'inertia = 1.0',
                  f'q0 = [{centre + length * c!r}, {length * s!r}, 0.0]']
        for i, x in enumerate(xs):
            lines += ['[[bodies]]', f'name = "crank{i}"', 'mass = 1.0', 'inertia = 0.1',
                      f'q0 = [{float(x) + 0.5 * length * c!r}, {0.5 * length * s!r}, {theta!r}]']
            joints.append((f"G{i}", f"crank{i}", "base", [-0.5 * length, 0.0], [float(x), 0.0]))
            joints.append((f"C{i}", f"crank{i}", "coupler", [0.5 * length, 0.0], [float(x) - centre, 0.0]))
    for name, bi, bj, si, sj in joints:
        lines += ['[[joints]]', f'name = "{name}"', 'type = "revolute"', f'body_i = "{bi}"', f'body_j = "{bj}"',
                  f's_i = [{si[0]!r}, {si[1]!r}]', f's_j = [{float(sj[0])!r}, {float(sj[1])!r}]']
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("seed", range(100))
def test_the_core_decides_as_the_precheck_on_random_linkages(tmp_path, seed):
    rng = np.random.default_rng(seed)
    kind = "loop" if seed % 2 else "parallelogram"
    path = _linkage(tmp_path / "m.toml", rng, kind)
    model = compile_checked(scene.as_scene(scene.load(path)))
    core, pre = _core_against_precheck(model, _spec(path).solver)
    assert core == pre
    m = model.m
    if kind == "loop":
        assert core[0] == m and all(core[1])  # no redundancy: every reaction unique
    else:
        assert core[0] == m - (len(model.joints) // 2 - 2) and not any(core[1])


def _flat_events(events):
    return [(kind, detail) for _, kind, detail in events if kind != "stopped"]


def test_the_flat_parallelogram_changes_rank_and_uniqueness_at_its_flat_position():
    """In process and in C: rank 8 -> 7 and G0 (friction) unique -> not unique at the flat
    position, t = 1 s (located by the watch; the friction of G0 moves it by about 1e-5 s), then
    the stop there; the C run's events equal the in-process run's."""
    spec = _spec(FLAT)
    model = compile_checked(spec)
    with pytest.raises(SimulationError, match="rank deficient") as exc:
        run(model, spec.solver)
    events = exc.value.partial.events
    assert _flat_events(events) == [("rank-change", "rank 8 -> 7"),
                                    ("uniqueness-change", "G0: unique -> not unique; motion_unique true -> false")]
    assert [kind for _, kind, _ in events][-1] == "stopped"
    assert all(abs(t - T_FLAT) < 1e-3 for t, _, _ in events)
    c = kernel.Run(model, spec.solver)
    assert c.uniqueness() == (8, {"G0": True, "C0": True, "G1": True, "C1": True}, True)
    with pytest.raises(kernel.RunStopped, match="rank deficient"):
        c.advance(2.0)
    assert [kind for _, kind, _ in c.events] == [kind for _, kind, _ in events]
    for a, b in zip(c.events, events):  # the stop's time read from its message: 9 digits
        assert abs(a[0] - b[0]) <= (1e-8 if a[1] == "stopped" else 1e-12) and a[2] == b[2]
    rank, unique, motion = c.uniqueness()
    assert rank == 7 and not any(unique.values()) and motion is False


def test_a_c_run_saves_and_restores_its_events_and_verdicts():
    spec = _spec(FLAT)
    model = compile_checked(spec)
    a = kernel.Run(model, spec.solver)
    with pytest.raises(kernel.RunStopped):
        a.advance(2.0)
    b = kernel.Run(model, spec.solver)
    before = b.get_state()
    b.set_state(a.get_state())
    assert b.events == a.events and b.uniqueness() == a.uniqueness()
    b.set_state(before)
    assert b.events == [] and b.uniqueness()[0] == 8
    with pytest.raises(kernel.RunStopped, match="set state"):
        b.set_state(before[:-1])


def test_a_regular_run_records_no_change():
    """Bricard's mechanism under auto keeps rank 29 and its verdicts for 10 s: no event."""
    spec = _spec(ROOT / "tests" / "data" / "bricard" / "bricard_auto.toml")
    res = run(compile_checked(spec), spec.solver, stop_time=2.0)
    assert not res.events


@pytest.mark.integration
def test_the_fmu_outputs_change_at_the_flat_position(tmp_path):
    """Through fmpy: rank, motion_unique and G0.reaction_unique are discrete outputs
    that keep the pre-check's values (start values) at every communication point before t = 1 s,
    and after the doStep that stops at the flat position hold the values there; the events are
    logged; fmpy validate is clean; the tooling reads the pre-check's verdicts from the start values."""
    fmpy = pytest.importorskip("fmpy")
    from fmpy.validation import validate_fmu
    from overcon.fmu.build import build_scene
    from overcon.tooling.fmus import inspect_fmu
    res = build_scene(FLAT, tmp_path / "out", echo=lambda s: None)
    assert res.status == "built", res.messages
    assert validate_fmu(str(res.fmu)) == []
    md = fmpy.read_model_description(str(res.fmu))
    var = {v.name: v for v in md.modelVariables}
    assert (var["rank"].type, var["rank"].variability, var["rank"].start) == ("Integer", "discrete", "8")
    assert var["motion_unique"].variability == "discrete" and var["G0.reaction_unique"].variability == "discrete"
    assert var["C0.reaction_unique"].variability == "constant"  # no friction: the pre-check's constant
    info = inspect_fmu(res.fmu)
    assert info.motion_unique is True and info.reaction_unique["G0"] is True
    # explicit callbacks: fmpy's instantiate_fmu(logger=...) leaves its logging proxy pointing at
    # the logger after this test, and the next FMU instantiated with fmpy's default callbacks that
    # logs would call the freed function (a segmentation fault in another test)
    from fmpy.fmi2 import FMU2Slave
    from test_fmu import Logs
    logs = Logs()
    slave = FMU2Slave(guid=md.guid, unzipDirectory=fmpy.extract(str(res.fmu)),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="flat")
    slave.instantiate(callbacks=logs.callbacks, loggingOn=True)
    refs = [var["rank"].valueReference], [var["motion_unique"].valueReference, var["G0.reaction_unique"].valueReference]
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    t, seen = 0.0, []
    with pytest.raises(Exception, match="fmi2DoStep failed"):
        for _ in range(200):
            slave.doStep(t, 0.01)
            t += 0.01
            seen.append((slave.getInteger(refs[0])[0], tuple(slave.getBoolean(refs[1]))))
    assert 0.98 < t < T_FLAT  # the failed step holds the flat position
    assert set(seen) == {(8, (True, True))}
    assert slave.getInteger(refs[0])[0] == 7 and tuple(slave.getBoolean(refs[1])) == (False, False)
    slave.terminate()
    slave.freeInstance()
    events = [m for _, _, m in logs.records if ": event " in m]
    assert [m.split(": event ")[1] for m in events] == [
        "rank-change: rank 8 -> 7", "uniqueness-change: G0: unique -> not unique; motion_unique true -> false"]
    assert all(abs(float(m.split("t = ")[1].split(" s")[0]) - T_FLAT) < 1e-3 for m in events)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_the_core_packs_the_kept_set_as_the_numpy_plan(path):
    """The kept set's arrays the core packs (ovk_pack_kept: what a C run uses when it chooses the
    kept equations again) are the numpy plan's: the friction rows in lam_R, each friction
    equation's index among them (eliminated: the pad), the bodies of each kept row."""
    model, spec = _compiled(path)
    if kernel.support(model) is not None:
        pytest.skip(f"the core does not cover it: {kernel.support(model)}")
    k = kernel.Kernel(kernel.library()[0], model, spec.solver)
    cm, plan = k._cmodel, model.plan

    def ints(address, n):
        return np.ctypeslib.as_array((ctypes.c_int32 * max(n, 1)).from_address(address))[:n].tolist()

    import ctypes
    assert cm.nx == len(plan.friction_xrows) and ints(cm.xrows, cm.nx) == plan.friction_xrows.tolist()
    want = [list(row) + [len(plan.friction_xrows)] * (6 - len(row)) for g in plan.friction for row in g.x_index.tolist()]
    assert ints(cm.fx, 6 * cm.nfj) == [x for row in want for x in row]
    bodies = {r: (c.bi, c.bj) for c in model.joints for r in c.rows}
    assert ints(cm.rbody, 2 * cm.nR) == [b for r in model.retained for b in bodies[int(r)]]
