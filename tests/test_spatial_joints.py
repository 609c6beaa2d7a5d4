"""Spatial revolute, prismatic, cylindrical, universal and fixed joints in the compiled core:
derivatives by finite differences of its Phi, row order and the rows' formulas, reactions,
initial consistency, simulations, the pre-check on the test mechanisms of tests/data/spatial,
friction (dissipation, symmetry, hand computations from the reaction outputs) and the FMU
description."""
from __future__ import annotations

import json
import math
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest
from compiled import compiled_models

from overcon import cli
from overcon.joints import TYPES, names, resolve
from overcon.model import InconsistentInitialState
from overcon.checks import compile_checked
from overcon.scene import SceneError, as_scene, load
from overcon.simulate import run
from overcon.spec import SolverSpec

from test_core_rows import (EQ_REL, FD_REL, applied_forces, law_mu, check_friction_at, consistent, equation_residuals,
                            friction_law, rotation, rows_fd_errors, rx, rz, solve)
from test_kernel import kernel_for

SIN_BETA_MIN = 1e-3
"""|sin beta| below which z-x-z Euler angles are singular (the core's OVK_EULER threshold)."""

DATA = Path(__file__).parent / "data" / "spatial"
SEEDS = [0, 1, 2]
AXIS_TYPES = ["revolute", "prismatic", "cylindrical", "universal", "fixed"]
FRICTION_TYPES = ["revolute", "prismatic", "cylindrical"]
N_ROWS = {"revolute": 5, "prismatic": 5, "cylindrical": 4, "universal": 4, "fixed": 6, "spherical": 3}
FRICTION_TABLE = {"revolute": "radius = 0.02\nlength = 0.1", "prismatic": "length = 0.3\nradius = 0.05",
                  "cylindrical": "length = 0.3\nradius = 0.05"}


# ----------------------------------------------------------------------------- helpers

def _fmt(v) -> str:
    return "[" + ", ".join(repr(float(x)) for x in np.atleast_1d(v)) + "]"


def euler_R(angles) -> np.ndarray:
    """Rotation body -> global of z-x-z Euler angles (paper Eq. 40)."""
    return rz(angles[0]) @ rx(angles[1]) @ rz(angles[2])


def completion(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) completing the unit axis a to a right-handed frame (docs/joint-friction.md): x is
    the standard basis vector least aligned with a (the first on ties) made orthogonal to a,
    y = a x x."""
    e = np.eye(3)[int(np.argmin(np.abs(a)))]
    x = e - (e @ a) * a
    x /= np.linalg.norm(x)
    return x, np.cross(a, x)


def random_rotation(rng) -> np.ndarray:
    return euler_R((rng.uniform(-3, 3), rng.uniform(0.4, 2.7), rng.uniform(-3, 3)))


def joint_lines(name, jtype, bi, bj, s_i, s_j, a_i=None, a_j=None, friction=None) -> list[str]:
    lines = ["[[joints]]", f'name = "{name}"', f'type = "{jtype}"', f'body_i = "{bi}"', f'body_j = "{bj}"',
             f"s_i = {_fmt(s_i)}", f"s_j = {_fmt(s_j)}"]
    if a_i is not None:
        lines += [f"axis_i = {_fmt(a_i)}", f"axis_j = {_fmt(a_j)}"]
    if friction is not None:
        lines += ["[joints.friction]", "mu = 0.3", friction]
    return lines + [""]


def mechanism_text(name, bodies, joints) -> str:
    """A spatial mechanism: ``bodies`` [(name, q0)], ``joints`` lists of lines."""
    lines = ["[mechanism]", f'name = "{name}"', 'kind = "spatial"', "gravity = [0.0, 0.0, -9.81]", ""]
    for bname, q0 in bodies:
        lines += ["[[bodies]]", f'name = "{bname}"', "mass = 1.5", "inertia = [0.3, 0.4, 0.5]",
                  f"q0 = {_fmt(q0)}", ""]
    for j in joints:
        lines += j
    return "\n".join(lines)


def random_q0(rng):
    return np.r_[rng.uniform(-1, 1, 3), rng.uniform(-3, 3), rng.uniform(0.4, 2.7), rng.uniform(-3, 3)]


def write_single_type(tmp: Path, jtype: str, seed: int, friction: str | None = None) -> Path:
    """Two bodies and three joints of one type, (b1, base), (b1, b2), (base, b2), with random
    points and axes and random q0 (not assembled: derivatives only); with ``friction`` (a
    friction table's lines) only two of them (the pair left out chosen by the seed: three axis
    joints hold two bodies fixed), each with that friction."""
    rng = np.random.default_rng(seed)
    joints = []
    pairs = [("b1", "base"), ("b1", "b2"), ("base", "b2")]
    if friction is not None:
        del pairs[seed % 3]
    for k, (bi, bj) in enumerate(pairs):
        axes = (rng.normal(size=3), rng.normal(size=3))
        joints.append(joint_lines(f"J{k}", jtype, bi, bj, rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3), *axes,
                                  friction=friction))
    path = tmp / f"single_{jtype}_{seed}{'_f' if friction is not None else ''}.toml"
    path.write_text(mechanism_text(f"single_{jtype}", [("b1", random_q0(rng)), ("b2", random_q0(rng))], joints))
    return path


@pytest.fixture(scope="module")
def single(tmp_path_factory):
    return compiled_models(tmp_path_factory.mktemp("spatial_single"), write_single_type)


def random_state(rng, nb=2) -> np.ndarray:
    """A random y (Euler angles, h with angular velocities in body axes) of nb bodies."""
    q = np.concatenate([np.r_[rng.uniform(-1, 1, 3), rng.uniform(-3, 3), rng.uniform(0.4, 2.7), rng.uniform(-3, 3)]
                        for _ in range(nb)])
    return np.concatenate([q, rng.normal(size=6 * nb)])


# ----------------------------------------------------------------------------- type resolution

def test_type_names_resolve_per_mechanism_kind():
    assert resolve("planar", "revolute") == "revolute"
    assert resolve("spatial", "revolute") == "spatial_revolute"
    assert resolve("planar", "prismatic") is None
    assert resolve("spatial", "translational") is None
    assert names("spatial") == ("spherical", "revolute", "prismatic", "cylindrical", "universal", "fixed",
                                "distance", "point_on_line")
    assert names("planar") == ("translational", "revolute", "distance", "point_on_line")
    for key, jt in TYPES.items():
        assert resolve(jt.kind, jt.name) == key
        if jt.kind == "spatial":
            assert jt.n_equations == {**N_ROWS, "distance": 1, "point_on_line": 2}[jt.name]


def test_type_not_allowed_names_the_field(tmp_path):
    text = mechanism_text("m", [("b1", [0, 0, 0, 0, 1, 0])],
                          [joint_lines("J", "translational", "b1", "base", [0, 0, 0], [0, 0, 0])])
    (tmp_path / "m.toml").write_text(text)
    with pytest.raises(SceneError, match=r"m\.toml: joints\[0\] \(J\)\.type: joint type 'translational' is not "
                                         r"allowed in a spatial mechanism \(allowed: spherical, revolute, "
                                         r"prismatic, cylindrical, universal, fixed, distance, point_on_line\)") as e:
        load(tmp_path / "m.toml")
    [p] = e.value.problems
    assert (p.field, p.name) == ("joints[0].type", "J")  # the field stays the path; the name is shown


# ----------------------------------------------------------------------------- derivatives

@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("jtype", AXIS_TYPES)
def test_jacobian_and_gamma_by_finite_differences(single, jtype, seed):
    """The core's Phi_h (column by column) and gamma against central differences of its Phi along
    the coordinate rates (tests/test_core_rows.py: FD_REL), the base as body i and as body j."""
    model = single(jtype, seed)
    assert [TYPES[c.type].name for c in model.joints] == [jtype] * 3
    assert model.m == 3 * N_ROWS[jtype]
    k = kernel_for(model, SolverSpec())
    rng = np.random.default_rng(100 + seed)
    for _ in range(3):
        eJ, eg = rows_fd_errors(k, model, random_state(rng))
        assert eJ <= FD_REL and eg <= FD_REL, (eJ, eg)


@pytest.mark.parametrize("seed", SEEDS)
def test_rows_in_the_contract_order(tmp_path, seed):
    """One joint of every type between the same bodies at the same points and axes: the rows
    shared by two types are equal (revolute = spherical + 2 axis rows; cylindrical = 2 point
    rows + the same 2 axis rows; prismatic = cylindrical + lock; fixed = revolute + the same
    lock; universal = spherical + 1 row)."""
    rng = np.random.default_rng(200 + seed)
    s_i, s_j, a_i, a_j = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3), rng.normal(size=3), rng.normal(size=3)
    joints = [joint_lines("S", "spherical", "b1", "b2", s_i, s_j)]
    joints += [joint_lines(t[0].upper(), t, "b1", "b2", s_i, s_j, a_i, a_j) for t in AXIS_TYPES]
    (tmp_path / "all.toml").write_text(mechanism_text("all", [("b1", random_q0(rng)), ("b2", random_q0(rng))], joints))
    spec = as_scene(load(tmp_path / "all.toml"))
    model = compile_checked(spec, check_initial=False)
    k = kernel_for(model, spec.solver)
    rows = {TYPES[c.type].name: list(c.rows) for c in model.joints}
    assert {k: len(v) for k, v in rows.items()} == N_ROWS
    for _ in range(3):
        y = random_state(rng)
        phi, J, g = k.rows(y)
        r = [y[0:3], y[6:9]]
        R = [rotation(model, y, 0), rotation(model, y, 1)]
        for x in (phi, J, g):
            sel = {k: x[v] for k, v in rows.items()}
            np.testing.assert_array_equal(sel["revolute"][:3], sel["spherical"])
            np.testing.assert_array_equal(sel["universal"][:3], sel["spherical"])
            np.testing.assert_array_equal(sel["cylindrical"][2:], sel["revolute"][3:])
            np.testing.assert_array_equal(sel["prismatic"][:4], sel["cylindrical"])
            np.testing.assert_array_equal(sel["fixed"][:5], sel["revolute"])
            np.testing.assert_array_equal(sel["fixed"][5], sel["prismatic"][4])
        # the formulas of the rows, written out
        Ri, Rj = R
        ai, aj = a_i / np.linalg.norm(a_i), a_j / np.linalg.norm(a_j)
        b1, b2 = completion(aj)
        d = r[0] + Ri @ s_i - r[1] - Rj @ s_j
        np.testing.assert_allclose(phi[rows["revolute"][3:]], [(Ri @ ai) @ (Rj @ b1), (Ri @ ai) @ (Rj @ b2)],
                                   atol=1e-14)
        np.testing.assert_allclose(phi[rows["cylindrical"][:2]], [d @ (Rj @ b1), d @ (Rj @ b2)], atol=1e-14)
        np.testing.assert_allclose(phi[rows["universal"][3]], (Ri @ ai) @ (Rj @ aj), atol=1e-14)
        R0 = [euler_R(model.q0[3:6]), euler_R(model.q0[9:12])]
        c_i = R0[0].T @ R0[1] @ b1
        np.testing.assert_allclose(phi[rows["prismatic"][4]], (Ri @ c_i) @ (Rj @ b2), atol=1e-14)


def test_completion_rule():
    """The completion rule as docs/joint-friction.md states it (the helper test_rows_in_the_contract_order
    and test_reaction_components hold the core to)."""
    b1, b2 = completion(np.array([0.0, 0.0, 1.0]))
    np.testing.assert_array_equal(b1, [1.0, 0.0, 0.0])  # e1 and e2 tie: the first
    np.testing.assert_array_equal(b2, [0.0, 1.0, 0.0])
    b1, _ = completion(np.array([1.0, 0.0, 0.0]))
    np.testing.assert_array_equal(b1, [0.0, 1.0, 0.0])
    rng = np.random.default_rng(3)
    for _ in range(20):
        a = rng.normal(size=3)
        a /= np.linalg.norm(a)
        b1, b2 = completion(a)
        B = np.column_stack([b1, b2, a])
        np.testing.assert_allclose(B.T @ B, np.eye(3), atol=1e-15)
        assert np.linalg.det(B) == pytest.approx(1.0)


# ----------------------------------------------------------------------------- reactions

def assembled_pair(rng, jtype, slide=True):
    """(s_i, s_j, a_i, a_j, [q0 of b1, q0 of b2], u): bodies b1, b2 placed so that a joint of
    ``jtype`` with these constants holds; cylindrical and prismatic joints slid along the axis
    (P_i != P_j) if ``slide``."""
    s_i, s_j = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3)
    a_i = rng.normal(size=3)
    a_i /= np.linalg.norm(a_i)
    R1 = random_rotation(rng)
    C = random_rotation(rng)  # body i axes -> body j axes at q0
    a_j = C @ a_i
    if jtype == "universal":
        a_j = np.cross(a_j, rng.normal(size=3))
        a_j /= np.linalg.norm(a_j)
    R2 = R1 @ C.T
    P = rng.uniform(-1, 1, 3)
    slide = rng.uniform(-0.5, 0.5) if slide and jtype in ("cylindrical", "prismatic") else 0.0
    r1 = P - R1 @ s_i
    r2 = P - slide * (R1 @ a_i) - R2 @ s_j
    q = [np.r_[r1, _euler_of(R1)], np.r_[r2, _euler_of(R2)]]
    return s_i, s_j, a_i, a_j, q, (R1 @ a_i)


def _euler_of(R):
    b = math.acos(R[2, 2])
    return [math.atan2(R[0, 2], -R[1, 2]), b, math.atan2(R[2, 0], R[2, 1])]


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("jtype", AXIS_TYPES)
def test_reaction_components(tmp_path, jtype, seed):
    """At an assembled configuration: the reported components equal a direct computation from
    -(J_X)_i^T lam (force and moment about P_i in the frame z = axis_i); the left-out ones vanish."""
    rng = np.random.default_rng(300 + seed)
    s_i, s_j, a_i, a_j, q, u = assembled_pair(rng, jtype)
    text = mechanism_text("pair", [("b1", q[0]), ("b2", q[1])],
                          [joint_lines("X", jtype, "b1", "b2", s_i, s_j, a_i, a_j)])
    (tmp_path / "pair.toml").write_text(text)
    spec = as_scene(load(tmp_path / "pair.toml"))
    model = compile_checked(spec)  # assembled: q0 accepted
    c = model.joints[0]
    comps = TYPES[c.type].reaction_components
    k = kernel_for(model, spec.solver)
    y0 = np.concatenate([model.q0, model.h0])
    J = k.rows(y0)[1]
    R1 = rotation(model, model.q0, 0)
    x, y = completion(a_i)
    E = np.column_stack([x, y, a_i])
    for _ in range(5):
        lam = rng.normal(size=model.m) * 10
        fi = J[:, :6].T @ lam
        F, T = -fi[:3], -fi[3:]
        F_body = R1.T @ F
        full = dict(zip(("Fx", "Fy", "Fz", "Tx", "Ty", "Tz"), np.r_[E.T @ F_body, E.T @ (T - np.cross(s_i, F_body))]))
        out = k.outputs(y0, lam)[0][0, : len(comps) + 3]
        assert len(c.components) == len(comps) + 3
        np.testing.assert_allclose(out[:len(comps)], [full[k] for k in comps], atol=1e-12)
        np.testing.assert_allclose(out[len(comps):], F, atol=1e-12)
        left_out = [k for k in full if k not in comps]
        scale = max(1.0, np.abs(lam).max())
        assert all(abs(full[k]) <= 1e-12 * scale for k in left_out), (left_out, full)
        assert all(abs(full[k]) > 1e-6 for k in comps)  # none of the reported is zero by construction


def test_fixed_joint_axes_optional(tmp_path):
    rng = np.random.default_rng(11)
    s_i, s_j, a_i, a_j, q, _ = assembled_pair(rng, "fixed")
    (tmp_path / "f.toml").write_text(mechanism_text("f", [("b1", q[0]), ("b2", q[1])],
                                                    [joint_lines("X", "fixed", "b1", "b2", s_i, s_j)]))
    spec = as_scene(load(tmp_path / "f.toml"))
    model = compile_checked(spec)
    p = model.joints[0].p
    np.testing.assert_array_equal(p["a_i"], [0.0, 0.0, 1.0])
    np.testing.assert_array_equal(p["E"], np.eye(3))  # the joint frame is body i's axes
    np.testing.assert_allclose(rotation(model, model.q0, 0) @ p["a_i"], rotation(model, model.q0, 1) @ p["a_j"],
                               atol=1e-15)
    # the relative rotation is frozen: rank 6 and the single body pair has no DOF
    k = kernel_for(model, spec.solver)
    assert np.linalg.matrix_rank(k.rows(np.concatenate([model.q0, model.h0]))[1]) == 6
    # given axes that are not parallel at q0 are refused like any other constraint
    bad = mechanism_text("f", [("b1", q[0]), ("b2", q[1])],
                         [joint_lines("X", "fixed", "b1", "b2", s_i, s_j, a_i, np.cross(a_j, [0.3, 1, 0]))])
    (tmp_path / "bad.toml").write_text(bad)
    with pytest.raises(InconsistentInitialState, match=r"joint X \(joints\[0\]\): axis_i and axis_j are not "
                                                       r"parallel at q0 \(angle [0-9.]+ deg\): Phi4"):
        compile_checked(as_scene(load(tmp_path / "bad.toml")))


# ----------------------------------------------------------------------------- initial consistency

def test_door_with_hinge_axes_not_parallel_refused(tmp_path):
    text = (DATA / "door.toml").read_text()
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("axis_j"))  # the upper hinge's
    lines[k] = "axis_j = [0.35, 0.1, 1.0]"
    (tmp_path / "door.toml").write_text("\n".join(lines))
    with pytest.raises(InconsistentInitialState, match=r"joint upper \(joints\[0\]\): axis_i and axis_j are not "
                                                       r"parallel at q0") as e:
        compile_checked(as_scene(load(tmp_path / "door.toml")))
    msg = str(e.value)
    assert "joint upper (joints[0]): axis_i and axis_j are not parallel at q0" in msg and "lower" not in msg
    assert "door.toml" in msg


def test_universal_axes_must_be_perpendicular_at_q0(tmp_path):
    text = (DATA / "universal_spherical.toml").read_text().replace(
        "axis_j = [0.0, 1.0, 0.0]", "axis_j = [0.2, 1.0, 0.0]")
    assert text != (DATA / "universal_spherical.toml").read_text()
    (tmp_path / "us.toml").write_text(text)
    with pytest.raises(InconsistentInitialState, match=r"joint U \(joints\[0\]\): axis_i and axis_j are not "
                                                       r"perpendicular at q0 \(angle [0-9.]+ deg\): Phi4"):
        compile_checked(as_scene(load(tmp_path / "us.toml")))


# the axis rows of each type, 1-based equation numbers of a single joint (joints[0])
AXIS_ROWS = {"revolute": (4, 5), "prismatic": (3, 4), "cylindrical": (3, 4), "universal": (4,), "fixed": (4, 5)}
Q0 = (0.1, 0.2, 0.3, 0.4, 1.0, -0.3)


def one_joint_file(tmp_path, jtype, a_i, a_j_body, s_j_shift=(0.0, 0.0, 0.0)) -> Path:
    """A body at Q0 on one ``jtype`` joint to the base at its origin (s_i = 0); axis_i = a_i in
    the body, axis_j = R0 a_j_body (the body's a_j_body seen from the base at q0); the base's
    joint point moved by ``s_j_shift`` (m)."""
    R0 = euler_R(Q0[3:])
    s_j = np.array(Q0[:3]) + np.array(s_j_shift)
    path = tmp_path / f"{jtype}.toml"
    path.write_text(mechanism_text("m", [("b", Q0)], [joint_lines("J", jtype, "b", "base", (0, 0, 0), s_j,
                                                                   a_i, R0 @ np.array(a_j_body, float))]))
    return path


def refusal(path) -> str:
    with pytest.raises(InconsistentInitialState, match=r"\(bodies' q0/h0 in .*\.toml\)") as e:
        compile_checked(as_scene(load(path)))
    return str(e.value)


@pytest.mark.parametrize("jtype, a_i, a_j, relation, angle, good", [
    ("revolute", (1, 0, 0), (0, 1, 0), "parallel", "90", (1, 0, 0)),
    ("prismatic", (1, 0, 0), (0, 0, 1), "parallel", "90", (1, 0, 0)),
    ("cylindrical", (0, 0, 1), (0, math.sin(0.5), math.cos(0.5)), "parallel", "28.65", (0, 0, 1)),
    ("universal", (1, 0, 0), (0.5, math.sqrt(0.75), 0), "perpendicular", "60", (0, 1, 0)),
    ("fixed", (0, 0, 1), (math.sin(math.pi / 6), 0, math.cos(math.pi / 6)), "parallel", "30", (0, 0, 1)),
])
def test_axis_rows_violated_name_the_axis_fields(tmp_path, jtype, a_i, a_j, relation, angle, good):
    """Axes at fault: the message names the joint, its fields axis_i and axis_j, what they fail
    to be and their angle at q0 (and q0 as the other suspect); no point-row wording."""
    msg = refusal(one_joint_file(tmp_path, jtype, a_i, a_j))
    assert f"joint J (joints[0]): axis_i and axis_j are not {relation} at q0 (angle {angle} deg): Phi" in msg
    assert "joints[0].axis_i, joints[0].axis_j or the bodies' q0" in msg and f"{jtype}.toml" in msg
    listed = {int(k) for k in re.findall(r"Phi(\d+)", msg)}
    assert listed and listed <= set(AXIS_ROWS[jtype])
    assert "initial coordinates q0 violate" not in msg
    # the same joint with axes that hold at q0 compiles
    compile_checked(as_scene(load(one_joint_file(tmp_path, jtype, a_i, good))))


def test_point_rows_keep_their_wording_and_mix_with_axis_rows(tmp_path):
    msg = refusal(one_joint_file(tmp_path, "revolute", (1, 0, 0), (1, 0, 0), s_j_shift=(0.0, 0.0, 0.25)))
    assert msg.startswith("initial coordinates q0 violate the constraints Phi3 (joint J): largest |Phi3| = 0.25")
    assert "axis_i" not in msg
    both = refusal(one_joint_file(tmp_path, "revolute", (1, 0, 0), (0, 1, 0), s_j_shift=(0.0, 0.0, 0.25)))
    assert both.startswith("initial coordinates q0 violate the constraints Phi3 (joint J): largest |Phi3| = 0.25; "
                           "joint J (joints[0]): axis_i and axis_j are not parallel at q0 (angle 90 deg): Phi4")


def test_row_meanings_declared_once_per_type():
    """Every type states a meaning per equation; the axis types' axis rows are where AXIS_ROWS
    says, a prismatic and a fixed joint also have their lock row last."""
    for key, jt in TYPES.items():
        assert len(jt.row_meanings) == jt.n_equations
        if jt.kind == "spatial" and jt.name in AXIS_ROWS:
            axis = {k + 1 for k, m in enumerate(jt.row_meanings) if m in ("parallel", "perpendicular")}
            assert axis == set(AXIS_ROWS[jt.name]), key
        if jt.name in ("prismatic", "fixed"):
            assert jt.row_meanings[-1] == "lock"
    assert set(TYPES["spatial_universal"].row_meanings) == {"point", "perpendicular"}
    assert set(TYPES["revolute"].row_meanings) == {"point"}  # planar: today's wording


@pytest.mark.integration
def test_euler_beta_zero_refused_at_compile_time_everywhere(tmp_path, capsys):
    """A body at beta = 0 with Euler angles: check, simulate and build refuse it (exit 2) with
    one message naming the file, the body, its field q0 and the quaternion alternative."""
    from overcon.fmu.build import build_scene

    mech = tmp_path / "beta0.toml"
    mech.write_text(mechanism_text("beta0", [("link", (0.0, 0.5, 0.0, 0.0, 0.0, 0.0))],
                                   [joint_lines("h", "revolute", "link", "base", (0, 0, 0), (0, 0.5, 0),
                                                (1, 0, 0), (1, 0, 0))]))
    scene = tmp_path / "s.toml"
    scene.write_text('[scene]\nname = "s"\nmechanism = "beta0.toml"\nfriction = []\neliminate = []\n'
                     "stop_time = 0.1\n")
    expect = ("body 'link': bodies[0].q0 has beta = q0[4] = 0 rad, at the z-x-z Euler angle singularity "
              "(|sin(beta)| = 0 < 0.001)")
    errors = []
    for argv in (["check", str(mech)], ["check", str(scene)],
                 ["simulate", str(scene), "--out", str(tmp_path / "o.csv")]):
        assert cli.main(argv) == 2
        err = capsys.readouterr().err
        assert expect in err and 'rotation = "quaternion"' in err and f"bodies' q0 in {mech}" in err
        errors.append(err.split(": ", 2)[-1])
    assert errors[0] == errors[1] == errors[2]
    res = build_scene(scene, tmp_path / "fmus", echo=lambda s: None, validate=False)
    assert res.status == "invalid" and res.messages == [f"{scene}: {errors[0].strip()}"]
    assert not (tmp_path / "fmus").exists()
    # just outside the threshold (|sin beta| = 2 SIN_BETA_MIN) the same file compiles
    mech.write_text(mech.read_text().replace("q0 = [0.0, 0.5, 0.0, 0.0, 0.0, 0.0]",
                                             f"q0 = [0.0, 0.5, 0.0, 0.0, {math.asin(2 * SIN_BETA_MIN)!r}, 0.0]"))
    assert cli.main(["check", str(scene)]) == 0


# ----------------------------------------------------------------------------- check --json

def check_json(path, capsys) -> dict:
    code = cli.main(["check", str(path), "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert code == 0, doc
    return doc


@pytest.mark.parametrize("name, expect", [
    ("universal_spherical", dict(n_coordinates=12, n_equations=7, rank=7, dof=5, redundant=0,
                                 joints={"U": ("universal", True), "S": ("spherical", True)})),
    ("bennett", dict(n_coordinates=18, n_equations=20, rank=17, dof=1, redundant=3,
                     joints={f"J{k}": ("revolute", False) for k in (1, 2, 3, 4)})),
    ("door", dict(n_coordinates=6, n_equations=10, rank=5, dof=1, redundant=5,
                  joints={"upper": ("revolute", False), "lower": ("revolute", False)})),
])
def test_check_json(capsys, name, expect):
    doc = check_json(DATA / f"{name}.toml", capsys)
    for key in ("n_coordinates", "n_equations", "rank", "dof", "redundant"):
        assert doc[key] == expect[key], key
    assert {j["name"]: (j["type"], j["unique"]) for j in doc["joints"]} == expect["joints"]
    assert all(j["agree"] for j in doc["joints"])


def test_bennett_moves_with_one_dof():
    """The Bennett linkage is mobile: its velocity null space at q0 is one-dimensional and the
    gravity run keeps the constraints."""
    scene = as_scene(load(DATA / "bennett.toml"), stop_time=0.5, solver={"tolerance": 1e-10})
    model = compile_checked(scene)
    res = run(model, scene.solver)
    assert res.max_drift <= 1e-8
    moved_by = np.abs(res.values[-1] - res.values[0])[:9].max()  # positions of the three links
    assert moved_by > 1e-3


# ----------------------------------------------------------------------------- simulations

def test_door_swings_and_stays_on_its_constraints():
    scene = as_scene(load(DATA / "door.toml"), stop_time=1.0, solver={"tolerance": 1e-10})
    model = compile_checked(scene)
    assert model.eliminated  # auto elimination of the 5 redundant equations
    assert len(model.eliminated) == 5
    res = run(model, scene.solver, output_interval=0.05)
    assert res.max_drift <= 1e-8
    q_end = np.array([res.column(f"door.{c}")[-1] for c in ("x", "y", "z", "alpha", "beta", "gamma")])
    phi = kernel_for(model, scene.solver).rows(np.concatenate([q_end, model.h0]))[0]
    assert np.abs(phi).max() <= 1e-8
    assert np.linalg.norm(q_end[:3] - model.q0[:3]) > 0.05  # it swung


def test_pendulum_period_matches_small_angle_formula():
    scene = as_scene(load(DATA / "pendulum.toml"), stop_time=3.2, solver={"tolerance": 1e-11})
    model = compile_checked(scene)
    res = run(model, scene.solver, output_interval=0.005)
    assert res.max_drift <= 1e-8
    y = res.column("bob.y")
    t = res.time
    crossings = []
    for k in range(len(y) - 1):
        if y[k] > 0 >= y[k + 1] or y[k] < 0 <= y[k + 1]:
            crossings.append(t[k] - y[k] * (t[k + 1] - t[k]) / (y[k + 1] - y[k]))
    period = 2 * np.mean(np.diff(crossings))
    m, Jx, L, theta0 = 2.0, 0.1, 0.5, 0.02
    T0 = 2 * math.pi * math.sqrt((Jx + m * L ** 2) / (m * 9.81 * L))
    expected = T0 * (1 + theta0 ** 2 / 16)  # first finite-amplitude correction
    assert len(crossings) >= 4
    assert period == pytest.approx(expected, rel=2e-5)


def test_flywheel_friction_decelerates_uniformly():
    """Revolute friction in a simulation: the radial load is m g (centre of mass on the axis), so
    the spin decreases at mu a m g / Jz and gamma(t) = w0 t - mu a m g t^2 / (2 Jz)."""
    scene = as_scene(load(DATA / "flywheel.toml"), friction=["axle"], stop_time=1.0, solver={"tolerance": 1e-10})
    model = compile_checked(scene)
    res = run(model, scene.solver, output_interval=0.1)
    decel = 0.2 * 0.05 * 2.0 * 9.81 / 0.1
    t = res.time
    np.testing.assert_allclose(res.column("wheel.gamma"), 10.0 * t - 0.5 * decel * t ** 2, rtol=0, atol=1e-6)
    np.testing.assert_allclose(res.column("axle.friction")[1:], -0.2 * 0.05 * 2.0 * 9.81, rtol=1e-6)
    np.testing.assert_allclose(res.column("axle.Fz"), 0.0, atol=1e-8)  # no axial load


def test_incline_friction_gives_the_textbook_acceleration():
    """Prismatic friction in a simulation: a block on a guide inclined at 30 degrees slides with
    acceleration g (sin 30 - mu cos 30) (normal load m g cos 30, no moment: the joint point is
    the centre of mass)."""
    scene = as_scene(load(DATA / "incline.toml"), friction=["guide"], stop_time=0.5, solver={"tolerance": 1e-10})
    model = compile_checked(scene)
    res = run(model, scene.solver, output_interval=0.05)
    th = math.radians(30)
    a = 9.81 * (math.sin(th) - 0.2 * math.cos(th))
    t = res.time
    x = res.column("block.x") - model.q0[0]
    z = res.column("block.z") - model.q0[2]
    s = x * math.cos(th) - z * math.sin(th)
    np.testing.assert_allclose(s, 0.5 * a * t ** 2, rtol=0, atol=1e-6)
    np.testing.assert_allclose(res.column("guide.friction")[2:], -0.2 * 3.0 * 9.81 * math.cos(th), rtol=1e-6)


# ----------------------------------------------------------------------------- friction

LAWS = {"regularised": "", "stribeck": 'law = "stribeck"\nmu_static = 0.5\nv_stribeck = 0.01'}


@pytest.mark.parametrize("law", list(LAWS))
@pytest.mark.parametrize("jtype", FRICTION_TYPES)
def test_friction_dissipates(tmp_path, jtype, law):
    """Two joints with friction on two bodies (the base as body i or j, or two moving bodies), at
    random states moved onto the constraints, velocities scaled into the laws' linear part too:
    the outputs are their law at the returned multipliers (docs/joint-friction.md), and the
    friction forces' power in the equations of motion, h . (M h' + Phi_h^T lam - Q), is the
    outputs' and <= 0 (tests/test_core_rows.py), < 0 somewhere."""
    table = FRICTION_TABLE[jtype] + ("\n" + LAWS[law] if LAWS[law] else "")
    n_negative = 0
    for seed in SEEDS:
        spec = as_scene(load(write_single_type(tmp_path, jtype, seed, table)), friction=["J0", "J1"],
                        friction_outputs="all")
        model = compile_checked(spec, check_initial=False)
        assert [c.law.name for c in model.joints] == [law] * 2
        k = kernel_for(model, spec.solver)
        rng = np.random.default_rng(400 + seed)
        for _ in range(8):
            y, assembled = consistent(k, model, random_state(rng))
            if not assembled:
                continue
            y[12:] *= 10.0 ** rng.uniform(-5, 0)  # reach the linear part of the regularised law
            got = solve(k, y)
            if got is None:
                continue
            Qf = equation_residuals(k, model, spec.solver, y, got)[0]
            power = check_friction_at(k, model, spec, y, got)
            h = y[12:]
            P = float(h @ Qf)
            scale = max(1.0, float(np.max(np.abs(applied_forces(model, y))))) * max(1.0, float(np.max(np.abs(h))))
            assert abs(P - power) <= EQ_REL * scale and P <= EQ_REL * scale, (P, power)
            n_negative += power < -1e-9 * scale
    assert n_negative > 0


def pair_model(tmp_path, jtype, seed):
    """Bodies b1, b2 assembled for two joints of ``jtype``: X (b1, b2) and Y (b2, b1), the same
    joint with i and j (points, axes) swapped; the joint points coincide (the contact geometry
    of a guide is attached to body i: with P_i != P_j the two descriptions are different
    guides). (spec, model, kernel, rng, the joint's constants)."""
    rng = np.random.default_rng(500 + seed)
    s_i, s_j, a_i, a_j, q, u = assembled_pair(rng, jtype, slide=False)
    fr = FRICTION_TABLE[jtype]
    joints = [joint_lines("X", jtype, "b1", "b2", s_i, s_j, a_i, a_j, fr),
              joint_lines("Y", jtype, "b2", "b1", s_j, s_i, a_j, a_i, fr)]
    (tmp_path / "pair.toml").write_text(mechanism_text("pair", [("b1", q[0]), ("b2", q[1])], joints))
    scene = as_scene(load(tmp_path / "pair.toml"), friction=["X", "Y"], friction_outputs="all")
    model = compile_checked(scene, check_initial=False)
    return scene, model, kernel_for(model, scene.solver), rng, (s_i, s_j, a_i, a_j)


def _swap_multipliers(model, J, lam_x):
    """Multipliers of Y whose reaction on its body i (b2) is X's reaction on b2."""
    X, Y = model.joints
    fj = J[list(X.rows), 6:].T @ lam_x
    JY = J[list(Y.rows), 6:]
    lam_y, *_ = np.linalg.lstsq(JY.T, fj, rcond=None)
    np.testing.assert_allclose(JY.T @ lam_y, fj, atol=1e-9)  # the same reaction space
    return lam_y


def _rotated(q, Q) -> np.ndarray:
    """The configuration q (Euler angles) turned as a whole by the rotation Q about the origin."""
    out = q.copy()
    for b in range(len(q) // 6):
        out[6 * b: 6 * b + 3] = Q @ q[6 * b: 6 * b + 3]
        out[6 * b + 3: 6 * b + 6] = _euler_of(Q @ euler_R(q[6 * b + 3: 6 * b + 6]))
    return out


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("jtype", FRICTION_TYPES)
def test_friction_symmetry(tmp_path, jtype, seed):
    """The core's friction output of one joint described from either body: at multipliers giving
    the same reaction, Y's output is -X's (signed: revolute, prismatic) or X's (cylindrical's
    magnitude); it is odd in the relative velocity, and unchanged when the whole configuration
    turns (reaction components and speeds are relative)."""
    spec, model, k, rng, _ = pair_model(tmp_path, jtype, seed)
    X, Y = model.joints
    y0 = np.concatenate([model.q0, np.zeros(12)])
    J = k.rows(y0)[1]
    JX = J[list(X.rows)]
    h = rng.normal(size=12)
    h -= np.linalg.pinv(JX) @ (JX @ h)  # a velocity that keeps the joint
    y = np.concatenate([model.q0, h * 0.01])
    lam = np.zeros(model.m)
    lam[list(X.rows)] = rng.normal(size=len(X.rows)) * 10
    lam[list(Y.rows)] = _swap_multipliers(model, J, lam[list(X.rows)])
    outX, outY = k.outputs(y, lam)[1].copy()
    assert abs(outX) > 1e-6
    assert outY == pytest.approx(outX if jtype == "cylindrical" else -outX, abs=1e-9)
    outN = k.outputs(np.concatenate([model.q0, -h * 0.01]), lam)[1][0]
    assert outN == pytest.approx(outX if jtype == "cylindrical" else -outX, abs=1e-12)
    Q = random_rotation(rng)
    lam_r = lam.copy()
    if jtype == "revolute":  # point rows are global components
        for c in model.joints:
            lam_r[list(c.rows)[:3]] = Q @ lam[list(c.rows)[:3]]
    h_r = h.copy()
    for b in range(2):
        h_r[6 * b: 6 * b + 3] = Q @ h[6 * b: 6 * b + 3]  # global velocities turn, body-axis ones not
    outR = k.outputs(np.concatenate([_rotated(model.q0, Q), h_r * 0.01]), lam_r)[1][0]
    assert outR == pytest.approx(outX, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("jtype", FRICTION_TYPES)
def test_friction_output_by_hand(tmp_path, jtype, seed):
    """The output <joint>.friction at random multipliers and velocities from the reported reaction
    by the formulas of docs/joint-friction.md, written out here (sizes of FRICTION_TABLE, the
    revolute collar radius defaulting to the radius), and the same by test_core_rows.friction_law."""
    spec, model, k, rng, (s_i, s_j, a_i, a_j) = pair_model(tmp_path, jtype, seed)
    X = model.joints[0]
    h = rng.normal(size=12) * 0.01
    y = np.concatenate([model.q0, h])
    lam = rng.normal(size=model.m) * 10
    reac, fric = k.outputs(y, lam)
    p = dict(zip(X.components, reac[0]))
    Fx, Fy, Tx, Ty = p["Fx"], p["Fy"], p["Tx"], p["Ty"]
    R = [rotation(model, model.q0, b) for b in (0, 1)]
    u = R[0] @ (a_i / np.linalg.norm(a_i))
    spin = (R[1] @ h[9:12] - R[0] @ h[3:6]) @ u
    P = model.q0[0:3] + R[0] @ s_i
    vel = [h[6 * b: 6 * b + 3] + np.cross(R[b] @ h[6 * b + 3: 6 * b + 6], P - model.q0[6 * b: 6 * b + 3]) for b in (0, 1)]
    slide = (vel[1] - vel[0]) @ u
    law = X.law
    if jtype == "revolute":
        a, L = 0.02, 0.1
        m = np.array([Ty, -Tx]) / L
        Nr = np.linalg.norm([Fx / 2 + m[0], Fy / 2 + m[1]]) + np.linalg.norm([Fx / 2 - m[0], Fy / 2 - m[1]])
        expected = law_mu(law, spin) * (a * Nr + a * abs(p["Fz"]))
    else:
        l, r = 0.3, 0.05
        fB = np.array([Ty, -Tx]) / l
        fA = np.array([Fx, Fy]) - fB
        N = np.linalg.norm(fA) + np.linalg.norm(fB)
        if jtype == "prismatic":
            expected = law_mu(law, slide) * (N + abs(p["Tz"]) / r)
        else:
            expected = law_mu(law, math.hypot(slide, r * spin)) * N
    assert fric[0] == pytest.approx(expected, rel=1e-12, abs=1e-14)
    assert abs(fric[0]) > 1e-6
    assert friction_law(model, spec, model.q0, h, X, reac[0], fric[0])[0] == pytest.approx(expected, rel=1e-12)


def test_revolute_friction_pure_radial_load(tmp_path):
    """Without bending or axial load the radial load is |F_perp| and T_f = mu a |F_perp|; the
    prismatic guide reduces to the planar A.2 (|N - T/l| + |T/l|) for a planar load: the core's
    outputs at multipliers whose reaction is such a load, sliding fast (mu(v) = mu)."""
    for jtype, want in (("revolute", lambda F, T: 0.3 * 0.02 * math.hypot(F[0], F[1])),
                        ("prismatic", lambda F, T: 0.3 * (abs(F[1] + T[0] / 0.3) + abs(T[0] / 0.3)))):
        spec, model, k, rng, _ = pair_model(tmp_path, jtype, 0)
        X = model.joints[0]
        rows = list(X.rows)
        y0 = np.concatenate([model.q0, np.zeros(12)])
        J = k.rows(y0)[1]
        h = rng.normal(size=12)
        JX = J[rows]
        h -= np.linalg.pinv(JX) @ (JX @ h)
        h *= 10.0 / np.linalg.norm(h)
        y = np.concatenate([model.q0, h])
        comps = list(X.components[:-3])
        # the physical reaction on body i (joint frame, about P_i) wanted: F = (3, 4, 0), or the
        # planar load F = (0, 7, 0), T = (-1.2, 0, 0); the multipliers giving it by least squares
        F, T = ((np.array([3.0, 4.0, 0.0]), np.zeros(3)) if jtype == "revolute"
                else (np.array([0.0, 7.0, 0.0]), np.array([-1.2, 0.0, 0.0])))
        M = np.array([k.outputs(y, np.eye(model.m)[r])[0][0, : len(comps)].copy() for r in rows]).T
        target = np.array([dict(zip(("Fx", "Fy", "Fz", "Tx", "Ty", "Tz"), np.r_[F, T]))[c] for c in comps])
        lam = np.zeros(model.m)
        lam[rows] = np.linalg.lstsq(M, target, rcond=None)[0]
        reac, fric = k.outputs(y, lam)
        np.testing.assert_allclose(reac[0, : len(comps)], target, atol=1e-9)
        assert abs(fric[0]) == pytest.approx(want(F, T), rel=1e-9)


# ----------------------------------------------------------------------------- friction fields

def _mech_with_friction(tmp_path, jtype, friction_lines) -> Path:
    rng = np.random.default_rng(9)
    s_i, s_j, a_i, a_j, q, _ = assembled_pair(rng, jtype)
    lines = joint_lines("X", jtype, "b1", "b2", s_i, s_j, a_i, a_j)
    lines = lines[:-1] + ["[joints.friction]", *friction_lines, ""]
    path = tmp_path / "m.toml"
    path.write_text(mechanism_text("m", [("b1", q[0]), ("b2", q[1])], [lines]))
    return path


@pytest.mark.parametrize("jtype", ["universal", "fixed"])
def test_friction_refused_on_universal_and_fixed(tmp_path, jtype):
    path = _mech_with_friction(tmp_path, jtype, ["mu = 0.1", "radius = 0.01"])
    with pytest.raises(SceneError, match=rf"m\.toml: joints\[0\] \(X\)\.friction: a {jtype} joint has no "
                                         "friction model"):
        load(path)


@pytest.mark.parametrize("jtype", ["universal", "fixed"])
def test_friction_switched_on_for_a_type_without_friction_says_so(tmp_path, capsys, jtype):
    """scene.friction or --friction naming a universal or fixed joint (no friction table): the
    refusal is the type's, naming the field, not an invitation to add a table."""
    rng = np.random.default_rng(9)
    s_i, s_j, a_i, a_j, q, _ = assembled_pair(rng, jtype)
    (tmp_path / "m.toml").write_text(mechanism_text("m", [("b1", q[0]), ("b2", q[1])],
                                                    [joint_lines("X", jtype, "b1", "b2", s_i, s_j, a_i, a_j)]))
    (tmp_path / "s.toml").write_text('[scene]\nname = "s"\nmechanism = "m.toml"\nfriction = ["X"]\n'
                                     'eliminate = "auto"\nstop_time = 1.0\n')
    expect = f"joint 'X': a {jtype} joint has no friction model (joint friction: "
    with pytest.raises(SceneError, match=re.escape(f"s.toml: scene.friction[0]: {expect}")) as e:
        load(tmp_path / "s.toml")
    assert f"s.toml: scene.friction[0]: {expect}" in str(e.value)
    assert "no friction parameters" not in str(e.value)
    assert cli.main(["check", str(tmp_path / "m.toml"), "--friction", "X"]) == 2
    err = capsys.readouterr().err
    assert f"m.toml: --friction: {expect}" in err and "no friction parameters" not in err


def test_friction_params_refused_on_a_universal_joint(tmp_path):
    (tmp_path / "us.toml").write_text((DATA / "universal_spherical.toml").read_text())
    (tmp_path / "s.toml").write_text(
        '[scene]\nname = "s"\nmechanism = "us.toml"\nfriction = []\neliminate = "auto"\nstop_time = 1.0\n'
        "[scene.friction_params.U]\nmu = 0.1\nradius = 0.01\n")
    with pytest.raises(SceneError, match=r"s\.toml: scene\.friction_params\.U: a universal joint has no "
                                         r"friction model"):
        load(tmp_path / "s.toml")


def test_friction_size_keys(tmp_path):
    with pytest.raises(SceneError, match=r"joints\[0\] \(X\)\.friction\.length: missing required field"):
        load(_mech_with_friction(tmp_path, "revolute", ["mu = 0.1", "radius = 0.01"]))
    with pytest.raises(SceneError, match=r"joints\[0\] \(X\)\.friction\.radius: missing required field"):
        load(_mech_with_friction(tmp_path, "prismatic", ["mu = 0.1", "length = 0.01"]))
    with pytest.raises(SceneError, match=r"joints\[0\] \(X\)\.friction\.collar_radius: unknown key"):
        load(_mech_with_friction(tmp_path, "cylindrical", ["mu = 0.1", "length = 0.1", "radius = 0.1",
                                                           "collar_radius = 0.2"]))
    mech = load(_mech_with_friction(tmp_path, "revolute", ["mu = 0.1", "radius = 0.01", "length = 0.2"]))
    spec = mech.joints[0].friction
    assert (spec.size, spec.extra) == (0.01, (("length", 0.2),))
    jt = TYPES[mech.joints[0].type]
    assert jt.friction_sizes(spec) == {"radius": 0.01, "length": 0.2, "collar_radius": 0.01}
    # a scene's friction_params override merges onto the mechanism's sizes
    (tmp_path / "s.toml").write_text(
        '[scene]\nname = "s"\nmechanism = "m.toml"\nfriction = ["X"]\neliminate = "auto"\nstop_time = 1.0\n'
        "[scene.friction_params.X]\ncollar_radius = 0.03\n")
    scene = load(tmp_path / "s.toml")
    law = compile_checked(scene).joints[0].law
    assert dict(law.sizes) == {"radius": 0.01, "length": 0.2, "collar_radius": 0.03}


# ----------------------------------------------------------------------------- FMU description

@pytest.mark.integration
def test_fmu_description_of_spatial_joints(tmp_path):
    """A small FMU with a spatial revolute joint with friction: the outputs, units and texts of
    its modelDescription.xml come from the joint type's table and name the file's type name."""
    from overcon.fmu import build as fmu_build
    import xml.etree.ElementTree as ET
    (tmp_path / "pendulum.toml").write_text((DATA / "pendulum.toml").read_text().replace(
        "axis_j = [1.0, 0.0, 0.0]", "axis_j = [1.0, 0.0, 0.0]\n[joints.friction]\nmu = 0.1\nradius = 0.01\nlength = 0.05"))
    (tmp_path / "scene.toml").write_text(
        '[scene]\nname = "pendulum_friction"\nmechanism = "pendulum.toml"\nfriction = ["pivot"]\n'
        'eliminate = "auto"\nstop_time = 0.2\n')
    res = fmu_build.build_scene(tmp_path / "scene.toml", tmp_path / "out", validate=False, echo=lambda s: None)
    assert res.status == "built", res.messages
    with zipfile.ZipFile(res.fmu) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    sv = {v.get("name"): v for v in root.iter("ScalarVariable")}
    comps = ["Fx", "Fy", "Fz", "Tx", "Ty", "Fx0", "Fy0", "Fz0"]
    assert [n for n in sv if n.startswith("pivot.") and n.split(".")[1] in comps + ["Tz"]] == \
        [f"pivot.{c}" for c in comps]
    unit = {n: v.find("Real").get("unit") for n, v in sv.items() if v.find("Real") is not None}
    assert unit["pivot.Tx"] == "N.m" and unit["pivot.Fz"] == "N" and unit["pivot.friction"] == "N.m"
    assert unit["pivot.v_reg"] == "rad/s"
    assert "auxiliary frame of the revolute joint" in sv["pivot.Tx"].get("description")
    assert "moment" in sv["pivot.Tx"].get("description")
    assert "torque about the axis" in sv["pivot.friction"].get("description")
