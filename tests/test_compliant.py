"""Compliant joints (``redundancy = "compliant"``, ``[joints.compliance]``): a joint's equations
become a spring-damper on their violation. Without friction the motion converges to the rigid one
as 1/stiffness; with friction on a joint whose rigid reaction is not unique, the compliant
motion is one motion, whatever elimination the scene names, and it lies apart from the rigid
eliminations' motions."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from overcon import converge as converge_mod
from overcon import scene
from overcon.checks import compile_checked
from overcon.cli import main
from overcon.kernel import support
from overcon.precheck import precheck
from overcon.converge import converge, max_diff, scaled_scene
from overcon.simulate import SimulationError, run

MECH = Path(__file__).resolve().parents[1] / "mechanisms"
SLIDERS = (MECH / "planar_sliders.toml").read_text()


def compliant_sliders(tmp_path: Path, k: float, *, friction: str = "[]", eliminate: str = "", stop: float = 0.5,
                      table: str | None = None) -> Path:
    """The paper's planar mechanism with joint1 compliant (stiffness k in N/m and N.m/rad,
    damping 2 sqrt(k) in N.s/m and N.m.s/rad), run with radau."""
    d = 2.0 * math.sqrt(k)
    table = table or (f"stiffness = {k}\nrotational_stiffness = {k}\ndamping = {d}\nrotational_damping = {d}\n")
    i = SLIDERS.index('name = "joint1"')
    nxt = SLIDERS.find("\n[", i)
    (tmp_path / "mech.toml").write_text(SLIDERS[:nxt] + "\n\n[joints.compliance]\n" + table + SLIDERS[nxt:])
    path = tmp_path / f"compliant_{k:.0e}{eliminate.strip('[]')}.toml"
    path.write_text(f'[scene]\nname = "compliant"\nmechanism = "mech.toml"\nfriction = {friction}\n'
                    f'redundancy = "compliant"\n{"eliminate = " + eliminate if eliminate else ""}\n'
                    f'stop_time = {stop}\n\n[solver]\nmethod = "radau"\ntolerance = 1e-10\n')
    return path


def rigid_sliders(tmp_path: Path, eliminate: int, friction: str = "[]", stop: float = 0.5) -> Path:
    path = tmp_path / f"rigid_{eliminate}.toml"
    path.write_text(f'[scene]\nname = "rigid"\nmechanism = "{MECH / "planar_sliders.toml"}"\nfriction = {friction}\n'
                    f'eliminate = [{eliminate}]\nstop_time = {stop}\n\n[solver]\ntolerance = 1e-12\n')
    return path


def in_core(res):
    """``res`` (a run's Result) with the assertion that the compiled core ran every evaluation."""
    assert res.kernel_note.startswith("right-hand side: compiled kernel"), res.kernel_note
    return res


def positions(path: Path) -> np.ndarray:
    spec = scene.load(path)
    res = in_core(run(compile_checked(spec), spec.solver))
    return res.values[:, [i for i, n in enumerate(res.names) if n.rsplit(".", 1)[1] in ("x", "y", "phi")]]


def test_compiled_compliant_model(tmp_path):
    model = compile_checked(scene.load(compliant_sliders(tmp_path, 1e6)))
    assert model.elimination_mode == "compliant" and model.eliminated == ()
    assert list(model.compliant_rows) == [0, 1]  # joint1: distance (N/m) and angle (N.m/rad) rows
    assert support(model) is None  # the core's compliant solve (core/compliance.c)
    report = precheck(model)
    assert report.redundancy == "compliant" and report.motion_unique
    assert (report.n_equations, report.rank, report.dof, report.redundant) == (10, 10, 2, 0)


def test_without_friction_the_motion_converges_to_the_rigid_one_as_one_over_k(tmp_path):
    """Measured: max position difference 1.07e-2, 1.08e-3, 1.08e-4 m at k = 1e4, 1e5, 1e6 over
    1 s: order 1.00."""
    rigid = positions(rigid_sliders(tmp_path, 4))
    errors = [np.max(np.abs(positions(compliant_sliders(tmp_path, k)) - rigid)) for k in (1e4, 1e5, 1e6)]
    orders = [math.log10(errors[i] / errors[i + 1]) for i in range(2)]
    assert all(0.8 <= p <= 1.2 for p in orders), (errors, orders)


def test_friction_on_a_non_unique_joint_gives_one_motion(tmp_path, capsys):
    """Friction in joint1 (rigidly its reaction is not unique: the eliminations of Phi4 and Phi6
    give motions 0.4 m apart): compliant, the scene's elimination no longer applies, and the
    motion lies apart from both rigid ones (0.09 m and 0.58 m at 2 s, measured)."""
    wo4 = compliant_sliders(tmp_path, 1e6, friction='["joint1"]', eliminate="[4]", stop=2.0)
    wo6 = compliant_sliders(tmp_path, 1e6, friction='["joint1"]', eliminate="[6]", stop=2.0)
    a, b = positions(wo4), positions(wo6)
    assert np.array_equal(a, b)
    r4 = positions(rigid_sliders(tmp_path, 4, '["joint1"]', 2.0))
    r6 = positions(rigid_sliders(tmp_path, 6, '["joint1"]', 2.0))
    assert np.max(np.abs(r4 - r6)) > 0.3
    assert min(np.max(np.abs(a - r4)), np.max(np.abs(a - r6))) > 0.05
    assert main(["check", str(wo4)]) == 0
    out = capsys.readouterr().out
    assert "motion with friction in joint1: UNIQUE" in out
    assert "joint1     translational  1-2       yes     -      -      -      ON  (compliant: its reaction comes from its " \
           "deformation)" in out
    assert "warning: scene.eliminate (Phi4) does not apply under redundancy = 'compliant'" in out


@pytest.mark.parametrize("table, message", [
    ("stiffness = 1e6\n", r"joints\[0\] \(joint1\).compliance.rotational_stiffness: missing required field"),
    ("stiffness = [1e6, 1e6, 1e6]\nrotational_stiffness = 1e6\n",
     r"mech.toml: joints\[0\] \(joint1\).compliance.stiffness: per-axis values \(a 3-vector\) are for spatial joints: "
     r"a planar joint takes one scalar"),
    ("stiffness = 1e6\nrotational_stiffness = nan\n",
     r"joints\[0\] \(joint1\).compliance.rotational_stiffness: must be finite, got nan"),
    ("stiffness = 0.0\nrotational_stiffness = 1e6\n", r"joints\[0\] \(joint1\).compliance.stiffness: must be > 0, got 0.0"),
    ("stiffness = 1e6\nrotational_stiffness = 1e6\ndamping = -1.0\n",
     r"joints\[0\] \(joint1\).compliance.damping: must be >= 0, got -1.0"),
    ("stiffness = 1e6\nrotational_stiffness = 1e6\nspring = 1.0\n", r"joints\[0\] \(joint1\).compliance.spring: unknown key \(allowed: stiffness, rotational_stiffness, "
                                                     r"damping, rotational_damping\)"),
])
def test_compliance_table_is_checked(tmp_path, table, message):
    with pytest.raises(scene.SceneError, match=message):
        scene.load(compliant_sliders(tmp_path, 1e6, table=table))


# ------------------------------------------------------------------ per-axis values (spatial)

BLOCK = """[mechanism]
name = "block"
kind = "spatial"
rotation = "quaternion"
gravity = [0.0, 0.0, -9.81]

[[bodies]]
name = "block"
mass = 2.0
inertia = [0.1, 0.2, 0.3]
q0 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]

[[joints]]
name = "pin"
type = "revolute"
body_i = "block"
body_j = "base"
s_i = [0.0, 0.0, 0.0]
s_j = [0.0, 0.0, 0.0]
axis_i = [1.0, 0.0, 0.0]
axis_j = [1.0, 0.0, 0.0]

[joints.compliance]
"""


def block_scene(tmp_path: Path, table: str, stop: float = 1.0) -> Path:
    """A 2 kg block on a compliant revolute joint at its centre of mass, axis along global x:
    its joint frame is x' = global y, y' = global z, z' = global x (the completion of the axis,
    overcon.joints.spatial_rows.completion), so gravity (-z) loads the frame's y axis only."""
    (tmp_path / "block.toml").write_text(BLOCK + table)
    path = tmp_path / "block_scene.toml"
    path.write_text(f'[scene]\nname = "block_scene"\nmechanism = "block.toml"\nfriction = []\nredundancy = "compliant"\n'
                    f'stop_time = {stop}\n\n[solver]\nmethod = "radau"\ntolerance = 1e-10\n')
    return path


def final_position(path: Path) -> np.ndarray:
    spec = scene.load(path)
    res = in_core(run(compile_checked(spec), spec.solver))
    return np.array([res.values[-1, res.names.index(f"block.{c}")] for c in "xyz"])


def test_per_axis_stiffness_acts_along_the_joint_frame(tmp_path):
    """Static sag under gravity = m g / k along the loaded frame axis (y' = global z), whatever
    the other axes' stiffnesses; damping 2 sqrt(k m) per axis settles it well within 1 s."""
    k = np.array([1e4, 2e4, 4e4])
    d = 2.0 * np.sqrt(k * 2.0)
    table = (f"stiffness = {k.tolist()}\nrotational_stiffness = [1e3, 2e3, 3e3]\ndamping = {d.tolist()}\n"
             f"rotational_damping = 50.0\n")
    x, y, z = final_position(block_scene(tmp_path, table))
    assert abs(z - (-2.0 * 9.81 / k[1])) < 1e-9 * 2.0 * 9.81 / k[1] + 1e-12, z
    assert abs(x) < 1e-12 and abs(y) < 1e-12
    # the isotropic table with the loaded axis's values gives the same sag
    iso = f"stiffness = {k[1]}\nrotational_stiffness = 1e3\ndamping = {d[1]}\nrotational_damping = 50.0\n"
    assert abs(final_position(block_scene(tmp_path, iso))[2] - z) < 1e-12


def test_equal_per_axis_values_are_the_isotropic_joint(tmp_path):
    """[k, k, k] on every value is the scalar k: the same motion of a block swinging on the joint
    0.3 m above its centre of mass (the frame and the directions of the rows turn with it)."""
    body = BLOCK.replace("q0 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]", "q0 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]\n"
                         "h0 = [0.0, 0.9, 0.0, 3.0, 0.0, 0.0]")  # 3 rad/s about the joint 0.3 m above
    body = body.replace("s_i = [0.0, 0.0, 0.0]\ns_j = [0.0, 0.0, 0.0]", "s_i = [0.0, 0.0, 0.3]\ns_j = [0.0, 0.0, 0.3]")
    iso = "stiffness = 1e6\nrotational_stiffness = 1e5\ndamping = 2e3\nrotational_damping = 2e2\n"
    vec = "stiffness = [1e6, 1e6, 1e6]\nrotational_stiffness = [1e5, 1e5, 1e5]\ndamping = 2e3\n" \
          "rotational_damping = [2e2, 2e2, 2e2]\n"
    out = []
    for table in (iso, vec):
        (tmp_path / "block.toml").write_text(body + table)
        path = tmp_path / "block_scene.toml"
        path.write_text('[scene]\nname = "swing"\nmechanism = "block.toml"\nfriction = []\nredundancy = "compliant"\n'
                        'stop_time = 0.5\n\n[solver]\nmethod = "radau"\ntolerance = 1e-10\n')
        spec = scene.load(path)
        model = compile_checked(spec)
        assert len(model.compliance_axes) == (table is vec)
        res = in_core(run(model, spec.solver))
        out.append(res.values)
    pos = [i for i, n in enumerate(res.names) if n.startswith("block.")]
    forces = [i for i, n in enumerate(res.names) if n.startswith("pin.")]
    diff = np.abs(out[0] - out[1])
    # the tensor path restricts K with the rows' actual directions, orthonormal only up to the
    # joint's deformation: the positions agree to round-off (measured 5e-14 m), and a reaction is
    # k times a deformation, so it agrees to the stiffest k (1e6 N/m) times that position bound
    assert diff[:, pos].max() < 1e-12, diff[:, pos].max()
    assert diff[:, forces].max() < 1e6 * 1e-12, diff[:, forces].max()


@pytest.mark.parametrize("table, message", [
    ("stiffness = [1e6, 1e6]\nrotational_stiffness = 1e6\n",
     r"block.toml: joints\[0\] \(pin\).compliance.stiffness: expected a scalar \(isotropic\) or an array of 3 numbers "
     r"\(along the joint frame's x, y, z axes\), got 2 element\(s\)"),
    ("stiffness = 1e6\nrotational_stiffness = [1e6, -1.0, 1e6]\n",
     r"joints\[0\] \(pin\).compliance.rotational_stiffness\[1\]: must be > 0, got -1.0"),
    ("stiffness = 1e6\nrotational_stiffness = 1e6\ndamping = [0.0, inf, 0.0]\n",
     r"joints\[0\] \(pin\).compliance.damping\[1\]: must be finite, got inf"),
    ("stiffness = 1e6\nrotational_stiffness = 1e6\nrotational_damping = [1.0, 1.0, -2.0]\n",
     r"joints\[0\] \(pin\).compliance.rotational_damping\[2\]: must be >= 0, got -2.0"),
])
def test_per_axis_values_are_checked(tmp_path, table, message):
    with pytest.raises(scene.SceneError, match=message):
        scene.load(block_scene(tmp_path, table))


# ------------------------------------------------------------------ the rigid limit (converge)

def test_converge_measures_the_order_and_the_rigid_limit_without_friction(tmp_path):
    """Through overcon.converge: without friction the positions converge as 1/k or faster
    (measured order 1.00 on k = 1e4, 1e5, 1e6), the limit is the rigid motion: the error the
    study estimates for each run (measured 1.07e-2, 1.09e-3, 1.08e-4 m) is its distance to the
    rigid run, which the estimate does not use."""
    study = converge(compliant_sliders(tmp_path, 1e6), np.geomspace(1e4, 1e6, 3), accuracy=2e-3, echo=lambda s: None)
    assert study.order >= 0.9, (study.order, study.pos_next)
    assert [g.label for g in study.rigid] == ["eliminate auto"]
    to_rigid = np.array([max_diff(r.positions, study.rigid[0].positions) for r in study.runs])
    assert np.all((0.5 <= study.error / to_rigid) & (study.error / to_rigid <= 2.0)), (study.error, to_rigid)
    k, measured = study.enough()
    assert measured and k == 1e5 and study.error[1] <= 2e-3 < study.error[0], study.error


def test_converge_scales_every_compliant_value(tmp_path):
    """At stiffness k the stiffnesses are multiplied by k / k0 and the dampings by sqrt(k / k0)
    (k0 the largest translational stiffness, here 1e6 N/m)."""
    spec = scene.load(compliant_sliders(tmp_path, 1e6, table="stiffness = 1e6\nrotational_stiffness = 2e5\n"
                                                               "damping = 10.0\nrotational_damping = 4.0\n"))
    c = next(j.compliance for j in scaled_scene(spec, 1e8).mechanism.joints if j.compliance is not None)
    assert (c.stiffness, c.rotational_stiffness) == (1e8, 2e7)
    assert (c.damping, c.rotational_damping) == pytest.approx((100.0, 40.0), rel=1e-15)


def test_converge_command(tmp_path, capsys, monkeypatch):
    """Exit 0 with the table and the plot; 2 for a bad range or a scene that is not compliant;
    3 naming the run that failed."""
    path = compliant_sliders(tmp_path, 1e5, stop=0.1)
    out = tmp_path / "out"
    assert main(["converge", str(path), "--stiffness", "1e4:1e5:2", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "measured order" in text and "stiffest run against rigid eliminate auto" in text
    rows = (out / "converge.csv").read_text().splitlines()
    assert len(rows) == 3 and rows[0].startswith("stiffness_N_per_m,")
    assert (out / "converge.png").stat().st_size > 0
    assert main(["converge", str(path), "--stiffness", "1e5:1e4:2", "--out", str(out)]) == 2
    assert "--stiffness '1e5:1e4:2': start and stop must be finite with 0 < start < stop" in capsys.readouterr().err
    assert main(["converge", str(rigid_sliders(tmp_path, 4)), "--stiffness", "1e4:1e5:2", "--out", str(out)]) == 2
    assert "scene.redundancy is 'eliminate': converge needs redundancy = \"compliant\"" in capsys.readouterr().err

    def fail(*a, **kw):
        raise SimulationError("t = 0.05 s: step size collapsed")
    monkeypatch.setattr(converge_mod, "run", fail)
    assert main(["converge", str(path), "--stiffness", "1e4:1e5:2", "--out", str(out)]) == 3
    assert "run k = 1e+04 N/m" in capsys.readouterr().err


# ------------------------------------------------------------------ the compliant examples

EXAMPLES = MECH / "examples"


def example_positions(name: str, **kw) -> tuple[list[str], np.ndarray]:
    spec = scene.load(EXAMPLES / f"{name}.toml")
    if kw:
        spec = dataclasses.replace(spec, **kw)
    res = in_core(run(compile_checked(spec), spec.solver))
    cols = [i for i, n in enumerate(res.names) if n.rsplit(".", 1)[1] in ("x", "y", "z")]
    return [res.names[i] for i in cols], res.values[:, cols]


def test_compliant_door_one_motion_whatever_the_elimination(capsys):
    """The door with friction in hinge1 and both hinges compliant (1e8 N/m): the scene's
    elimination no longer applies (both scenes of the group give the same motion), and the motion
    lies apart from both rigid eliminations' (which disagree among themselves); the distances
    are printed (docs/howto/compliant.md)."""
    names, a = example_positions("compliant_door_h1_wo_hinge2")
    _, b = example_positions("compliant_door_h1_wo3_4_5_9_10")
    assert np.array_equal(a, b)
    rigid = [example_positions(n, redundancy="eliminate")[1]
             for n in ("compliant_door_h1_wo_hinge2", "compliant_door_h1_wo3_4_5_9_10")]
    gap = max_diff(rigid[0], rigid[1])
    apart = [max_diff(a, r) for r in rigid]
    print(f"door over 2 s: rigid eliminations {gap:.3e} m apart; compliant (1e8 N/m) {apart[0]:.3e} m from "
          f"[hinge2] eliminated, {apart[1]:.3e} m from [3, 4, 5, 9, 10]")
    # converge measured the compliant run at 1e8 N/m within ~1e-6 m of its limit: the distances
    # to the rigid runs are the limit's, not the springs' deformation
    assert gap > 1e-2 and min(apart) > 1e-3, (gap, apart)


@pytest.mark.parametrize("name", ["compliant_fourbar_A_wo3_4_5", "compliant_loop_A1_wo_A2"])
def test_compliant_examples_run_and_are_unique(name, capsys):
    """The four-bar (hinge A compliant, per-axis values) and the loop (A1 and A2 compliant) with
    friction on their rigidly non-unique hinge: the pre-check says UNIQUE and the run ends."""
    assert main(["check", str(EXAMPLES / f"{name}.toml")]) == 0
    assert ": UNIQUE" in capsys.readouterr().out
    names, x = example_positions(name)
    assert x.shape[0] == 51 and np.all(np.isfinite(x))


# ------------------------------------------------------------------ the compiled core (core/compliance.c)

@pytest.mark.parametrize("name", ["compliant_door_h1_wo_hinge2", "compliant_fourbar_A_wo3_4_5", "compliant_loop_A1_wo_A2",
                                  "compliant_planar_f1_wo4"])
def test_core_compliant_rows_follow_the_force_law(name):
    """Scalar (door, loop, the paper's group) and per-axis values (the four-bar's hinge A), with
    friction on a compliant joint: at states along the run the rigid kept equations hold
    (Baumgarte's form, 1e-9 relative), and every scalar compliant row's multiplier is its
    spring-damper force k Phi + d Phi_h h (core/compliance.c's law) from the core's rows, to
    1e-9 of the largest such force. (Per-axis joints: their energy balance,
    tests/test_compliant_energy.py.)"""
    from test_redundancy import constraint_residuals, states_along_a_run
    from overcon.kernel import rows_at
    spec = scene.load(EXAMPLES / f"{name}.toml")
    model = compile_checked(spec)
    assert support(model) is None and model.compliant_rows.size
    axis_rows = {r for a in model.compliance_axes for r in a.t_rows + a.r_rows}
    scalar = [int(r) for r in model.compliant_rows if int(r) not in axis_rows]
    rigid = [int(r) for r in model.retained if int(r) not in set(int(c) for c in model.compliant_rows)]
    states = states_along_a_run(model, spec.solver, (0.0, 0.02, 0.05))
    for y, (_, lam, J, res) in zip(states, constraint_residuals(model, spec.solver, states, rigid)):
        assert res <= 1e-9, res
        q, h = y[: model.n], y[model.n:]
        phi = rows_at(model, q, h)[0]
        law = model.row_stiffness[scalar] * phi[scalar] + model.row_damping[scalar] * (J[scalar] @ h)
        assert np.max(np.abs(lam[scalar] - law), initial=0.0) <= 1e-9 * max(1.0, float(np.max(np.abs(law), initial=0.0)))


def _door_scene(tmp_path: Path, name: str, redundancy: str | None = None) -> Path:
    """The example ``name`` over 0.3 s with dopri5 (the C runtime's integrators), ``redundancy``
    given (None: the file's), next to its mechanism file."""
    text = (EXAMPLES / f"{name}.toml").read_text()
    text = text.replace("stop_time = 2.0", "stop_time = 0.3").replace('method = "radau"', 'method = "dopri5"')
    if redundancy:
        text = text.replace('redundancy = "compliant"', f'redundancy = "{redundancy}"')
    (tmp_path / "compliant_door.toml").write_text((EXAMPLES / "compliant_door.toml").read_text())
    path = tmp_path / f"{name}_{redundancy or 'own'}.toml"
    path.write_text(text)
    return path


def test_c_fmu_runs_the_compliant_door_whatever_the_elimination(tmp_path):
    """Built with --runtime c (no Python in the FMU): both scenes of the compliant door group give
    the same motion through fmpy, equal to the in-process run."""
    from test_redundancy import _fmu, _simulate
    a = _simulate(_fmu(_door_scene(tmp_path, "compliant_door_h1_wo_hinge2"), tmp_path / "a", "c"))
    b = _simulate(_fmu(_door_scene(tmp_path, "compliant_door_h1_wo3_4_5_9_10"), tmp_path / "b", "c"))
    assert np.array_equal(a, b)
    spec = scene.load(_door_scene(tmp_path, "compliant_door_h1_wo_hinge2"))
    res = in_core(run(compile_checked(spec), spec.solver, stop_time=0.3))
    assert np.max(np.abs(a[: len(res.names)].T - res.values)) <= 1e-9


def test_redundancy_parameter_of_a_compliant_scene(tmp_path):
    """The compliant door's FMU with redundancy = 1 (eliminate) or 2 (min-norm) runs as the scene
    file with that key (bit for bit), and apart from its own compliant motion."""
    from test_redundancy import _fmu, _simulate
    own = _fmu(_door_scene(tmp_path, "compliant_door_h1_wo_hinge2"), tmp_path / "own", "c")
    mine = _simulate(own)
    for value, key in ((1, "eliminate"), (2, "min-norm")):
        keyed = _simulate(_fmu(_door_scene(tmp_path, "compliant_door_h1_wo_hinge2", key), tmp_path / key, "c"))
        assert np.array_equal(_simulate(own, redundancy=value), keyed), key
        assert np.max(np.abs(keyed[:3] - mine[:3])) > 1e-6, key
    assert np.array_equal(_simulate(own, redundancy=3), mine)
