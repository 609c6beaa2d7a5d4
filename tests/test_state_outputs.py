"""Velocity and energy outputs (``[outputs] velocities``, ``energy``): velocities are the
derivatives of the positions (central finite differences of a fine output grid), and the
energy of a frictionless mechanism without applied forces or torques is conserved to the
integration accuracy."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from overcon import scene
from overcon.checks import compile_checked
from overcon.simulate import run

MECH = Path(__file__).resolve().parents[1] / "mechanisms"


def _scene(tmp_path: Path, mechanism: str, eliminate: str, stop: float, outputs: str = 'velocities = "all"\nenergy = true',
           tolerance: float = 1e-10) -> Path:
    shutil.copy(MECH / mechanism, tmp_path / "mechanism.toml")  # beside the scene: an FMU carries it
    path = tmp_path / "scene.toml"
    path.write_text('[scene]\nname = "state_outputs"\nmechanism = "mechanism.toml"\nfriction = []\n'
                    f'eliminate = {eliminate}\nstop_time = {stop}\n\n[outputs]\npositions = "all"\nreactions = []\n'
                    f'{outputs}\n\n[solver]\ntolerance = {tolerance}\n')
    return path


def _run(path: Path, **kw):
    spec = scene.load(path)
    res = run(compile_checked(spec), spec.solver, **kw)
    return res, res.column


def _central(res, name):
    t = res.time
    return (res.column(name)[2:] - res.column(name)[:-2]) / (t[2:] - t[:-2])


@pytest.mark.parametrize("mechanism, eliminate, stop", [("planar_sliders.toml", "[4]", 2.0),
                                                        ("examples/fourbar.toml", '"auto"', 10.0)])
def test_energy_of_a_frictionless_mechanism_without_applied_loads_is_conserved(tmp_path, mechanism, eliminate, stop):
    """Gravity and a spring (planar sliders), gravity (the spatial four-bar, quaternions): kinetic
    + potential stays within 1e-7 J over the run at tolerance 1e-10 (measured: 1.1e-9 J of 162 J,
    1.9e-8 J of 33 J)."""
    res, col = _run(_scene(tmp_path, mechanism, eliminate, stop))
    energy = col("energy.kinetic") + col("energy.potential")
    assert np.max(np.abs(energy - energy[0])) <= 1e-7
    assert np.ptp(col("energy.kinetic")) > 1.0  # the mechanism does move: energy is exchanged


def _friction_scene(tmp_path: Path, mechanism: str, friction: str, eliminate: str, stop: float) -> Path:
    path = _scene(tmp_path, mechanism, eliminate, stop, outputs="energy = true")
    path.write_text(path.read_text().replace("friction = []", f"friction = {friction}"))
    return path


@pytest.mark.parametrize("mechanism, friction, eliminate, stop", [
    ("planar_sliders.toml", '["joint4", "joint5"]', "[4]", 4.0),
    ("examples/carriage.toml", '["guide"]', '["rod"]', 2.0)])
def test_energy_balance_with_friction_and_applied_loads(tmp_path, mechanism, friction, eliminate, stop):
    """kinetic + potential + dissipated - applied stays within 1e-7 J at tolerance 1e-10 (measured:
    7e-9 J with 1.07 J dissipated, the paper's sliders with friction in joints 4 and 5; 2e-13 J
    with 180 J dissipated and 328 J applied, the carriage driven along its friction guide); the
    dissipated work never decreases."""
    res, col = _run(_friction_scene(tmp_path, mechanism, friction, eliminate, stop))
    balance = col("energy.kinetic") + col("energy.potential") + col("energy.dissipated") - col("energy.applied")
    assert np.max(np.abs(balance - balance[0])) <= 1e-7
    assert col("energy.dissipated")[0] == 0.0 and col("energy.applied")[0] == 0.0
    assert col("energy.dissipated")[-1] > 1.0 and np.all(np.diff(col("energy.dissipated")) >= 0.0)
    if mechanism.startswith("examples/carriage"):
        assert col("energy.applied")[-1] > 1.0  # the driving force does work


def test_work_outputs_follow_a_saved_state(tmp_path):
    """The accumulated work is part of the run's state: a run restored from a saved state gives
    the same energy outputs, bit for bit."""
    from overcon.simulate import Simulation
    spec = scene.load(_friction_scene(tmp_path, "planar_sliders.toml", '["joint4", "joint5"]', "[4]", 1.0))
    model = compile_checked(spec)
    sim = Simulation(model, spec.solver)
    sim.advance(0.3)
    state = sim.get_state()
    first = sim.outputs(0.55, sim.advance(0.55))
    other = Simulation(model, spec.solver)
    other.set_state(state)
    assert np.array_equal(other.outputs(0.55, other.advance(0.55)), first)
    assert first[model.output_names().index("energy.dissipated")] > 0.0


def test_planar_velocities_are_the_derivatives_of_the_positions(tmp_path):
    res, col = _run(_scene(tmp_path, "planar_sliders.toml", "[4]", 1.0), output_interval=1e-3)
    for body in ("slider1", "link3", "link4"):
        for coord, vel in (("x", "vx"), ("y", "vy"), ("phi", "omega")):
            v = col(f"{body}.{vel}")[1:-1]
            assert np.max(np.abs(_central(res, f"{body}.{coord}") - v)) <= 1e-3 * max(1.0, np.max(np.abs(v)))


def test_spatial_velocities_global_and_angular_velocity_in_body_axes(tmp_path):
    """The spatial parallelogram (z-x-z Euler angles; link1 turns about its body x and y axes
    while alpha changes, so body and global axes differ): the velocity outputs are the derivatives
    of x, y, z, and the angular velocity is the body-axes one,
    omega = [a' sin b sin g + b' cos g, a' sin b cos g - b' sin g, a' cos b + g']."""
    res, col = _run(_scene(tmp_path, "spatial_parallelogram.toml", "[5]", 1.0, 'velocities = ["link1"]'),
                    output_interval=1e-3)
    scale = 1e-3 * max(1.0, max(np.max(np.abs(col(f"link1.{v}"))) for v in ("vx", "vy", "vz", "wx", "wy", "wz")))
    for c in "xyz":
        assert np.max(np.abs(_central(res, f"link1.{c}") - col(f"link1.v{c}")[1:-1])) <= scale
    a, b, g = (col(f"link1.{c}")[1:-1] for c in ("alpha", "beta", "gamma"))
    da, db, dg = (_central(res, f"link1.{c}") for c in ("alpha", "beta", "gamma"))
    w = {"wx": da * np.sin(b) * np.sin(g) + db * np.cos(g), "wy": da * np.sin(b) * np.cos(g) - db * np.sin(g),
         "wz": da * np.cos(b) + dg}
    assert min(np.ptp(w["wx"]), np.ptp(w["wy"])) > 0.1  # turning about body x and y: the frame matters
    for k, expected in w.items():
        assert np.max(np.abs(expected - col(f"link1.{k}")[1:-1])) <= scale


def test_outputs_table_velocities_and_energy_are_checked(tmp_path):
    path = _scene(tmp_path, "planar_sliders.toml", "[4]", 1.0, 'velocities = ["nowhere", "base"]\nenergy = "yes"')
    with pytest.raises(scene.SceneError, match=r"outputs\.velocities\[0\]: unknown body 'nowhere'") as info:
        scene.load(path)
    text = str(info.value)
    assert "outputs.velocities[0]: unknown body 'nowhere' (the base does not move)" in text
    assert "outputs.velocities[1]: unknown body 'base'" in text
    assert "outputs.energy: expected true or false, got" in text


def test_without_the_keys_a_scene_has_neither(tmp_path):
    spec = scene.load(_scene(tmp_path, "planar_sliders.toml", "[4]", 1.0, ""))
    names = compile_checked(spec).output_names()
    assert not [n for n in names if n.endswith((".vx", ".omega")) or n.startswith("energy.")]


@pytest.mark.integration
def test_fmu_publishes_velocities_and_energy_with_units(tmp_path):
    """The FMU has the outputs with units m/s, rad/s and J, and gives the in-process values."""
    fmpy = pytest.importorskip("fmpy")
    from overcon.fmu.build import build_all
    path = _scene(tmp_path, "planar_sliders.toml", "[4]", 0.5)
    code, _ = build_all([str(path)], tmp_path / "fmus", refs=False, echo=lambda s: None, echo_err=lambda s: None)
    assert code == 0
    fmu = str(tmp_path / "fmus" / "state_outputs.fmu")
    units = {v.name: v.unit for v in fmpy.read_model_description(fmu).modelVariables}
    assert (units["slider1.vx"], units["slider1.omega"], units["energy.kinetic"], units["energy.potential"]) == \
        ("m/s", "rad/s", "J", "J")
    out = fmpy.simulate_fmu(fmu, stop_time=0.5, output_interval=0.01)
    res, col = _run(path)
    for name in ("slider1.vx", "link4.omega", "energy.kinetic", "energy.potential", "energy.dissipated",
                 "energy.applied"):
        assert np.max(np.abs(out[name] - col(name))) <= 1e-9 * max(1.0, np.max(np.abs(col(name))))
