"""Drivers ([[drivers]], issue 38): a joint's coordinate prescribed in time by one rheonomic
equation, its multiplier the effort. The door driven at constant speed about hinge1 against the
gravity moment computed here from its mass and centre of mass; the work balance with friction; the
effort's dependence on the elimination that the pre-check predicts; the counting (DOF 0, a
driver on a fixed coordinate refused); the ramp's quintic; the FMU equal to the run in process."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from overcon import scene
from overcon.checks import compile_checked
from overcon.cli import main
from overcon.simulate import run

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "mechanisms" / "examples"
A = np.array([np.sin(0.1), 0.0, np.cos(0.1)])  # the door's hinge line (door.toml)


def _driven(tmp_path: Path, *, friction: str = "[]", eliminate: str = '["hinge2"]', drivers: str | None = None,
            name: str = "driven", stop: float = 2.0, energy: bool = True) -> Path:
    shutil.copy(EX / "door.toml", tmp_path / "door.toml")
    drivers = drivers if drivers is not None else ('[[drivers]]\nname = "motor"\njoint = "hinge1"\n'
                                                   'motion = "constant_speed"\nspeed = 1.0\n')
    path = tmp_path / f"{name}.toml"
    path.write_text(f'[scene]\nname = "{name}"\nmechanism = "door.toml"\nfriction = {friction}\n'
                    f'eliminate = {eliminate}\nstop_time = {stop}\n\n{drivers}\n[outputs]\n'
                    'positions = ["door.x", "door.y", "door.z"]\nreactions = ["hinge1"]\nfriction = "all"\n'
                    f'joints = ["hinge1"]\nenergy = {"true" if energy else "false"}\n\n'
                    '[solver]\ntolerance = 1e-10\noutput_interval = 0.01\n')
    return path


def _run(path: Path, **kw):
    spec = scene.load(path)
    return run(compile_checked(spec), spec.solver, **kw)


def test_constant_speed_on_hinge1_rate_angle_and_effort_against_gravity(tmp_path):
    """driven_door.toml: hinge1.rate = 1 rad/s to 1e-9, the angle = t to 1e-9, and without friction
    the effort balances the gravity moment about the hinge line, -a . (c x m g), to 1e-9 relative
    (about a fixed axis at constant speed the inertial forces have no moment about it)."""
    res = _run(EX / "driven_door.toml")
    col, t = res.column, res.time
    assert np.max(np.abs(col("hinge1.rate") - 1.0)) <= 1e-9
    assert np.max(np.abs(col("hinge1.angle") - t)) <= 1e-9
    c = np.stack([col("door.x"), col("door.y"), col("door.z")], axis=1)
    weight = np.array([0.0, 0.0, -9.81 * 20.0])
    moment = np.cross(c, weight) @ A
    effort = col("motor.effort")
    assert np.ptp(effort) > 1.0  # the moment changes as the door turns
    assert np.max(np.abs(effort + moment)) <= 1e-9 * np.max(np.abs(moment))


def test_with_friction_the_driver_work_is_potential_energy_plus_dissipation(tmp_path):
    """Friction in hinge1: the driver's work (energy.applied, which carries it; cross-checked against
    the trapezoid of effort * speed on a fine grid) equals the change of potential energy plus the
    work dissipated to 1e-8 J; the kinetic energy stays constant."""
    res = _run(_driven(tmp_path, friction='["hinge1"]'), output_interval=1e-3)
    col, t = res.column, res.time
    applied, pot, diss, kin = col("energy.applied"), col("energy.potential"), col("energy.dissipated"), \
        col("energy.kinetic")
    assert np.max(np.abs(kin - kin[0])) <= 1e-8
    assert diss[-1] > 0.1  # the friction does work
    assert np.max(np.abs(applied - (pot - pot[0]) - diss)) <= 1e-8
    power = col("motor.effort") * col("hinge1.rate")
    trapezoid = np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(t))])
    assert np.max(np.abs(trapezoid - applied)) <= 1e-5 * np.max(np.abs(applied))


@pytest.mark.parametrize("friction", ["[]", '["hinge1"]'])
def test_effort_of_the_driven_door_under_two_eliminations(tmp_path, friction, capsys):
    """Eliminating hinge2 or equations 3, 4, 5, 9, 10: without friction the efforts agree to 1e-9
    relative (check: effort UNIQUE, exit 0); with friction in hinge1 they differ, and check says
    the effort is not unique, naming the driver and the joint (exit 1)."""
    a = _run(_driven(tmp_path, friction=friction, name="a", stop=0.5, energy=False))
    b = _run(_driven(tmp_path, friction=friction, eliminate="[3, 4, 5, 9, 10]", name="b", stop=0.5, energy=False))
    ea, eb = a.column("motor.effort"), b.column("motor.effort")
    code = main(["check", "--json", str(tmp_path / "a.toml")])
    doc = json.loads(capsys.readouterr().out)
    assert doc["dof"] == 0 and doc["drivers"] == ["motor"] and doc["n_equations"] == 11
    if friction == "[]":
        assert np.max(np.abs(ea - eb)) <= 1e-9 * np.max(np.abs(ea))
        assert code == 0 and doc["effort_unique"] is True
    else:
        assert np.max(np.abs(ea - eb)) > 1e-3 * np.max(np.abs(ea))
        bad = [p for p in doc["problems"] if p.startswith("effort not unique")]
        assert code == 1 and doc["effort_unique"] is False
        assert bad and "driver motor" in bad[0] and "hinge1" in bad[0]
        main(["check", str(tmp_path / "a.toml")])
        assert "driver motor: effort NOT UNIQUE" in capsys.readouterr().out


def _sliders(tmp_path: Path, drivers: str) -> Path:
    shutil.copy(ROOT / "mechanisms" / "planar_sliders.toml", tmp_path / "planar_sliders.toml")
    path = tmp_path / "sliders.toml"
    path.write_text('[scene]\nname = "sliders"\nmechanism = "planar_sliders.toml"\nfriction = []\neliminate = [4]\n'
                    f'stop_time = 2.0\n\n{drivers}\n[outputs]\npositions = "all"\nreactions = []\njoints = ["joint1"]\n\n'
                    '[solver]\ntolerance = 1e-10\noutput_interval = 0.01\n')
    return path


RAMP = '[[drivers]]\nname = "slide"\njoint = "joint1"\nmotion = "ramp"\nfrom = 0.0\nto = 0.3\nt0 = 0.5\nt1 = 1.5\n'


def test_a_fully_driven_paper_mechanism_has_dof_0_and_follows_the_quintic_ramp(tmp_path, capsys):
    """The paper's planar mechanism (DOF 1) with a ramp driver on slider 1's guide: check reports
    DOF 0; the slider's displacement follows 0.3 s^3 (10 - 15 s + 6 s^2), s = (t - 0.5) / 1, to
    1e-8 m, held before and after."""
    path = _sliders(tmp_path, RAMP)
    assert main(["check", "--json", str(path)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["dof"] == 0 and doc["rank"] == 12
    res = _run(path)
    s = np.clip(res.time - 0.5, 0.0, 1.0)
    expect = 0.3 * s ** 3 * (10 - 15 * s + 6 * s ** 2)
    assert np.max(np.abs(res.column("joint1.displacement") - expect)) <= 1e-8
    assert np.max(np.abs(res.column("joint1.speed")[res.time > 1.6])) <= 1e-8


def test_a_driver_on_a_fixed_coordinate_is_refused_exit_2_naming_it(tmp_path, capsys):
    """A second driver on the coordinate the first already prescribes (DOF 0 before it): exit 2, the
    message names the driver and its joint; so does a motion that does not start at the coordinate's
    value at q0."""
    path = _sliders(tmp_path, RAMP + RAMP.replace('"slide"', '"again"').replace('"joint1"', '"joint2"'))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "driver again" in err and "joint2" in err and "already fixed" in err
    path = _sliders(tmp_path, RAMP.replace("from = 0.0", "from = 0.2"))
    assert main(["check", str(path)]) == 2
    assert "driver slide" in capsys.readouterr().err


@pytest.mark.parametrize("drivers, field, words", [
    ('[[drivers]]\nname = "d"\njoint = "hinge1"\nmotion = "spin"\n', "drivers[0].motion", "allowed"),
    ('[[drivers]]\nname = "d"\njoint = "hinge1"\nmotion = "constant_speed"\n', "drivers[0].speed", "missing"),
    ('[[drivers]]\nname = "d"\njoint = "hinge1"\nmotion = "ramp"\nfrom = 0\nto = 1\nt0 = 2\nt1 = 1\n',
     "drivers[0].t1", "> t0"),
    ('[[drivers]]\nname = "hinge2"\njoint = "hinge1"\nmotion = "constant_speed"\nspeed = 1\n', "drivers[0].name",
     "already the name"),
    ('[[drivers]]\nname = "d"\njoint = "hinge1"\nmotion = "constant_speed"\nspeed = 1\ncoordinate = "displacement"\n',
     "drivers[0].joint", "revolute joint"),
    ('[[drivers]]\nname = "d"\njoint = "hinge1"\nmotion = "constant_speed"\nspeed = 1\nfrom = 2\n', "drivers[0].from",
     "unknown key"),
])
def test_bad_drivers_are_refused_naming_the_field(tmp_path, drivers, field, words):
    path = _driven(tmp_path, drivers=drivers)
    with pytest.raises(scene.SceneError) as exc:
        scene.load(path)
    hit = [p for p in exc.value.problems if p.field == field]
    assert hit and words in hit[0].message, exc.value.problems


@pytest.mark.integration
@pytest.mark.parametrize("fmi", [2, 3])
def test_the_driven_door_fmu_equals_the_run_in_process(tmp_path, fmi):
    """driven_door.toml as an FMU (FMI 2.0 and 3.0): fmpy validate clean, motor.effort and the
    sensors equal the in-process run bit for bit, effort_unique true."""
    fmpy = pytest.importorskip("fmpy")
    from fmpy.validation import validate_fmu

    from overcon.fmu import build as fmu_build

    res = fmu_build.build_scene(EX / "driven_door.toml", tmp_path / "out", echo=lambda s: None, fmi=fmi, kind="both")
    assert res.status == "built", res.messages
    assert validate_fmu(str(res.fmu)) == []
    outs = ["motor.effort", "hinge1.angle", "hinge1.rate", "effort_unique"]
    theirs = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.01, output=outs)
    ours = _run(EX / "driven_door.toml", stop_time=1.0)
    for n in outs[:3]:
        assert np.array_equal(theirs[n], ours.column(n)), n
    assert all(theirs["effort_unique"])


def _carriage(tmp_path: Path, drivers: str) -> Path:
    shutil.copy(EX / "carriage.toml", tmp_path / "carriage.toml")
    path = tmp_path / "carriage_driven.toml"
    path.write_text('[scene]\nname = "carriage_driven"\nmechanism = "carriage.toml"\nfriction = []\n'
                    f'eliminate = ["rod"]\nstop_time = 1.5\n\n{drivers}\n[outputs]\npositions = ["carriage.x"]\n'
                    'reactions = []\njoints = ["guide"]\n\n[solver]\ntolerance = 1e-10\noutput_interval = 0.01\n')
    return path


def test_harmonic_driver_on_the_carriage_guide_and_its_effort(tmp_path, capsys):
    """The carriage (5 kg, 40 N along its prismatic guide) driven harmonically along the guide,
    x = A sin(2 pi t) with A 2 pi = its initial 0.5 m/s: the displacement follows to 1e-9 m and the
    effort is m x'' - 40 N to 1e-8 relative; a driver on the rod's angle, which the guide already
    locks, is refused (exit 2)."""
    amp = 0.5 / (2 * np.pi)
    path = _carriage(tmp_path, f'[[drivers]]\nname = "shaker"\njoint = "guide"\nmotion = "harmonic"\n'
                               f'amplitude = {amp!r}\nfrequency = 1.0\n')
    res = _run(path)
    t = res.time
    assert np.max(np.abs(res.column("guide.displacement") - amp * np.sin(2 * np.pi * t))) <= 1e-9
    expect = 5.0 * (-amp * (2 * np.pi) ** 2 * np.sin(2 * np.pi * t)) - 40.0
    assert np.max(np.abs(res.column("shaker.effort") - expect)) <= 1e-8 * np.max(np.abs(expect))
    path = _carriage(tmp_path, '[[drivers]]\nname = "twist"\njoint = "rod"\nmotion = "constant_speed"\nspeed = 0.0\n')
    assert main(["check", str(path)]) == 2
    assert "driver twist" in capsys.readouterr().err


@pytest.mark.integration
@pytest.mark.parametrize("friction", ["[]", '["hinge1"]'])
def test_compare_decides_a_driven_group_on_its_efforts(tmp_path, friction):
    """overcon compare of the driven door under two eliminations (a group): the positions agree
    (the motion is prescribed), the efforts decide; predicted by effort_unique: unique without
    friction, not unique with friction in hinge1, and observed so."""
    pytest.importorskip("fmpy")
    from overcon.fmu.build import build_all
    from overcon.tooling.pipeline import compare_paths

    scenes = []
    for name, elim in (("dr_a", '["hinge2"]'), ("dr_b", "[3, 4, 5, 9, 10]")):
        path = _driven(tmp_path, friction=friction, eliminate=elim, name=name, stop=0.5, energy=False)
        path.write_text(path.read_text().replace(f'name = "{name}"\n', f'name = "{name}"\ngroup = "driven"\n', 1))
        scenes.append(path)
    code, res = build_all(scenes, tmp_path / "fmus", allow_nonunique=True, refs=False, validate=False,
                          echo=lambda s: None, echo_err=lambda s: None)
    assert code == 0, [m for r in res for m in r.messages]
    out = compare_paths([tmp_path / "fmus"], tmp_path / "cmp", echo=lambda s: None)
    c = {c.group: c for c in out.comparisons}["driven"]
    assert c.failure is None and c.predicted is (friction == "[]")
    deciding = [d.name for d in c.diffs if d.decides]
    assert deciding == ["motor.effort"]
    assert c.observed is c.predicted and c.matches
