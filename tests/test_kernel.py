"""The compiled core (overcon/core through overcon.kernel) on the paper's, the examples' and random
mechanisms: one solution whatever the warm start, the friction laws and reactions at the
returned multipliers, the statuses it hands back; the selection and its note, and FMUs that carry
it. The stage checks by finite differences and the equations of motion: tests/test_core_rows.py."""
from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from overcon import kernel, scene as scene_mod
from overcon.checks import compile_checked
from overcon.simulate import Simulation, SimulationError, run

MECH = Path(__file__).resolve().parent.parent / "mechanisms"
EXAMPLES = MECH / "examples"
SCENES = ["planar_none_wo4", "planar_f45_wo4", "planar_f145_wo6", "planar_f1_wo4", "spatial_none_wo5",
          "spatial_MN_wo5", "spatial_GHMN_wo18", "spatial_GH_wo9"]
REL_OTHER_COUNT = 1e-9
"""Two friction solves of one evaluation from different starts stop after different numbers of
Newton steps; each result is within the friction tolerance (1e-12 relative on the multipliers)
of the solution, not of each other's bits: the accelerations then agree to the friction
tolerance times the Newton matrix's conditioning."""


def spec_of(name: str, **solver):
    spec = scene_mod.as_scene(scene_mod.load(MECH / f"{name}.toml"))
    return dataclasses.replace(spec, solver=dataclasses.replace(spec.solver, **solver)) if solver else spec


def kernel_for(model, solver):
    k, note = kernel.select(model, dataclasses.replace(solver, kernel="c"))
    assert k is not None and "compiled kernel" in note
    return k


def rel(a, b) -> float:
    return float(np.max(np.abs(a - b), initial=0.0) / max(1.0, float(np.max(np.abs(b), initial=0.0))))


def states(model, n=20, seed=0):
    """Random states around the initial one (not on the constraints: Eq. 18 is defined anyway)."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        q = model.q0 + (0.02 * rng.standard_normal(model.n) if i else 0.0)
        h = model.h0 + (0.5 * rng.standard_normal(model.nh) if i else 0.0)
        yield np.concatenate([q, h])


@pytest.mark.parametrize("name", SCENES)
@pytest.mark.parametrize("baumgarte", [10.0, 0.0])
def test_solution_does_not_depend_on_the_warm_start(name, baumgarte):
    """y' and lam at random states, cold and warm-started (from lam and from friction forces, as
    the integration does), are one solution: without friction the same bits (no iteration); with
    friction within REL_OTHER_COUNT (each solve stops within the friction tolerance of the
    solution). The equations each solution satisfies: tests/test_core_rows.py."""
    spec = spec_of(name, baumgarte=baumgarte)
    model = compile_checked(spec)
    k = kernel_for(model, spec.solver)
    compared = 0
    for y in states(model):
        cold = k.evaluate(0.3, y)
        if cold is None:
            assert k.last_status == 2 and k.newton_failed() > 0, kernel.STATUS[k.last_status]
            continue
        guesses = [(cold[1] * 1.01, None)] + ([(None, cold[2] * 0.99)] if model.friction_joints else [])
        for lam_guess, qf_guess in guesses:
            got = k.evaluate(0.3, y, lam_guess, qf_guess)
            if got is None:
                assert k.last_status == 2 and k.newton_failed() > 0, kernel.STATUS[k.last_status]
                continue
            tol = REL_OTHER_COUNT if model.friction_joints else 0.0
            assert rel(got[0], cold[0]) <= tol and rel(got[1], cold[1]) <= tol, (rel(got[0], cold[0]),
                                                                                  rel(got[1], cold[1]))
            compared += 1
    assert compared >= 20


def test_kernel_covers_loads_and_friction_laws():
    """The Stribeck law on a revolute and a translational joint, in the planar mechanism with its
    spring and torque: at each evaluation the friction outputs obey the law at the returned
    multipliers and the kept acceleration rows hold (tests/test_core_rows.py's checks)."""
    from test_core_rows import check_friction_at, consistent, equation_residuals, solve

    spatial = compile_checked(spec_of("spatial_MN_wo5"))
    assert {ld.type for ld in spatial.loads} == {"force", "torque"}
    spec = scene_mod.as_scene(scene_mod.load(MECH / "planar_f145_wo6.toml"))
    laws = {j: dataclasses.replace(fp, law="stribeck", mu_static=1.5 * fp.mu, v_stribeck=0.05)
            for j, fp in spec.friction_params.items()}
    spec = dataclasses.replace(spec, friction_params=laws)
    model = compile_checked(spec)
    assert {ld.type for ld in model.loads} == {"torque", "spring"}
    assert {model.joints[j].type for j in model.friction_joints} == {"revolute", "translational"}
    assert {model.joints[j].law.name for j in model.friction_joints} == {"stribeck"}
    k = kernel_for(model, spec.solver)
    checked = 0
    for y in states(model, 15, seed=3):
        y = consistent(k, model, y)[0]
        got = solve(k, y)
        if got is None:
            assert k.last_status == 2
            continue
        _, acc, elim = equation_residuals(k, model, spec.solver, y, got)
        assert acc <= 1e-9 and elim == 0.0
        assert check_friction_at(k, model, spec, y, got) <= 1e-9
        checked += 1
    assert checked >= 10


def test_kernel_reports_non_finite_states_and_euler_singularities():
    """A non-finite state and an Euler singularity: the kernel returns its status (the messages:
    tests/test_core.py)."""
    spec = spec_of("spatial_MN_wo5")
    model = compile_checked(spec)
    k = kernel_for(model, spec.solver)
    y = np.concatenate([model.q0, model.h0])
    bad = y.copy()
    bad[0] = np.nan
    assert k.evaluate(0.0, bad) is None and kernel.STATUS[k.last_status] == "non-finite number"
    flat = y.copy()
    flat[4] = 1e-4  # beta of the first body: |sin beta| < SIN_BETA_MIN
    assert k.evaluate(0.0, flat) is None and kernel.STATUS[k.last_status] == "Euler angles singular"
    assert "body 0 has |sin beta| = 0.0001" in k.last_message


def test_singular_position_stops_the_run(tmp_path):
    """The planar sliders driven into K = L = O (spring of free length 0): the run stops with the
    singular position named, before the stop time (docs/explanation/decisions.md: within 1 s)."""
    text = (MECH / "planar_sliders.toml").read_text().replace("free_length = 3.0", "free_length = 0.0")
    (tmp_path / "planar_sliders.toml").write_text(text)
    (tmp_path / "s.toml").write_text((MECH / "planar_none_wo4.toml").read_text())
    spec = scene_mod.as_scene(scene_mod.load(tmp_path / "s.toml"), stop_time=2.0)
    model = compile_checked(spec)
    with pytest.raises(SimulationError, match="singular position") as exc:
        run(model, dataclasses.replace(spec.solver, kernel="c"), stop_time=2.0)
    times = [float(x) for x in re.findall(r"t = ([0-9.]+(?:e-?[0-9]+)?) s", str(exc.value))]
    assert times and 0.0 < times[0] < 1.0, str(exc.value)


UNCOVERED = "2 friction joints (a limit of 1 set for the test)"


def uncovered(tmp_path: Path, monkeypatch) -> Path:
    """The paper's scene with friction in joints 4 and 5, with the kernel's coverage limited to one
    friction joint for the test (the core has no limit): a model the kernel does not cover
    (:data:`UNCOVERED`)."""
    covered = kernel.support
    monkeypatch.setattr(kernel, "support",
                        lambda model: UNCOVERED if len(model.friction_joints) > 1 else covered(model))
    (tmp_path / "planar_sliders.toml").write_text((MECH / "planar_sliders.toml").read_text())
    scene_file = tmp_path / "planar_f45_wo4.toml"
    scene_file.write_text((MECH / "planar_f45_wo4.toml").read_text())
    return scene_file


def test_selection_and_note(monkeypatch, tmp_path):
    """Every run is the core's: auto, c and the deprecated numpy (which warns) name the compiled
    kernel; a model the core does not cover, or no library, refuses to start naming why."""
    spec = spec_of("planar_f45_wo4")
    model = compile_checked(spec)
    for choice in ("auto", "c"):
        assert "compiled kernel" in Simulation(model, dataclasses.replace(spec.solver, kernel=choice)).kernel_note
    with pytest.warns(DeprecationWarning, match="solver.kernel = 'numpy' is deprecated"):
        sim = Simulation(model, dataclasses.replace(spec.solver, kernel="numpy"))
    assert "compiled kernel" in sim.kernel_note
    door = compile_checked(scene_mod.as_scene(scene_mod.load(uncovered(tmp_path, monkeypatch))))
    for choice in ("auto", "c"):
        with pytest.raises(SimulationError, match=re.escape(UNCOVERED)):
            Simulation(door, dataclasses.replace(spec.solver, kernel=choice))
    monkeypatch.undo()  # the kernel's own coverage again
    saved = dict(kernel._state)
    try:
        kernel.disable("no library here (test)")
        with pytest.raises(SimulationError, match="no library here"):
            Simulation(model, spec.solver)
    finally:
        kernel._state.update(saved)


def test_missing_library_names_the_fix(monkeypatch, tmp_path):
    """A source tree whose core was never compiled: a run refuses to start and names the fix
    (pip install -e .)."""
    spec = spec_of("planar_f45_wo4")
    model = compile_checked(spec)
    saved = dict(kernel._state)
    missing = tmp_path / "core" / "libovercore.so"
    monkeypatch.setattr(kernel, "LIBRARY", missing)
    try:
        kernel._state.update(lib=None, reason=None, path=None, tried=False)
        with pytest.raises(SimulationError, match=rf"{re.escape(str(missing))} is missing .*pip install -e \."):
            Simulation(model, spec.solver)
    finally:
        kernel._state.update(saved)


def test_installed_library_is_the_package_core():
    """In process the library is the one the installation compiled inside the package
    (overcon/core/libovercore.*), and nothing else is compiled or cached at run time (a process
    fresh for the kernel: an in-process FMU instance earlier in the session may have chosen its own
    copy with use_library)."""
    saved = dict(kernel._state)
    try:
        kernel._state.update(lib=None, reason=None, path=None, tried=False)
        lib, why = kernel.library()
        assert lib is not None, why
        assert kernel._state["path"] == str(kernel.LIBRARY) and kernel.LIBRARY.parent.name == "core"
        assert kernel.LIBRARY.parent.parent == Path(kernel.__file__).resolve().parent
    finally:
        kernel._state.update(saved)


def check_reactions(k, model, y, lam) -> None:
    """The reported reactions at (y, lam) against the core's Phi_h: each joint's global force
    (Fx0, Fy0(, Fz0), after its type's components) is the physical reaction on body i,
    -(Phi_h)_X^T lam_X on body i's translational velocity columns (docs/reference/conventions.md; on body j
    the opposite when body i is the base), its auxiliary- or joint-frame force has the same
    magnitude (a rotation of it; where the type does not report the axial component, at most
    that), and a joint with friction switched off reports friction 0."""
    J = k.rows(y)[1]
    reac, fric = k.outputs(y, lam)
    d, kh = model.dim, model.nh_b
    for n, c in enumerate(model.joints):
        rows = list(c.rows)
        nc = len(c.components) - d
        glob = reac[n, nc: nc + d]
        if c.bi >= 0:
            want = -J[rows][:, c.bi * kh: c.bi * kh + d].T @ lam[rows]
        else:
            want = J[rows][:, c.bj * kh: c.bj * kh + d].T @ lam[rows]
        scale = max(1.0, float(np.max(np.abs(lam[rows]))))
        assert np.max(np.abs(glob - want)) <= 1e-12 * scale, (c.name, glob, want)
        force = [i for i, name in enumerate(c.components[:nc]) if name.startswith("F")]
        if len(force) == d:  # all components reported: a rotation of the global force
            assert abs(np.linalg.norm(reac[n, force]) - np.linalg.norm(glob)) <= 1e-12 * scale, c.name
        else:  # (prismatic, cylindrical: the axial one, zero on the constraints, is not reported)
            assert np.linalg.norm(reac[n, force]) <= np.linalg.norm(glob) * (1 + 1e-12) + 1e-12 * scale, c.name
        assert not np.any(reac[n, nc + d:])
        if c.law is None:
            assert fric[n] == 0.0


@pytest.mark.parametrize("name", ["planar_f145_wo6", "spatial_GHMN_wo18"])
def test_kernel_outputs_are_the_reactions_of_the_multipliers(name):
    """The reported reactions (every joint) at random states and multipliers are the physical
    reactions of the multipliers (:func:`check_reactions`), and the table the run reports holds
    them; without reactions (lam = 0) friction is zero (the spherical joint has no contact point)."""
    spec = spec_of(name)
    joints = tuple(j.name for j in spec.mechanism.joints)
    spec = dataclasses.replace(spec, reactions=joints, friction_outputs="all")
    model = compile_checked(spec)
    assert model.friction_outputs and len(model.reaction_joints) == len(joints)
    k = kernel.Kernel(kernel.library()[0], model, spec.solver)
    rng = np.random.default_rng(5)
    for y in states(model, 10, seed=5):
        lam = 100.0 * rng.standard_normal(model.m)
        check_reactions(k, model, y, lam)
        table = _derived_table(model, *k.outputs(y, lam))
        assert np.all(np.isfinite(table)) and np.any(table)
    zero = np.zeros(model.m)
    assert not np.any(_derived_table(model, *k.outputs(y, zero)))


def _derived_table(model, reac, fric) -> np.ndarray:
    """The reaction and friction outputs of the model's output plan (kernel.output_plan) from the
    core's per-joint table."""
    kinds = kernel.OUT_KINDS
    return np.array([reac[a, b] if kind == kinds["reaction"] else fric[a]
                     for kind, a, b in kernel.output_plan(model).tolist() if kind in (kinds["reaction"], kinds["friction"])])


def test_cli_kernel_flag_and_scene_field(tmp_path, capsys, monkeypatch):
    """overcon simulate --kernel: the summary names the compiled kernel; the deprecated numpy
    warns on stderr and runs the core; a scene the core cannot run is bad input (exit 2) naming
    the file and why; a scene's [solver] kernel outside auto|c|numpy is refused naming the field."""
    from overcon.cli import main

    out = tmp_path / "o.csv"
    assert main(["simulate", str(MECH / "planar_f45_wo4.toml"), "--stop-time", "0.2", "--out", str(out),
                 "--kernel", "numpy"]) == 0
    cap = capsys.readouterr()
    assert "right-hand side: compiled kernel" in cap.out and "--kernel numpy: solver.kernel = 'numpy' is deprecated" in cap.err
    assert main(["simulate", str(MECH / "planar_f45_wo4.toml"), "--stop-time", "0.2", "--out", str(out)]) == 0
    assert "right-hand side: compiled kernel" in capsys.readouterr().out
    scene_file = uncovered(tmp_path, monkeypatch)
    assert main(["simulate", str(scene_file), "--stop-time", "0.1", "--out", str(out), "--kernel", "c"]) == 2
    assert f"{scene_file}: the compiled core cannot run this scene: {UNCOVERED}" in capsys.readouterr().err
    text = (MECH / "planar_f45_wo4.toml").read_text()
    assert "[solver]" in text
    (tmp_path / "planar_sliders.toml").write_text((MECH / "planar_sliders.toml").read_text())
    (tmp_path / "bad.toml").write_text(text.replace("[solver]", '[solver]\nkernel = "fortran"', 1))
    with pytest.raises(scene_mod.SceneError, match=r"solver\.kernel.*fortran"):
        scene_mod.load(tmp_path / "bad.toml")


def _random_mechanism(path: Path, kind: str, seed: int) -> list[str]:
    """A random open chain (joints to the base on either side, every load type, friction laws of
    both kinds) written as a mechanism file; returns the joint names."""
    rng = np.random.default_rng(seed)
    nb = 3
    vec = (lambda k: ", ".join(f"{x:.6f}" for x in rng.uniform(-0.5, 0.5, k)))
    lines = ['[mechanism]', f'name = "random_{kind}_{seed}"', f'kind = "{kind}"',
             'gravity = [0.0, -9.81]' if kind == "planar" else 'gravity = [0.0, 0.0, -9.81]']
    for b in range(nb):
        if kind == "planar":
            q0 = f"{rng.uniform(-1, 1):.6f}, {rng.uniform(-1, 1):.6f}, {rng.uniform(-3, 3):.6f}"
            inertia = f"{rng.uniform(0.5, 2):.6f}"
        else:
            q0 = (f"{vec(3)}, {rng.uniform(-3, 3):.6f}, {rng.uniform(0.4, 2.7):.6f}, {rng.uniform(-3, 3):.6f}")
            inertia = f"[{rng.uniform(0.5, 2):.6f}, {rng.uniform(0.5, 2):.6f}, {rng.uniform(0.5, 2):.6f}]"
        lines += ['[[bodies]]', f'name = "b{b}"', f'mass = {rng.uniform(0.5, 3):.6f}', f'inertia = {inertia}',
                  f'q0 = [{q0}]']
    names, d = [], (2 if kind == "planar" else 3)
    for j in range(nb):
        bodies = [f"b{j}", "base" if j == 0 else f"b{j - 1}"]
        if rng.random() < 0.5:
            bodies.reverse()
        jtype = "spherical" if kind == "spatial" else ("translational" if j == 1 else "revolute")
        names.append(f"J{j}")
        lines += ['[[joints]]', f'name = "J{j}"', f'type = "{jtype}"', f'body_i = "{bodies[0]}"', f'body_j = "{bodies[1]}"']
        if jtype == "translational":
            lines += [f's_A = [{vec(2)}]', f's_B = [{vec(2)}]', f'v = [{vec(2)}]', f'psi = {rng.uniform(-1, 1):.6f}']
        else:
            lines += [f's_i = [{vec(d)}]', f's_j = [{vec(d)}]']
        size = "length" if jtype == "translational" else "radius"
        law = ['law = "regularised"'] if j % 2 == 0 else ['law = "stribeck"', 'mu_static = 0.5', 'v_stribeck = 0.02']
        lines += ['[joints.friction]', *law, f'mu = {rng.uniform(0.05, 0.4):.6f}', f'{size} = 0.1', 'v_reg = 1e-3']
    torque = f"{rng.uniform(-5, 5):.6f}" if kind == "planar" else f"[{vec(3)}]"
    lines += ['[[loads]]', 'type = "force"', 'body = "b1"', f'value = [{vec(d)}]',
              '[[loads]]', 'type = "torque"', 'body = "b2"', f'value = {torque}',
              '[[loads]]', 'type = "spring"', 'body_i = "b2"', 'body_j = "base"', 'stiffness = 20.0',
              'free_length = 0.3', f's_i = [{vec(d)}]', f's_j = [{vec(d)}]',
              '[[loads]]', 'type = "spring"', 'body_i = "b0"', 'body_j = "b2"', 'stiffness = 5.0',
              'free_length = 0.1', f's_i = [{vec(d)}]', f's_j = [{vec(d)}]']
    path.write_text("\n".join(lines) + "\n")
    return names


def random_planar_model(tmp_path: Path, seed: int, friction: bool = True, kind: str = "planar"):
    """(spec, model) of :func:`_random_mechanism` (not checked at q0: random geometry)."""
    names = _random_mechanism(tmp_path / f"m_{kind}.toml", kind, seed)
    spec = scene_mod.as_scene(scene_mod.load(tmp_path / f"m_{kind}.toml"), friction=names if friction else [],
                              friction_outputs="all" if friction else "none")
    return spec, compile_checked(spec, check_initial=False)


@pytest.mark.parametrize("kind", ["planar", "spatial"])
@pytest.mark.parametrize("seed", range(4))
def test_random_mechanisms(tmp_path, kind, seed):
    """Mechanisms the paper does not have (random geometry, the base as body i or j, forces,
    torques and springs on any body and to the base, Stribeck and regularised friction in every
    joint): at each state the kernel solves as a run does (evaluate, then evaluate_robust; or
    gives up with status 2 where the friction solve has no solution), the kept acceleration rows hold, the friction outputs obey their law
    (tests/test_core_rows.py) and the reactions are those of the multipliers."""
    from test_core_rows import check_friction_at, equation_residuals, solve

    spec, model = random_planar_model(tmp_path, seed, kind=kind)
    assert {ld.type for ld in model.loads} == {"force", "torque", "spring"} and len(model.friction_joints) == 3
    assert any(c.bi < 0 for c in model.joints) or any(c.bj < 0 for c in model.joints)
    k = kernel_for(model, spec.solver)
    compared = 0
    for y in states(model, 24, seed=seed):
        got = solve(k, y)
        if got is None:  # (a random state can couple the joints' friction too strongly)
            assert k.last_status == 2
            continue
        _, acc, elim = equation_residuals(k, model, spec.solver, y, got)
        assert acc <= 1e-9 and elim == 0.0, acc
        assert check_friction_at(k, model, spec, y, got, assembled=False) <= 1e-9
        check_reactions(k, model, y, got[1])
        compared += 1
    assert compared >= 12  # at least half the states


def test_spring_of_zero_free_length_at_coinciding_points(tmp_path):
    """A spring of free length 0 pulls with -k d, defined where its points coincide: the evaluation
    there solves the equations of motion with that spring's force 0; with a positive free length
    coinciding points are refused (status 5, the message: tests/test_core.py)."""
    from test_core_rows import equation_residuals, force_scale

    text = (MECH / "planar_sliders.toml").read_text()
    assert "free_length = 3.0" in text
    for free, ok in (("0.0", True), ("0.5", False)):
        (tmp_path / "m.toml").write_text(text.replace("free_length = 3.0", f"free_length = {free}"))
        spec = scene_mod.as_scene(scene_mod.load(tmp_path / "m.toml"), friction=[])
        model = compile_checked(spec, check_initial=False)
        n = next(i for i, ld in enumerate(model.loads) if ld.type == "spring")
        ld = model.loads[n]
        q = model.q0.copy()
        q[3 * ld.bi: 3 * ld.bi + 2] = 0.0  # slider2 at the base point of its spring (s_i = s_j = 0)
        y = np.concatenate([q, model.h0])
        k = kernel_for(model, spec.solver)
        if ok:
            got = k.evaluate(0.0, y)
            assert got is not None and np.all(np.isfinite(got[0]))
            Qf, acc, _ = equation_residuals(k, model, spec.solver, y, got)
            assert np.max(np.abs(Qf)) <= 1e-9 * force_scale(model, y, got) and acc <= 1e-9
        else:
            assert k.evaluate(0.0, y) is None and kernel.STATUS[k.last_status] == "spring points coincide"


@pytest.mark.integration
def test_check_and_build_refuse_a_kernel_that_cannot_run(tmp_path, capsys, monkeypatch):
    """[solver] kernel = "c" on a model the kernel does not cover: check and build refuse the scene
    (exit 2, file and field named) instead of an FMU that could never start."""
    from overcon.cli import main

    scene_file = uncovered(tmp_path, monkeypatch)
    text = scene_file.read_text()
    scene_file.write_text(text.replace("[solver]", '[solver]\nkernel = "c"', 1) if "[solver]" in text
                          else text + '\n[solver]\nkernel = "c"\n')
    assert main(["check", str(scene_file)]) == 2
    err = capsys.readouterr().err
    assert f"the compiled core cannot run this scene: {UNCOVERED}" in err
    assert main(["build", str(scene_file), "--out", str(tmp_path / "out"), "--no-ref"]) == 2
    assert "cannot run" in capsys.readouterr().err
    assert not list((tmp_path / "out").glob("*.fmu"))


@pytest.mark.integration
def test_set_values_outside_their_rule_refused_before_running(tmp_path, capsys):
    """overcon run/compare --set on an overcon FMU: a value outside the parameter's rule (an
    unknown solver.kernel, a tolerance out of range) is bad input (exit 2) before any run."""
    from overcon.cli import main
    from overcon.fmu.build import build_scene

    r = build_scene(MECH / "planar_none_wo4.toml", tmp_path, echo=lambda *a: None)
    for setting, why in (("solver.kernel=fast", "must be one of auto, c, numpy"),
                         ("solver.tolerance=5", "must be in [1e-14, 0.01]")):
        assert main(["run", str(r.fmu), "--set", setting, "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert f"--set {setting}: {why}" in err and "FAILED" not in err
        assert not (tmp_path / "o" / "planar_none_wo4.csv").exists()
    assert main(["run", str(r.fmu), "--set", "solver.kernel=numpy", "--stop-time", "0.1", "--out", str(tmp_path / "o")]) == 0


# ----------------------------------------------------------------------------- quaternions and the spatial axis joints

EXAMPLE_SCENES = ["door_h1_wo_hinge2", "door_none_wo3_4_5_9_10", "carriage_guide_wo_rod", "carriage_none_wo1_2_3_4",
                  "fourbar_A_wo3_4_5", "fourbar_none_wo18_19_20", "loop_A1_wo_A2", "loop_D_wo3_4_5_9_10"]


def example_spec(name: str, **solver):
    spec = scene_mod.as_scene(scene_mod.load(EXAMPLES / f"{name}.toml"))
    return dataclasses.replace(spec, solver=dataclasses.replace(spec.solver, **solver)) if solver else spec


def quat_of_euler(angles) -> np.ndarray:
    """The unit quaternion (scalar first) of z-x-z angles: the product qz(alpha) qx(beta) qz(gamma)
    of the three elementary rotations' quaternions (cos(t/2), sin(t/2) axis)."""
    def mul(p, q):
        return np.concatenate([[p[0] * q[0] - np.dot(p[1:], q[1:])], p[0] * q[1:] + q[0] * p[1:] + np.cross(p[1:], q[1:])])

    a, b, g = (0.5 * float(x) for x in angles)
    return mul(mul(np.array([np.cos(a), 0.0, 0.0, np.sin(a)]), np.array([np.cos(b), np.sin(b), 0.0, 0.0])),
               np.array([np.cos(g), 0.0, 0.0, np.sin(g)]))


def quaternion_spec(spec):
    """The scene with its spatial mechanism in quaternions: each body's z-x-z angles in q0 turned
    into the same rotation's unit quaternion (h0, body axes, unchanged)."""
    mech = spec.mechanism
    assert mech.kind == "spatial" and mech.rotation == "euler_zxz"
    bodies = tuple(dataclasses.replace(b, q0=tuple(b.q0[:3]) + tuple(float(x) for x in quat_of_euler(b.q0[3:])))
                   for b in mech.bodies)
    return dataclasses.replace(spec, mechanism=dataclasses.replace(mech, rotation="quaternion", bodies=bodies))


def test_kernel_covers_the_examples_and_their_joint_types():
    """Every example mechanism (quaternions; revolute, prismatic, cylindrical and spherical joints)
    is covered by the kernel, and so is each spatial joint type under each rotation."""
    from overcon.joints import TYPES

    kinds = set()
    for name in EXAMPLE_SCENES:
        model = compile_checked(example_spec(name))
        assert model.rotation == "quaternion" and kernel.support(model) is None, name
        kinds |= {c.type for c in model.joints}
    assert kinds == {"spatial_revolute", "spatial_prismatic", "spatial_cylindrical", "spherical"}
    assert {t for t, jt in TYPES.items() if jt.kind == "spatial"} <= {t for (_, t) in kernel._JOINTS}


@pytest.mark.parametrize("name", ["door_h1_wo_hinge2", "carriage_guide_wo_rod", "loop_A1_wo_A2"])
def test_example_outputs_are_the_reactions_of_the_multipliers(name):
    """The reported reactions of the examples (every joint: the axis joints' components in their
    joint frame) are the physical reactions of random multipliers (:func:`check_reactions`)."""
    spec = example_spec(name)
    joints = tuple(j.name for j in spec.mechanism.joints)
    spec = dataclasses.replace(spec, reactions=joints, friction_outputs="all")
    model = compile_checked(spec)
    assert model.friction_outputs and len(model.reaction_joints) == len(joints)
    k = kernel_for(model, spec.solver)
    rng = np.random.default_rng(5)
    for y in states(model, 10, seed=5):
        check_reactions(k, model, y, 100.0 * rng.standard_normal(model.m))


def _random_axis_mechanism(path: Path, rotation: str, seed: int) -> list[str]:
    """A random open chain of six bodies, one joint of every spatial type (revolute, prismatic,
    cylindrical, universal, fixed, spherical; in a random order, the base as body i or j), friction
    of both laws in the four types that have it, every load type; in ``rotation``. Returns the
    names of the joints with a friction table."""
    rng = np.random.default_rng(seed)
    vec = (lambda k: ", ".join(f"{x:.6f}" for x in rng.uniform(-0.5, 0.5, k)))
    types = ["revolute", "prismatic", "cylindrical", "universal", "fixed", "spherical"]
    rng.shuffle(types)
    lines = ['[mechanism]', f'name = "axes_{rotation}_{seed}"', 'kind = "spatial"', f'rotation = "{rotation}"',
             'gravity = [0.0, 0.0, -9.81]']
    for b in range(len(types)):
        angles = [rng.uniform(-3, 3), rng.uniform(0.4, 2.7), rng.uniform(-3, 3)]
        orient = quat_of_euler(angles) if rotation == "quaternion" else angles
        lines += ['[[bodies]]', f'name = "b{b}"', f'mass = {rng.uniform(0.5, 3):.6f}',
                  f'inertia = [{rng.uniform(0.5, 2):.6f}, {rng.uniform(0.5, 2):.6f}, {rng.uniform(0.5, 2):.6f}]',
                  f'q0 = [{vec(3)}, {", ".join(repr(float(x)) for x in orient)}]']
    names = []
    sizes = {"revolute": ("radius", "length", "collar_radius"), "prismatic": ("length", "radius"),
             "cylindrical": ("length", "radius"), "spherical": ("radius",)}
    for j, jtype in enumerate(types):
        bodies = [f"b{j}", "base" if j == 0 else f"b{j - 1}"]
        if rng.random() < 0.5:
            bodies.reverse()
        names.append(f"J{j}")
        lines += ['[[joints]]', f'name = "J{j}"', f'type = "{jtype}"', f'body_i = "{bodies[0]}"',
                  f'body_j = "{bodies[1]}"', f's_i = [{vec(3)}]', f's_j = [{vec(3)}]']
        if jtype != "spherical":
            lines += [f'axis_i = [{vec(3)}]', f'axis_j = [{vec(3)}]']
        if jtype in sizes:
            law = ['law = "regularised"'] if j % 2 == 0 else ['law = "stribeck"', 'mu_static = 0.5', 'v_stribeck = 0.02']
            lines += ['[joints.friction]', *law, f'mu = {rng.uniform(0.02, 0.15):.6f}', 'v_reg = 1e-3']
            lines += [f'{key} = {rng.uniform(0.05, 0.2):.6f}' for key in sizes[jtype]]
    lines += ['[[loads]]', 'type = "force"', 'body = "b1"', f'value = [{vec(3)}]',
              '[[loads]]', 'type = "torque"', 'body = "b2"', f'value = [{vec(3)}]',
              '[[loads]]', 'type = "spring"', 'body_i = "b5"', 'body_j = "base"', 'stiffness = 20.0',
              'free_length = 0.3', f's_i = [{vec(3)}]', f's_j = [{vec(3)}]']
    path.write_text("\n".join(lines) + "\n")
    return [n for n, t in zip(names, types) if t in sizes]


def random_axis_model(tmp_path: Path, rotation: str, seed: int, friction: bool = True):
    frictional = _random_axis_mechanism(tmp_path / "m.toml", rotation, seed)
    spec = scene_mod.as_scene(scene_mod.load(tmp_path / "m.toml"), friction=frictional if friction else [],
                              friction_outputs="all" if friction else "none")
    return spec, compile_checked(spec, check_initial=False)


@pytest.mark.parametrize("rotation", ["euler_zxz", "quaternion"])
@pytest.mark.parametrize("seed", range(4))
def test_random_axis_joints(tmp_path, rotation, seed):
    """Every spatial joint type in random geometry, both rotations, with friction of both laws in
    the revolute, prismatic, cylindrical and spherical joints: at each state the kernel solves as a
    run does (or gives up with status 2), the kept acceleration rows hold, the friction outputs obey their law
    and the reactions are those of the multipliers (as test_random_mechanisms)."""
    from test_core_rows import check_friction_at, equation_residuals, solve

    spec, model = random_axis_model(tmp_path, rotation, seed)
    assert len(model.friction_joints) == 4 and kernel.support(model) is None
    assert {c.type for c in model.joints} == {"spatial_revolute", "spatial_prismatic", "spatial_cylindrical",
                                               "spatial_universal", "spatial_fixed", "spherical"}
    k = kernel_for(model, spec.solver)
    compared = 0
    for y in states(model, 24, seed=seed):
        got = solve(k, y)
        if got is None:
            assert k.last_status == 2
            continue
        _, acc, elim = equation_residuals(k, model, spec.solver, y, got)
        assert acc <= 1e-9 and elim == 0.0, acc
        assert check_friction_at(k, model, spec, y, got, assembled=False) <= 1e-9
        check_reactions(k, model, y, got[1])
        compared += 1
    assert compared >= 12
