"""Friction laws (paper Fig. 1), the friction solve, and friction at the extremes."""
from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from overcon import scene
from overcon import kernel
from overcon.model import ModelError
from overcon.checks import compile_checked
from overcon.simulate import Simulation, SimulationError, run_scene

from test_core_rows import position, rotation

MECH = Path(__file__).resolve().parent.parent / "mechanisms"


def test_coulomb_refused_for_integration():
    """Law A (mu sign(v)) is discontinuous at v = 0: a run refuses it, naming why. (The laws' values
    are held to the paper's formulas through the core's friction outputs: test_spatial_joints.py,
    test_joints.py.)"""
    sc = scene.load(MECH / "planar_f45_wo4.toml")
    fp = {k: dataclasses.replace(v, law="coulomb") for k, v in sc.friction_params.items()}
    model = compile_checked(dataclasses.replace(sc, friction_params=fp))
    with pytest.raises(ModelError, match="analysis only"):
        Simulation(model, sc.solver)


# ------------------------------------------------------------------------------ helpers

def scene_with(name, *, mu=None, v_reg=None, tolerance=1e-8, stop_time=None, text_edit=None, tmp_path=None):
    path = MECH / name
    if text_edit:
        mech_text = (MECH / "planar_sliders.toml").read_text()
        for old, new in text_edit:
            assert old in mech_text
            mech_text = mech_text.replace(old, new)
        (tmp_path / "planar_sliders.toml").write_text(mech_text)
        (tmp_path / name).write_text(path.read_text())
        path = tmp_path / name
    sc = scene.load(path)
    changes = {}
    if mu is not None:
        changes["mu"] = mu
    if v_reg is not None:
        changes["v_reg"] = v_reg
    fp = {k: dataclasses.replace(v, **changes) for k, v in sc.friction_params.items()}
    sc = dataclasses.replace(sc, friction_params=fp)
    return scene.as_scene(sc, tolerance=tolerance, stop_time=stop_time)


def mechanical_energy(model, y):
    """Kinetic + gravity + spring energy (J) of the planar model at state y."""
    q, h = y[: model.n], y[model.n:]
    kinetic = 0.5 * float(h @ (model.M * h))
    grav = -sum(model.mass[b] * float(model.gravity @ position(model, q, b)) for b in range(model.nb))
    spring = 0.0
    for ld in model.loads:
        if ld.type == "spring":
            d = (position(model, q, ld.bi) + rotation(model, q, ld.bi) @ ld.s_i - position(model, q, ld.bj)
                 - rotation(model, q, ld.bj) @ ld.s_j)
            spring += 0.5 * ld.stiffness * (np.linalg.norm(d) - ld.free_length) ** 2
    return kinetic + grav + spring


# ------------------------------------------------------------------------------ physics

NO_DRIVE = [("value = 10.0", "value = 0.0"), ("value = 30.0", "value = 0.0")]


@pytest.mark.parametrize("scene_name", ["planar_f45_wo4", "planar_f1_wo6", "planar_f145_wo4"])
def test_friction_never_adds_energy(tmp_path, scene_name):
    """Without the drive torques the mechanism is conservative: with friction its mechanical
    energy never increases (beyond the integration error) and ends below the frictionless one."""
    sc = scene_with(f"{scene_name}.toml", tolerance=1e-10, stop_time=4.0, text_edit=NO_DRIVE, tmp_path=tmp_path)
    model = compile_checked(sc)
    free = compile_checked(dataclasses.replace(sc, friction=(), friction_params={}))
    sim, sim_free = Simulation(model, sc.solver), Simulation(free, sc.solver)
    e0 = mechanical_energy(model, sim.advance(0.0))
    energies, free_energies = [], []
    for t in np.linspace(0.02, 4.0, 200):
        energies.append(mechanical_energy(model, sim.advance(t)))
        free_energies.append(mechanical_energy(free, sim_free.advance(t)))
    energies = np.array([e0, *energies])
    assert np.all(np.diff(energies) <= 1e-7)
    assert np.max(np.abs(np.array(free_energies) - e0)) < 1e-6  # frictionless: conserved
    assert energies[-1] < e0 - 0.01  # friction dissipated a measurable amount


def test_mu_zero_is_exactly_frictionless():
    with_zero = run_scene(scene_with("planar_f145_wo4.toml", mu=0.0, stop_time=2.0))
    none = run_scene(scene_with("planar_none_wo4.toml", stop_time=2.0))
    for name in none.names:
        np.testing.assert_array_equal(with_zero.column(name), none.column(name))
    sp0 = run_scene(scene_with("spatial_GHMN_wo9.toml", mu=0.0, stop_time=0.5))
    sp = run_scene(scene_with("spatial_none_wo9.toml", stop_time=0.5))
    for name in sp.names:
        np.testing.assert_array_equal(sp0.column(name), sp.column(name))


@pytest.mark.parametrize("name", ["planar_f45_wo4", "planar_f1_wo4", "planar_f145_wo6"])
@pytest.mark.parametrize("mu", [1.0, 5.0])
def test_large_mu_converges_or_fails_clearly(name, mu):
    sc = scene_with(f"{name}.toml", mu=mu, stop_time=1.0)
    try:
        res = run_scene(sc)
    except SimulationError as exc:
        msg = str(exc)
        assert "t = " in msg
        if "friction solve" in msg:  # no solution of Eq. 18 found (jamming of the slider)
            assert "residual" in msg and any(j in msg for j in ("joint1", "joint4", "joint5"))
        else:  # sticking inside the regularisation band: reported, not crawled through
            assert "stiff" in msg
    else:
        assert np.all(np.isfinite(res.values))
        assert res.max_drift < 1e-6


def test_tiny_regularisation_velocity_is_accurate_not_garbage():
    """v_reg = 1e-6 m/s: the result converges to the v_reg -> 0 limit (compared with 1e-5), finite,
    constraints held; stiffness, if it arose, would be reported (dopri5 stiffness test)."""
    a = run_scene(scene_with("planar_f45_wo4.toml", v_reg=1e-6, stop_time=4.0))
    b = run_scene(scene_with("planar_f45_wo4.toml", v_reg=1e-5, stop_time=4.0))
    assert np.all(np.isfinite(a.values)) and a.max_drift < 1e-7
    assert np.max(np.abs(a.column("slider1.x") - b.column("slider1.x"))) < 1e-5


def test_friction_solve_failure_names_time_and_residual():
    """mu = 1 in joints 4 and 5 with friction_max_iter = 1: no stage of the friction solve can
    finish. The core's evaluation gives up (status 2, Newton and damped Newton counted), its
    robust path too (the residual and iterations named), and a run in C stops naming the time."""
    sc = scene_with("planar_f45_wo4.toml", mu=1.0)
    model = compile_checked(sc)
    solver = dataclasses.replace(sc.solver, friction_max_iter=1, kernel="c")
    k, _ = kernel.select(model, solver)
    J = k.rows(np.concatenate([model.q0, model.h0]))[1]
    y = np.concatenate([model.q0, 0.5 * np.linalg.svd(J)[2][-1]])  # a consistent velocity
    assert k.evaluate(1.25, y) is None and k.last_status == 2
    assert k.last_message == ("friction solve gave up: Newton after 1 force evaluations, damped Newton after 1 "
                              "more (4 friction multipliers of joints[3], joints[4])")
    assert k.evaluate_robust(y) is None and k.last_status == 2
    assert re.fullmatch(r"friction solve did not converge \(residual \S+ N after 2 iterations of the robust path: "
                        r"fixed point, then Newton with a finite-difference Jacobian, after Newton and damped "
                        r"Newton; 4 friction multipliers of joints\[3\], joints\[4\]\)", k.last_message), k.last_message
    with pytest.raises(kernel.RunStopped, match=r"t = [0-9.e-]+ s: friction solve did not converge \(residual"):
        kernel.Run(model, solver).advance(0.5)


def test_iteration_counts_reported():
    res = run_scene(scene_with("planar_f45_wo4.toml", stop_time=0.5))
    assert res.friction_iterations >= res.evaluations  # at least one iteration per evaluation
    assert res.friction_iterations < 30 * res.evaluations
