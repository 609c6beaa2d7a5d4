"""Unit-quaternion orientation of spatial bodies (``[mechanism] rotation = "quaternion"``):
kinematics against the z-x-z Euler angles, the identity orientation, agreement of the two
parametrisations, a torque-free rigid body, scene loading, the pre-check and the FMU."""
from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from overcon.cli import main
from overcon.model import InconsistentInitialState
from overcon.checks import compile_checked
from overcon.scene import SceneError, as_scene, load
from overcon.simulate import Simulation, run, run_scene
from overcon.spec import BodySpec, JointSpec, LoadSpec, MechanismSpec, SolverSpec
from overcon.tooling.fmus import inspect_fmu

from test_core_rows import EPS_FD, FD_REL, quat_mul, rates, rx, rz
from test_kernel import kernel_for, quaternion_spec, spec_of, states
from test_kernel import quat_of_euler as euler_to_quat

QUAT_NORM_RATE = 1.0
"""The quaternion norm stabilisation rate k (1/s; core/core.h): d|e|^2/dt = k (1 - |e|^2) |e|^2."""


def euler_R(angles) -> np.ndarray:
    """Rotation body -> global of z-x-z Euler angles (paper Eq. 40)."""
    return rz(angles[0]) @ rx(angles[1]) @ rz(angles[2])


def quat_R(e) -> np.ndarray:
    """The rotation of the quaternion e (scalar first), normalised."""
    e0, e1, e2, e3 = np.asarray(e, float) / np.linalg.norm(e)
    return np.array([[e0 * e0 + e1 * e1 - e2 * e2 - e3 * e3, 2 * (e1 * e2 - e0 * e3), 2 * (e1 * e3 + e0 * e2)],
                     [2 * (e1 * e2 + e0 * e3), e0 * e0 - e1 * e1 + e2 * e2 - e3 * e3, 2 * (e2 * e3 - e0 * e1)],
                     [2 * (e1 * e3 - e0 * e2), 2 * (e2 * e3 + e0 * e1), e0 * e0 - e1 * e1 - e2 * e2 + e3 * e3]])

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data" / "quaternion"
PENDULUM = DATA / "pendulum.toml"
PENDULUM_SCENE = DATA / "pendulum_scene.toml"


def random_angles(rng):
    """z-x-z angles away from the Euler singularity."""
    return np.array([rng.uniform(-np.pi, np.pi), rng.uniform(0.2, np.pi - 0.2), rng.uniform(-np.pi, np.pi)])


# ------------------------------------------------------------------------------- kinematics

def euler_and_quaternion_kernels():
    """The paper's spatial mechanism (spherical joints) in z-x-z angles and in quaternions: (model,
    kernel) of each."""
    out = []
    for spec in (spec_of("spatial_none_wo5"), quaternion_spec(spec_of("spatial_none_wo5"))):
        model = compile_checked(spec)
        out.append((model, kernel_for(model, spec.solver)))
    return out


def as_quaternions(q_euler, nb) -> np.ndarray:
    return np.concatenate([np.r_[q_euler[6 * b: 6 * b + 3], euler_to_quat(q_euler[6 * b + 3: 6 * b + 6])]
                           for b in range(nb)])


def test_quaternion_and_euler_rows_agree():
    """The core's rotation of a quaternion is that of the z-x-z angles it was made from: Phi,
    Phi_h and gamma of the paper's spatial mechanism agree to round-off (1e-13 relative) between
    the two rotations at random states (the same h: body-axis angular velocities)."""
    (me, ke), (mq, kq) = euler_and_quaternion_kernels()
    for y in states(me, 10, seed=1):
        q, h = y[: me.n], y[me.n:]
        yq = np.concatenate([as_quaternions(q, me.nb), h])
        for a, b in zip(ke.rows(y), kq.rows(yq)):
            assert np.max(np.abs(a - b)) <= 1e-13 * max(1.0, float(np.max(np.abs(a))))


def test_quaternion_R_uses_the_normalised_quaternion():
    """Scaling a body's quaternion changes none of the core's rows (R(e / |e|))."""
    _, (mq, kq) = euler_and_quaternion_kernels()
    rng = np.random.default_rng(2)
    for y in states(mq, 5, seed=2):
        z = y.copy()
        for b in range(mq.nb):
            z[7 * b + 3: 7 * b + 7] *= rng.uniform(0.5, 2.0)
        for a, c in zip(kq.rows(y), kq.rows(z)):
            assert np.max(np.abs(a - c)) <= 1e-14 * max(1.0, float(np.max(np.abs(a))))


def test_quaternion_of_euler_composes_rotations():
    """The test's conversion (z-x-z angles to the quaternion product of the elementary rotations)
    gives the Euler angles' rotation, orthonormal; the product composes rotations."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        a, b = random_angles(rng), random_angles(rng)
        ea, eb = euler_to_quat(a), euler_to_quat(b)
        assert abs(np.linalg.norm(ea) - 1.0) <= 1e-15
        assert np.max(np.abs(quat_R(ea) - euler_R(a))) <= 1e-15
        assert np.max(np.abs(quat_R(ea) @ quat_R(eb) - quat_R(quat_mul(ea, eb)))) <= 1e-15


def test_quaternion_rates_by_finite_differences_of_R():
    """The core's rates of a unit quaternion, e' = 1/2 e (x) (0, omega) with omega in body axes:
    d/dt R(e) = R skew(omega) by central differences, and e . e' = 0."""
    _, (mq, kq) = euler_and_quaternion_kernels()
    rng = np.random.default_rng(4)
    for y in states(mq, 10, seed=4):
        q, h = y[: mq.n].copy(), 2.0 * rng.normal(size=mq.nh)
        for b in range(mq.nb):
            q[7 * b + 3: 7 * b + 7] /= np.linalg.norm(q[7 * b + 3: 7 * b + 7])
        qd = rates(kq, mq, q, h)
        for b in range(mq.nb):
            e, ed, w = q[7 * b + 3: 7 * b + 7], qd[7 * b + 3: 7 * b + 7], h[6 * b + 3: 6 * b + 6]
            fd = (quat_R(e + EPS_FD * ed) - quat_R(e - EPS_FD * ed)) / (2 * EPS_FD)
            W = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
            assert np.max(np.abs(fd - quat_R(e) @ W)) <= FD_REL * max(1.0, float(np.max(np.abs(w))))
            assert abs(e @ ed) <= 1e-15 * max(1.0, float(np.max(np.abs(w))))


def test_quaternion_norm_stabilisation_is_radial():
    """The core's rates off the unit sphere: d|e|^2/dt = k (1 - |e|^2) |e|^2 (k = QUAT_NORM_RATE),
    and the difference from 1/2 e (x) (0, omega) lies along e."""
    _, (mq, kq) = euler_and_quaternion_kernels()
    rng = np.random.default_rng(5)
    q = mq.q0.copy()
    for b in range(mq.nb):
        q[7 * b + 3: 7 * b + 7] = rng.normal(size=4)
    h = rng.normal(size=mq.nh)
    qd = rates(kq, mq, q, h)
    for b in range(mq.nb):
        e, ed, w = q[7 * b + 3: 7 * b + 7], qd[7 * b + 3: 7 * b + 7], h[6 * b + 3: 6 * b + 6]
        n2 = e @ e
        assert 2 * (e @ ed) == pytest.approx(QUAT_NORM_RATE * (1 - n2) * n2, rel=1e-13, abs=1e-15)
        extra = ed - 0.5 * quat_mul(e, np.r_[0.0, w])
        assert np.max(np.abs(extra - 0.5 * QUAT_NORM_RATE * (1 - n2) * e)) <= 1e-14 * max(1.0, n2)


def test_euler_to_quaternion_of_every_orientation_including_the_euler_singularity():
    assert np.array_equal(euler_to_quat([0.0, 0.0, 0.0]), [1.0, 0.0, 0.0, 0.0])
    e = euler_to_quat([0.3, 0.0, 0.4])  # beta = 0: a rotation by 0.7 about z
    assert np.allclose(e, [np.cos(0.35), 0.0, 0.0, np.sin(0.35)], rtol=0, atol=1e-15)


# ------------------------------------------------------------------------------- mechanisms

def pendulum_mech(rotation: str, angles, w_body, *, force=(1.0, 0.0, 0.0), s_i=(0.0, 0.0, 0.5)) -> MechanismSpec:
    """A rod on a spherical joint at the base origin (joint at body point s_i), orientation the
    z-x-z ``angles``, body-axes angular velocity ``w_body``, consistent h0."""
    R = euler_R(angles)
    s_i = np.array(s_i)
    r = -R @ s_i
    v = -R @ np.cross(w_body, s_i)
    orient = tuple(euler_to_quat(angles)) if rotation == "quaternion" else tuple(angles)
    body = BodySpec("rod", 1.0, (0.1, 0.12, 0.01), tuple(float(x) for x in (*r, *orient)),
                    tuple(float(x) for x in (*v, *w_body)))
    joint = JointSpec("P", "spherical", "rod", "base", {"s_i": tuple(s_i), "s_j": (0.0, 0.0, 0.0)})
    loads = (LoadSpec("force", {"body": "rod", "value": tuple(force)}),)
    return MechanismSpec("pendulum", "spatial", (0.0, 0.0, -9.81), (body,), (joint,), loads, rotation=rotation)


def test_jacobian_times_h_is_the_rate_of_phi_along_the_quaternion_flow():
    """The core's Phi_h h = d/dt Phi(q) with q' its coordinate rates (central differences), at a
    configuration off the constraints too."""
    rng = np.random.default_rng(6)
    scene = as_scene(pendulum_mech("quaternion", random_angles(rng), rng.normal(size=3)))
    model = compile_checked(scene, check_initial=False)
    k = kernel_for(model, scene.solver)
    for _ in range(5):
        q = model.q0 + 0.1 * rng.normal(size=model.n)
        q[3:] /= np.linalg.norm(q[3:])
        h = rng.normal(size=model.nh)
        qd = rates(k, model, q, h)
        eps = 1e-6
        fd = (k.rows(np.r_[q + eps * qd, h])[0] - k.rows(np.r_[q - eps * qd, h])[0]) / (2 * eps)
        assert np.max(np.abs(k.rows(np.r_[q, h])[1] @ h - fd)) <= 1e-8


def test_model_splits_coordinates_and_velocities():
    model = compile_checked(load(PENDULUM_SCENE))
    assert (model.nq_b, model.nh_b, model.n, model.nh) == (7, 6, 7, 6)
    assert model.output_names()[:7] == ["rod.x", "rod.y", "rod.z", "rod.e0", "rod.e1", "rod.e2", "rod.e3"]
    assert [i for _, i in model.position_outputs] == list(range(7))
    euler = compile_checked(as_scene(pendulum_mech("euler_zxz", [0.1, 0.8, 0.2], [0.0, 0.0, 0.0])))
    assert (euler.nq_b, euler.nh_b, euler.n, euler.nh) == (6, 6, 6, 6)


def test_identity_orientation_simulates_with_quaternions_and_conserves_energy():
    """The rod hanging straight down (identity orientation): Euler angles refuse it
    (beta = 0), quaternions integrate it. Without friction the energy
    1/2 m v^2 + 1/2 w.J w + m g z - F.r is conserved to the integration error."""
    euler = as_scene(pendulum_mech("euler_zxz", [0.0, 0.0, 0.0], [-1.0, 0.0, 2.0]), eliminate=[], stop_time=1.0)
    with pytest.raises(InconsistentInitialState, match="Euler angle singularity"):
        run_scene(euler)
    mech = load(PENDULUM)
    assert mech.rotation == "quaternion" and mech.bodies[0].q0[3:] == (1.0, 0.0, 0.0, 0.0)
    model = compile_checked(as_scene(mech, eliminate=[], stop_time=2.0))
    tol = 1e-10
    sim = Simulation(model, SolverSpec(tolerance=tol))
    J = np.array(mech.bodies[0].inertia)
    F = np.array([1.0, 0.0, 0.0])

    def energy(y):
        r, e, v, w = y[:3], y[3:7], y[7:10], y[10:13]
        return 0.5 * v @ v + 0.5 * w @ (J * w) + 9.81 * r[2] - F @ r

    E0 = energy(np.concatenate([model.q0, model.h0]))
    worst = 0.0
    for t in np.linspace(0.1, 2.0, 20):
        y = sim.advance(t)
        worst = max(worst, abs(energy(y) - E0))
    steps = sim.steps
    # local error per step <= tol (1 + |y|) per component; |y| <= 3 here; energy gradient <= 10
    assert worst <= steps * tol * 4 * 10
    assert sim.max_drift <= 1e-8
    assert steps > 20  # the run did take steps through the orientations near the identity


def test_euler_and_quaternion_give_the_same_motion():
    """Same rod and initial state away from the Euler singularity, both parametrisations at
    tolerance 1e-10: positions agree to the integration error (global error ~ steps * tol)."""
    angles, w = [0.3, 0.9, -0.5], [1.0, -0.5, 2.0]
    tol = 1e-10
    out = {}
    for rotation in ("euler_zxz", "quaternion"):
        scene = as_scene(pendulum_mech(rotation, angles, w), eliminate=[], stop_time=1.0)
        model = compile_checked(scene)
        res = run(model, SolverSpec(tolerance=tol), output_interval=0.05)
        out[rotation] = res
    xyz = ["rod.x", "rod.y", "rod.z"]
    a = np.column_stack([out["euler_zxz"].column(n) for n in xyz])
    b = np.column_stack([out["quaternion"].column(n) for n in xyz])
    assert np.max(np.abs(a - b)) <= 1e-6
    # the orientations agree too: R from the Euler angles against R from the quaternion outputs
    ang = np.column_stack([out["euler_zxz"].column(f"rod.{c}") for c in ("alpha", "beta", "gamma")])
    quat = np.column_stack([out["quaternion"].column(f"rod.e{k}") for k in range(4)])
    assert np.max(np.abs(np.array([euler_R(x) for x in ang]) - np.array([quat_R(e) for e in quat]))) <= 1e-6
    assert np.max(np.abs(a[-1] - a[0])) > 0.1  # the rod did move


def test_torque_free_asymmetric_body_conserves_energy_momentum_and_quaternion_norm():
    """An asymmetric body on a spherical joint at its centre of mass (gravity balanced by the
    joint): no torque about the centre of mass, so the kinetic energy and the angular momentum
    vector R J omega (global frame) are constant. Tumbling near the intermediate axis over 20 s.
    Bounds: the global error of dopri5 grows at most like steps * tol * scale; the quaternion
    norm is pulled to 1 at QUAT_NORM_RATE (1/s) against an error of at most tol (1 + |y|) per
    step, so |e| - 1 stays below 2 tol times the steps taken in 1/k seconds."""
    J = np.array([1.0, 2.0, 3.0])
    w0 = np.array([0.05, 2.0, 0.05])
    tol = 1e-10
    body = BodySpec("top", 1.0, tuple(J), (0.0, 0.0, 0.0, *euler_to_quat([0.2, 1.0, 0.3])), (0.0, 0.0, 0.0, *w0))
    joint = JointSpec("C", "spherical", "top", "base", {"s_i": (0.0, 0.0, 0.0), "s_j": (0.0, 0.0, 0.0)})
    mech = MechanismSpec("top", "spatial", (0.0, 0.0, -9.81), (body,), (joint,), (), rotation="quaternion")
    model = compile_checked(as_scene(mech, eliminate=[], stop_time=20.0))
    sim = Simulation(model, SolverSpec(tolerance=tol))

    def invariants(y):
        e, w = y[3:7], y[10:13]
        L = quat_R(e) @ (J * w)
        return 0.5 * w @ (J * w), L, np.linalg.norm(e)

    T0, L0, _ = invariants(np.concatenate([model.q0, model.h0]))
    dT = dL = dn = 0.0
    w_min = np.inf
    for t in np.linspace(0.1, 20.0, 200):
        y = sim.advance(t)
        T, L, n = invariants(y)
        dT, dL, dn = max(dT, abs(T - T0)), max(dL, np.max(np.abs(L - L0))), max(dn, abs(n - 1.0))
        w_min = min(w_min, y[11])
    steps = sim.steps
    scale = 1.0 + 4.0  # |y| <= 4 here (|omega| <= 2.01, |e| = 1)
    assert dT <= steps * tol * scale * 6  # |dT/dw| <= |J w| <= 6
    assert dL <= steps * tol * scale * 6 * 2  # |L| <= 6, through R and J w
    steps_per_relaxation = steps / 20.0 / QUAT_NORM_RATE
    assert dn <= 2 * tol * scale * steps_per_relaxation
    assert w_min < -1.0  # the body did tumble: omega_y reversed


# ------------------------------------------------------------------------------- scene files

def _mech_text(rotation: str | None = "quaternion", kind="spatial", q0="[0.0, 0.0, -0.5, 1.0, 0.0, 0.0, 0.0]",
               h0=None) -> str:
    lines = ['[mechanism]', 'name = "m"', f'kind = "{kind}"']
    if kind == "spatial":
        lines.append("gravity = [0.0, 0.0, -9.81]")
    else:
        lines.append("gravity = [0.0, -9.81]")
    if rotation is not None:
        lines.append(f'rotation = "{rotation}"')
    lines += ['[[bodies]]', 'name = "rod"', 'mass = 1.0',
              'inertia = [0.1, 0.1, 0.01]' if kind == "spatial" else 'inertia = 0.1', f'q0 = {q0}']
    if h0 is not None:
        lines.append(f"h0 = {h0}")
    return "\n".join(lines) + "\n"


def _problems(path: Path) -> list:
    with pytest.raises(SceneError, match=re.escape(str(path))) as err:
        load(path)
    return err.value.problems


def test_rotation_key_errors(tmp_path):
    p = tmp_path / "planar.toml"
    p.write_text(_mech_text("quaternion", kind="planar", q0="[0.0, 0.0, 0.0]"))
    [prob] = _problems(p)
    assert (prob.file, prob.field) == (str(p), "mechanism.rotation")
    assert "planar" in prob.message and "spatial mechanisms only" in prob.message
    p.write_text(_mech_text("euler_xyz"))
    probs = _problems(p)
    assert [(x.file, x.field) for x in probs] == [(str(p), "mechanism.rotation")]
    assert "quaternion" in probs[0].message and "euler_zxz" in probs[0].message
    p.write_text(_mech_text(None, q0="[0.0, 0.0, -0.5, 0.1, 0.2, 0.3]"))
    assert load(p).rotation == "euler_zxz"  # the default


@pytest.mark.parametrize("rotation, q0, h0, field", [
    ("quaternion", "[0.0, 0.0, -0.5, 1.0, 0.0, 0.0]", None, "bodies[0].q0"),
    ("euler_zxz", "[0.0, 0.0, -0.5, 1.0, 0.0, 0.0, 0.0]", None, "bodies[0].q0"),
    ("quaternion", "[0.0, 0.0, -0.5, 1.0, 0.0, 0.0, 0.0]", "[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]", "bodies[0].h0"),
])
def test_coordinate_vector_lengths(tmp_path, rotation, q0, h0, field):
    p = tmp_path / "m.toml"
    p.write_text(_mech_text(rotation, q0=q0, h0=h0))
    [prob] = _problems(p)
    assert (prob.file, prob.field) == (str(p), field)
    n = 7 if field.endswith("q0") and rotation == "quaternion" else 6
    assert f"expected an array of {n} numbers" in prob.message


def test_non_unit_quaternion_refused_and_near_unit_normalised(tmp_path):
    p = tmp_path / "m.toml"
    p.write_text(_mech_text(q0="[0.0, 0.0, -0.5, 1.0, 0.0, 0.01, 0.0]"))
    [prob] = _problems(p)
    assert (prob.file, prob.field) == (str(p), "bodies[0].q0")
    assert "body 'rod'" in prob.message and "norm 1.00004999" in prob.message
    p.write_text(_mech_text(q0="[0.0, 0.0, -0.5, 0.6, 0.0, 0.8000004, 0.0]"))  # |e| = 1 + 3.2e-7
    e = np.array(load(p).bodies[0].q0[3:])
    assert abs(np.linalg.norm(e) - 1.0) <= 1e-15
    assert np.allclose(e, [0.6, 0.0, 0.8, 0.0], rtol=0, atol=1e-6)


def test_position_outputs_name_the_quaternion(tmp_path):
    mech = load(PENDULUM)
    scene = as_scene(mech)
    assert scene.positions[3:7] == ("rod.e0", "rod.e1", "rod.e2", "rod.e3")
    (tmp_path / "pendulum.toml").write_text(PENDULUM.read_text())
    s = tmp_path / "s.toml"
    head = '[scene]\nname = "s"\nmechanism = "pendulum.toml"\nfriction = []\neliminate = []\nstop_time = 1.0\n'
    s.write_text(head + '[outputs]\npositions = ["rod.alpha"]\n')
    [prob] = _problems(s)
    assert prob.field == "outputs.positions[0]" and "e0, e1, e2, e3" in prob.message
    s.write_text(head + '[outputs]\npositions = ["rod.e2"]\n')
    assert load(s).positions == ("rod.e2",)


def test_outputs_report_the_normalised_quaternion():
    res = run_scene(load(PENDULUM_SCENE))
    e = np.column_stack([res.column(f"rod.e{k}") for k in range(4)])
    assert np.max(np.abs(np.linalg.norm(e, axis=1) - 1.0)) <= 1e-15
    assert np.max(np.abs(e[-1] - e[0])) > 0.05


def test_check_json_counts_velocity_coordinates(capsys):
    assert main(["check", str(PENDULUM_SCENE), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert (doc["n_coordinates"], doc["n_equations"], doc["rank"], doc["dof"]) == (6, 3, 3, 3)
    assert doc["kind"] == "spatial"


# ------------------------------------------------------------------------------- FMU

fmpy = pytest.importorskip("fmpy")


def test_fmu_of_a_quaternion_scene(tmp_path):
    from test_fmu import Instance
    proc = subprocess.run([sys.executable, str(ROOT / "build_fmu.py"), str(PENDULUM_SCENE), "--out", str(tmp_path),
                           "--no-ref"], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    fmu = tmp_path / "quat_pendulum_friction.fmu"
    md = fmpy.read_model_description(str(fmu))
    by_name = {v.name: v for v in md.modelVariables}
    for k in range(4):
        v = by_name[f"rod.e{k}"]
        assert v.causality == "output" and f"e{k}" in v.description and "quaternion" in v.description
    assert "rod.alpha" not in by_name
    kinds = {o.name: o.kind for o in inspect_fmu(fmu).outputs}  # quaternion outputs decide verdicts
    assert [kinds[f"rod.{c}"] for c in ("x", "e0", "e3")] == ["position"] * 3 and kinds["P.Fx"] == "reaction"
    res = fmpy.simulate_fmu(str(fmu), stop_time=0.2)
    ref = run_scene(load(PENDULUM_SCENE), stop_time=0.2)
    got = np.column_stack([res[n] for n in ref.names])
    assert np.max(np.abs(got - ref.values)) <= 1e-9
    e = np.column_stack([res[f"rod.e{k}"] for k in range(4)])
    assert np.max(np.abs(np.linalg.norm(e, axis=1) - 1.0)) <= 1e-15
    # FMU state with 7 coordinates per body: get, serialize, restore, continue identically
    unz = Path(fmpy.extract(str(fmu), unzipdir=str(tmp_path / "unz")))
    inst = Instance(unz).init()
    inst.steps(5)
    t, k = inst.t, inst.k
    state = inst.fmu.getFMUstate()
    data = inst.fmu.serializeFMUstate(state)
    first = inst.steps(5)
    inst.fmu.freeFMUstate(state)
    restored = inst.fmu.deSerializeFMUstate(data)
    inst.fmu.setFMUstate(restored)
    inst.t, inst.k = t, k
    assert np.array_equal(first, inst.steps(5))
    inst.fmu.freeFMUstate(restored)
    inst.free()
