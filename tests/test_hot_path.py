"""The compiled core as the one hot path: a joint evaluated inside its mechanism gives the same
rows and outputs as the same joint alone (the core has one form per joint type, no batch beside a
single one), zero reactions give zero spherical friction, the first singular body is named; and
Model.plan, which packs the friction columns for the core, follows a replaced model."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from overcon import scene as scene_mod
from overcon.model import build_plan
from overcon.checks import compile_checked

from test_kernel import kernel_for

MECH = Path(__file__).resolve().parent.parent / "mechanisms"
SCENES = ["planar_f145_wo4", "planar_f45_wo6", "spatial_GHMN_wo5", "spatial_MN_wo18"]


def model_of(name, **scene_changes):
    spec = scene_mod.as_scene(scene_mod.load(MECH / f"{name}.toml"))
    if scene_changes:
        spec = dataclasses.replace(spec, **scene_changes)
    return spec, compile_checked(spec)


def random_states(model, n=25, seed=0, scale=0.4):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield np.concatenate([model.q0 + scale * rng.standard_normal(model.n), 2.0 * rng.standard_normal(model.nh)])


@pytest.mark.parametrize("name", SCENES)
def test_joint_rows_do_not_depend_on_the_other_joints(name):
    """Each joint's rows of Phi, Phi_h and gamma, and its reaction outputs, are the same bits in
    the whole mechanism as in the mechanism reduced to that joint alone (with the same bodies):
    nothing of one joint's evaluation leaks into another's."""
    spec, model = model_of(name)
    k = kernel_for(model, spec.solver)
    joints = spec.mechanism.joints
    rng = np.random.default_rng(1)
    ys = list(random_states(model, n=4, seed=2))
    lams = [rng.standard_normal(model.m) for _ in ys]
    whole = [(tuple(x.copy() for x in k.rows(y)), k.outputs(y, lam)[0].copy()) for y, lam in zip(ys, lams)]
    for n, c in enumerate(model.joints):
        alone_spec = dataclasses.replace(spec, mechanism=dataclasses.replace(spec.mechanism, joints=(joints[n],)),
                                         eliminate=(), friction=(), friction_params={}, reactions=(joints[n].name,),
                                         friction_outputs=())
        alone = compile_checked(alone_spec, check_initial=False)
        ka = kernel_for(alone, spec.solver)
        rows = list(c.rows)
        for y, lam, ((phi, J, gam), reac) in zip(ys, lams, whole):
            a_phi, a_J, a_gam = ka.rows(y)
            assert np.array_equal(a_phi, phi[rows]) and np.array_equal(a_J, J[rows])
            assert np.array_equal(a_gam, gam[rows])
            assert np.array_equal(ka.outputs(y, lam[rows])[0][0], reac[n])


def test_spherical_friction_zero_reaction_gives_zero_force():
    """A spherical joint without reaction (its multipliers 0) reports zero friction (no contact
    point), the other friction joint its law's positive magnitude."""
    spec, model = model_of("spatial_GHMN_wo5")
    k = kernel_for(model, spec.solver)
    y = np.concatenate([model.q0 + 0.1, model.h0 + 1.0])
    first, second = model.friction_joints[:2]
    lam = np.ones(model.m)
    lam[list(model.joints[second].rows)] = 0.0
    fric = k.outputs(y, lam)[1]
    assert fric[second] == 0.0 and fric[first] > 0.0


def test_coordinate_rates_singularity_names_first_body():
    """Two bodies at beta = 0: the core refuses naming the first (body 2, link3)."""
    spec, model = model_of("spatial_MN_wo5")
    k = kernel_for(model, spec.solver)
    q = model.q0.copy()
    q[2 * 6 + 4] = 0.0  # beta of link3
    q[4 * 6 + 4] = 0.0  # beta of link5
    assert model.body_names[2] == "link3"
    assert k.evaluate(0.0, np.concatenate([q, model.h0])) is None and k.last_status == 3
    assert k.last_message.startswith("Euler angles singular: body 2 has |sin beta| = 0 ")


def test_plan_follows_replaced_model():
    """A model whose retained equations were replaced gets its own matching plan (built by
    Model.__post_init__; no cache), and a Model's arrays cannot be written to."""
    _, model = model_of("planar_f45_wo4")
    row = model.joints[model.friction_joints[0]].rows[0]  # a friction row, retained in model
    assert row in model.retained and len(model.plan.friction_xrows) == sum(len(model.joints[j].rows)
                                                                          for j in model.friction_joints)
    other = dataclasses.replace(model, retained=np.array([i for i in range(model.m) if i != row]))
    expected = build_plan(other)
    assert len(other.plan.friction_xrows) == len(model.plan.friction_xrows) - 1  # the eliminated row reads 0
    assert np.array_equal(other.plan.friction_xrows, expected.friction_xrows)
    for arr in (model.q0, model.M, model.retained, model.joints[0].p["s_A"], model.plan.friction[0].x_index,
                model.plan.friction_xrows):
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = 1.0
