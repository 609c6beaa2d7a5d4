"""Cross-check of the frictionless door and four-bar against Exudyn (issue: spatial joint library).

Each mechanism is built a second time, independently, in Exudyn (rigid bodies with Euler-parameter
nodes, Exudyn's own revolute joints, its generalized-alpha integrator with a fixed step and
``ignoreSingularJacobian`` for the redundant equations), from the physical description in the
mechanism file's comments (dimensions, masses, hinge line), not from our parsed model. The centre of
mass positions of our run (dopri5, tolerance 1e-10) and of Exudyn's must agree to 1e-6 m over 0-2 s.
Exudyn's fixed step: 2.5e-4 s for the door, 6.25e-5 s for the four-bar, whose difference from our
run shrinks fourfold per halved step (second order: 1.0e-5, 2.7e-6, 6.6e-7 m at 5e-4, 2.5e-4,
1.25e-4 s), i.e. it is Exudyn's own step error (docs/examples.md).

The door on two compliant hinges (``redundancy = "compliant"``, mechanisms/examples/compliant_door.toml,
without friction) is built there from rigid-body spring-dampers (Exudyn's RigidBodySpringDamper: a
translational spring-damper on the hinge points' separation and a rotational one on the tilt of
the door's hinge axis, none about the axis), with the file's stiffnesses and dampings in the hinge
frame, and at a thousandth of them, where the compliance moves the door by millimetres. Our run
of it goes through the compiled core (core/compliance.c), which the test asserts.

Exudyn is part of the ``test`` extra (``pip install -e ".[test]"``); without it the tests are skipped.
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

exu = pytest.importorskip("exudyn")
from exudyn.utilities import MarkerBodyRigid, RigidBodyInertia, RigidBodySpringDamper, SensorBody  # noqa: E402

from overcon import scene as scene_mod  # noqa: E402
from overcon.converge import scaled_scene  # noqa: E402
from overcon.simulate import run_scene  # noqa: E402

MECH = Path(__file__).resolve().parent.parent / "mechanisms" / "examples"
STOP = 2.0
BOUND = 1e-6  # m


def _solve(mbs, bodies, step, newton_tolerance=1e-12, fixed_step=False):
    """Exudyn's generalized-alpha run to STOP; the bodies' positions every 0.01 s. ``fixed_step``
    forbids Exudyn's step reduction, which would move its output times off our grid."""
    sensors = [mbs.AddSensor(SensorBody(bodyNumber=b, storeInternal=True,
                                        outputVariableType=exu.OutputVariableType.Position)) for b in bodies]
    mbs.Assemble()
    ss = exu.SimulationSettings()
    ss.timeIntegration.numberOfSteps = int(round(STOP / step))
    ss.timeIntegration.endTime = STOP
    ss.timeIntegration.verboseMode = 0
    ss.timeIntegration.generalizedAlpha.spectralRadius = 1.0  # no numerical damping
    ss.timeIntegration.newton.relativeTolerance = newton_tolerance
    ss.timeIntegration.newton.absoluteTolerance = newton_tolerance
    if fixed_step:
        ss.timeIntegration.adaptiveStep = False
        ss.timeIntegration.newton.useModifiedNewton = False
    ss.solution.file.write = False
    ss.linearSolver.solverType = exu.LinearSolverType.EigenDense
    ss.linearSolver.ignoreSingularJacobian = True  # redundant hinge equations
    ss.solution.sensors.writePeriod = 0.01
    exu.SolveDynamic(mbs, ss)
    return [mbs.GetSensorStoredData(s) for s in sensors]  # rows [t, x, y, z]


def exudyn_door():
    """20 kg plate 0.8 x 0.04 x 2.0 m, centre [0.5, 0, 1], identity orientation; two hinges on the
    line through the origin along a = [sin 0.1, 0, cos 0.1] at heights 0.2 and 1.8 m; 1 rad/s about a."""
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.CreateGround()
    m, w, t, h = 20.0, 0.8, 0.04, 2.0
    a = np.array([math.sin(0.1), 0.0, math.cos(0.1)])
    com = np.array([0.5, 0.0, 1.0])
    J = np.diag([m / 12 * (h * h + t * t), m / 12 * (w * w + h * h), m / 12 * (w * w + t * t)])
    p1 = a / a[2] * 0.2
    door = mbs.CreateRigidBody(inertia=RigidBodyInertia(mass=m, inertiaTensor=J), referencePosition=com,
                               initialVelocity=np.cross(a, com - p1), initialAngularVelocity=a,
                               gravity=[0.0, 0.0, -9.81], nodeType=exu.NodeType.RotationEulerParameters)
    for height in (0.2, 1.8):
        mbs.CreateRevoluteJoint(itemNumbers=[ground, door], position=a / a[2] * height, axis=a, useGlobalFrame=True)
    return _solve(mbs, [door], 2.5e-4)


def exudyn_fourbar():
    """Rods of 1 kg/m, radius 0.02 m: crank A-B, coupler B-C, rocker D-C with A = 0, B = [0.5, sqrt(3)/2, 0],
    C = [2, 1.5, 0], D = [2, 0, 0]; four revolute joints along z; gravity 9.81 m/s^2 tilted 0.3 rad to -z."""
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.CreateGround()
    g = [0.0, -9.81 * math.cos(0.3), -9.81 * math.sin(0.3)]

    def rod(p, q, r=0.02):
        p, q = np.array(p, float), np.array(q, float)
        length = float(np.linalg.norm(q - p))
        m = length
        th = math.atan2(q[1] - p[1], q[0] - p[0])
        R = np.array([[math.cos(th), -math.sin(th), 0.0], [math.sin(th), math.cos(th), 0.0], [0.0, 0.0, 1.0]])
        J = np.diag([m * r * r / 2, m * length ** 2 / 12, m * length ** 2 / 12])
        return mbs.CreateRigidBody(inertia=RigidBodyInertia(mass=m, inertiaTensor=J), referencePosition=(p + q) / 2,
                                   referenceRotationMatrix=R, gravity=g, nodeType=exu.NodeType.RotationEulerParameters)

    A, B, C, D = [0.0, 0.0, 0.0], [0.5, math.sqrt(3) / 2, 0.0], [2.0, 1.5, 0.0], [2.0, 0.0, 0.0]
    crank, coupler, rocker = rod(A, B), rod(B, C), rod(D, C)
    for pair, pos in (([ground, crank], A), ([crank, coupler], B), ([coupler, rocker], C), ([rocker, ground], D)):
        mbs.CreateRevoluteJoint(itemNumbers=pair, position=pos, axis=[0.0, 0.0, 1.0], useGlobalFrame=True)
    return _solve(mbs, [crank, coupler, rocker], 6.25e-5)


def ours(scene_file: str, bodies):
    scene = scene_mod.load(MECH / scene_file)
    scene = replace(scene, positions=tuple(f"{b}.{c}" for b in bodies for c in "xyz"), reactions=(),
                    friction_outputs=(), solver=replace(scene.solver, tolerance=1e-10, output_interval=0.01))
    res = run_scene(scene)
    return res.time, res.values.reshape(len(res.time), len(bodies), 3)


@pytest.mark.parametrize("scene_file, bodies, peer", [
    ("door_none_wo_hinge2.toml", ["door"], exudyn_door),
    ("fourbar_none_wo18_19_20.toml", ["crank", "coupler", "rocker"], exudyn_fourbar),
])
def test_frictionless_motion_equals_exudyn(scene_file, bodies, peer):
    t, xyz = ours(scene_file, bodies)
    data = peer()
    for k, d in enumerate(data):
        assert np.allclose(d[:, 0], t, atol=1e-9), "Exudyn's sensor times differ from our output grid"
        err = np.max(np.abs(d[:, 1:4] - xyz[:, k, :]))
        assert err <= BOUND, f"{scene_file}: body {bodies[k]} differs from Exudyn by {err:.3g} m (> {BOUND:g} m)"


# The compliant door's hinges (compliant_door.toml): N/m, N.m/rad, N.s/m, N.m.s/rad, the same for both.
HINGE = {"stiffness": 1e8, "rotational_stiffness": 1e6, "damping": 1e4, "rotational_damping": 1e2}


def exudyn_compliant_door(scale: float):
    """The door of :func:`exudyn_door` on two compliant hinges, each a RigidBodySpringDamper between
    the hinge point on the door and on the ground, in the hinge frame (z along a): translational
    stiffness k and damping d on x, y, z, rotational kr and dr on x and y (the tilt of the axis),
    nothing about z (the hinge turns freely). Stiffnesses are HINGE's times ``scale``, dampings
    times sqrt(scale)."""
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.CreateGround()
    m, w, t, h = 20.0, 0.8, 0.04, 2.0
    a = np.array([math.sin(0.1), 0.0, math.cos(0.1)])
    com = np.array([0.5, 0.0, 1.0])
    J = np.diag([m / 12 * (h * h + t * t), m / 12 * (w * w + h * h), m / 12 * (w * w + t * t)])
    p1 = a / a[2] * 0.2
    door = mbs.CreateRigidBody(inertia=RigidBodyInertia(mass=m, inertiaTensor=J), referencePosition=com,
                               initialVelocity=np.cross(a, com - p1), initialAngularVelocity=a,
                               gravity=[0.0, 0.0, -9.81], nodeType=exu.NodeType.RotationEulerParameters)
    y = np.array([0.0, 1.0, 0.0])
    frame = np.column_stack([np.cross(y, a), y, a])  # hinge frame in global axes (door in identity orientation)
    k, kr = HINGE["stiffness"] * scale, HINGE["rotational_stiffness"] * scale
    d, dr = HINGE["damping"] * math.sqrt(scale), HINGE["rotational_damping"] * math.sqrt(scale)
    for height in (0.2, 1.8):
        p = a / a[2] * height
        on_door = mbs.AddMarker(MarkerBodyRigid(bodyNumber=door, localHT=exu.HT(rotation=frame, translation=p - com)))
        on_ground = mbs.AddMarker(MarkerBodyRigid(bodyNumber=ground, localHT=exu.HT(rotation=frame, translation=p)))
        mbs.AddObject(RigidBodySpringDamper(markerNumbers=[on_door, on_ground],
                                            stiffness=np.diag([k, k, k, kr, kr, 0.0]),
                                            damping=np.diag([d, d, d, dr, dr, 0.0])))
    # Newton to 1e-8: with springs of 1e8 N/m its residual stalls near 1e-9 (numerical Jacobian)
    return _solve(mbs, [door], 2.5e-4, newton_tolerance=1e-8, fixed_step=True)


def ours_compliant_door(k: float):
    """Our run of the compliant door without friction, its hinges scaled to translational
    stiffness k (converge's rule: stiffnesses times k / 1e8, dampings times sqrt(k / 1e8));
    radau at tolerance 1e-9."""
    spec = scene_mod.load(MECH / "compliant_door_h1_wo_hinge2.toml")
    for joint in spec.mechanism.joints:  # the physical description above is the file's
        c = joint.compliance
        assert (c.stiffness, c.rotational_stiffness, c.damping, c.rotational_damping) == tuple(HINGE.values()), joint
    spec = replace(scaled_scene(spec, k), friction=(), positions=("door.x", "door.y", "door.z"), reactions=(),
                   friction_outputs=(), solver=replace(spec.solver, tolerance=1e-9, output_interval=0.01))
    res = run_scene(spec)
    # the compliant hinges' forces come from the compiled core (core/compliance.c), every evaluation
    assert res.kernel_note.startswith("right-hand side: compiled kernel"), res.kernel_note
    return res.time, res.values


@pytest.mark.parametrize("scale", [1.0, 1e-3])
def test_compliant_door_equals_exudyn(scale):
    """Measured (Exudyn 1.13.6, step 2.5e-4 s): 3.1e-8 m at the file's stiffnesses, 1.2e-7 m at a
    thousandth of them, where the compliant door runs up to 2.0e-3 m from the rigid one."""
    t, xyz = ours_compliant_door(HINGE["stiffness"] * scale)
    (data,) = exudyn_compliant_door(scale)
    assert np.allclose(data[:, 0], t, atol=1e-9), "Exudyn's sensor times differ from our output grid"
    err = np.max(np.abs(data[:, 1:4] - xyz))
    assert err <= BOUND, f"compliant door at {scale:g} x the file's stiffness differs from Exudyn by {err:.3g} m"
    if scale < 1.0:  # soft enough that the check sees the compliance, not only the rigid motion
        t_rigid, rigid = ours("door_none_wo_hinge2.toml", ["door"])
        assert np.max(np.abs(xyz - rigid[:, 0, :])) > 100 * BOUND
