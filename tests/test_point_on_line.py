"""The point-on-line joint (issue 37: a particle in a joint with friction; docs/scene-format.md
"Point-on-line joint", docs/joint-friction.md): a bead on a wire.

- A bead on an inclined wire fixed to the ground (mechanisms/examples/bead_wire.toml, and a
  spatial wire) released from rest: `overcon simulate` follows the exact motion of the
  regularised law (v' = A - B v / v_reg below v_reg, then v' = A - B: A = g sin a, B = mu g cos a,
  the textbook x'' = g (sin a - mu cos a) while sliding) to 1e-8 relative over a second; the
  normal force is m g cos a and the friction output -mu m g cos a.
- `overcon check` reports the friction joint's verdict; two coincident wires are redundant, their
  normal forces not unique, and friction on one of them a non-unique motion; under redundancy
  "min-norm" the normal force is shared equally, so friction on one wire is half of it.
- A bead on a spinning rod (mechanisms/examples/bead_spin.toml): the angular momentum about the
  vertical and kinetic energy + dissipated work are conserved, the friction output is mu N with N
  the norm of the reported normal force components.
- FMI 2.0 and 3.0 co-simulation FMUs of both examples repeat the in-process runs (fmpy).
- Refusals name the body, joint and field: an orientation-holding joint on a particle, a particle
  as the line's body, a zero axis, a size key in the friction table.
The rows' derivatives, the reactions, the friction law and the friction Jacobian at random states:
tests/test_joints.py (single-type mechanisms)."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from overcon import scene as scene_mod
from overcon.cli import main
from overcon.simulate import run_scene

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "mechanisms" / "examples"
G = 9.81


def exact_slide(t: np.ndarray, A: float, B: float, v_reg: float) -> tuple[np.ndarray, np.ndarray]:
    """(s, v) along the wire of a bead released from rest under the regularised law: while v <
    v_reg, v' = A - B v / v_reg (v = V (1 - exp(-t / tau)), V = A v_reg / B, tau = v_reg / B),
    reaching v_reg at t1 = -tau ln(1 - B / A); then v' = A - B (needs A > B: it slides)."""
    V, tau = A * v_reg / B, v_reg / B
    t1 = -tau * math.log(1.0 - B / A)
    s1 = V * (t1 - tau * (1.0 - math.exp(-t1 / tau)))
    early = t < t1
    s = np.where(early, V * (t - tau * (1.0 - np.exp(-t / tau))), s1 + v_reg * (t - t1) + 0.5 * (A - B) * (t - t1) ** 2)
    v = np.where(early, V * (1.0 - np.exp(-t / tau)), v_reg + (A - B) * (t - t1))
    return s, v


def _csv(path: Path) -> dict[str, np.ndarray]:
    with path.open() as f:
        rows = list(csv.reader(f))
    return {name: np.array([float(r[k]) for r in rows[1:]]) for k, name in enumerate(rows[0])}


def _assert_slide(t, s, v, A, B, v_reg, what):
    want_s, want_v = exact_slide(t, A, B, v_reg)
    moving = t >= 0.05
    assert np.max(np.abs(s[moving] / want_s[moving] - 1.0)) <= 1e-8, what
    assert np.max(np.abs(v[moving] / want_v[moving] - 1.0)) <= 1e-8, what
    assert np.max(np.abs(s - want_s)) <= 1e-8 * float(want_s[-1]), what
    # the Coulomb limit the regularised law approaches: v = (A - B) t, s = (A - B) t^2 / 2; the start
    # below v_reg shifts the speed by less than v_reg
    assert np.all(np.abs(v - (A - B) * t) <= v_reg) and np.all(np.abs(s - 0.5 * (A - B) * t ** 2) <= v_reg * t), what


def test_bead_on_an_inclined_wire_follows_the_exact_motion(tmp_path):
    """`overcon simulate` on mechanisms/examples/bead_wire_slide.toml (30 degrees, mu = 0.2,
    v_reg = 1e-4, m = 0.5 kg, tolerance 1e-11)."""
    out = tmp_path / "bead.csv"
    assert main(["simulate", str(EXAMPLES / "bead_wire_slide.toml"), "--out", str(out)]) == 0
    r = _csv(out)
    a, mu, m, v_reg = math.radians(30.0), 0.2, 0.5, 1e-4
    u = np.array([math.cos(a), -math.sin(a)])
    s = r["bead.x"] * u[0] + r["bead.y"] * u[1]
    v = r["bead.vx"] * u[0] + r["bead.vy"] * u[1]
    A, B = G * math.sin(a), mu * G * math.cos(a)
    assert r["time"][-1] == 1.0 and len(r["time"]) == 101
    _assert_slide(r["time"], s, v, A, B, v_reg, "planar")
    assert np.max(np.abs(r["bead.x"] * u[1] - r["bead.y"] * u[0])) <= 1e-12  # on the wire
    N = m * G * math.cos(a)
    assert np.max(np.abs(r["wire.N"] / N - 1.0)) <= 1e-10  # the wire pushes the bead up, off the slope
    assert np.allclose(np.c_[r["wire.Fx0"], r["wire.Fy0"]], N * np.array([math.sin(a), math.cos(a)]), rtol=1e-10)
    sliding = r["time"] >= 0.01
    assert np.max(np.abs(r["wire.friction"][sliding] / (-mu * N) - 1.0)) <= 1e-10  # up the slope
    assert r["wire.friction"][0] == 0.0  # at rest


def _spatial_wire(tmp_path: Path, axis, rotation: str = "euler_zxz") -> Path:
    mech = ('[mechanism]\nname = "wire3"\nkind = "spatial"\n'
            f'rotation = "{rotation}"\ngravity = [0.0, 0.0, -9.81]\n'
            '[[bodies]]\nname = "bead"\nkind = "particle"\nmass = 0.3\nq0 = [0.2, -0.1, 0.5]\n'
            '[[joints]]\nname = "wire"\ntype = "point_on_line"\nbody_i = "bead"\nbody_j = "base"\n'
            f's_i = [0.0, 0.0, 0.0]\ns_j = [0.2, -0.1, 0.5]\naxis_j = {[float(x) for x in axis]}\n'
            '[joints.friction]\nlaw = "stribeck"\nmu = 0.25\nmu_static = 0.25\nv_stribeck = 0.1\nv_reg = 1e-4\n')
    (tmp_path / "wire3.toml").write_text(mech)
    scene = tmp_path / "wire3_scene.toml"
    scene.write_text('[scene]\nname = "wire3_scene"\nmechanism = "wire3.toml"\nfriction = ["wire"]\neliminate = []\n'
                     'stop_time = 1.0\n[outputs]\npositions = "all"\nvelocities = "all"\nreactions = "all"\n'
                     'friction = "all"\n[solver]\ntolerance = 1e-12\noutput_interval = 0.01\n')
    return scene


@pytest.mark.parametrize("rotation", ["euler_zxz", "quaternion"])
def test_bead_on_a_spatial_wire_follows_the_exact_motion(tmp_path, rotation):
    """The same on a wire along (2, 1, -1.5) (spatial, two equations, normal force of two
    components; the Stribeck law with mu_static = mu is the regularised one)."""
    axis = np.array([2.0, 1.0, -1.5])
    u = axis / np.linalg.norm(axis)
    out = tmp_path / "wire3.csv"
    assert main(["simulate", str(_spatial_wire(tmp_path, axis, rotation)), "--out", str(out)]) == 0
    r = _csv(out)
    d = np.c_[r["bead.x"] - 0.2, r["bead.y"] + 0.1, r["bead.z"] - 0.5]
    vel = np.c_[r["bead.vx"], r["bead.vy"], r["bead.vz"]]
    sin_a = -u[2]
    cos_a = math.sqrt(1.0 - sin_a * sin_a)
    A, B = G * sin_a, 0.25 * G * cos_a
    _assert_slide(r["time"], d @ u, vel @ u, A, B, 1e-4, rotation)
    assert np.max(np.linalg.norm(d - np.outer(d @ u, u), axis=1)) <= 1e-11  # on the wire
    N = 0.3 * G * cos_a
    assert np.max(np.abs(np.hypot(r["wire.Fx"], r["wire.Fy"]) / N - 1.0)) <= 1e-10
    F0 = np.c_[r["wire.Fx0"], r["wire.Fy0"], r["wire.Fz0"]]
    assert np.max(np.abs(F0 @ u)) <= 1e-10 and np.allclose(np.linalg.norm(F0, axis=1), N, rtol=1e-10)
    sliding = r["time"] >= 0.01
    assert np.max(np.abs(r["wire.friction"][sliding] / (-0.25 * N) - 1.0)) <= 1e-10


def _double_wire(tmp_path: Path, redundancy: str = "eliminate", eliminate: str = '["wire2"]') -> Path:
    """The planar bead on two coincident wires (a sleeve on a double rail): 2 equations, rank 1;
    friction in wire1."""
    text = (EXAMPLES / "bead_wire.toml").read_text()
    second = text[text.index("[[joints]]"):text.index("[joints.friction]")].replace('name = "wire"', 'name = "wire2"')
    text = text.replace('name = "wire"', 'name = "wire1"') + "\n" + second
    (tmp_path / "double.toml").write_text(text)
    scene = tmp_path / "double_scene.toml"
    scene.write_text(f'[scene]\nname = "double_scene"\nmechanism = "double.toml"\nfriction = ["wire1"]\n'
                     f'eliminate = {eliminate}\nredundancy = "{redundancy}"\nstop_time = 1.0\n'
                     '[outputs]\npositions = "all"\nvelocities = "all"\nreactions = "all"\nfriction = "all"\n'
                     '[solver]\ntolerance = 1e-12\noutput_interval = 0.01\n')
    return scene


def test_check_reports_the_friction_joint_and_the_redundant_wires(tmp_path, capsys):
    """One wire: unique reaction, unique motion with its friction; two coincident wires: one
    redundant equation, neither wire's normal force unique, friction in one a non-unique motion."""
    assert main(["check", "--json", str(EXAMPLES / "bead_wire_slide.toml")]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert (doc["n_coordinates"], doc["n_equations"], doc["rank"], doc["dof"], doc["redundant"]) == (2, 1, 1, 1, 0)
    [j] = doc["joints"]
    assert (j["name"], j["type"], j["unique"], j["agree"]) == ("wire", "point_on_line", True, True)
    assert doc["friction"] == ["wire"] and doc["motion_unique"] is True
    assert main(["check", str(EXAMPLES / "bead_spin_slide.toml")]) == 0
    text = capsys.readouterr().out
    assert "rod        point_on_line  6-7       yes" in text and "motion with friction in rod: UNIQUE" in text
    assert main(["check", "--json", str(_double_wire(tmp_path))]) == 1
    doc = json.loads(capsys.readouterr().out)
    assert (doc["n_equations"], doc["rank"], doc["redundant"]) == (2, 1, 1)
    assert [(j["name"], j["unique"]) for j in doc["joints"]] == [("wire1", False), ("wire2", False)]
    assert doc["friction_on_nonunique"] == ["wire1"] and doc["motion_unique"] is False


def test_min_norm_shares_the_normal_force_between_coincident_wires(tmp_path):
    """redundancy = "min-norm": the two wires' normal forces are equal (half of m g cos a each), so
    the friction of wire1 is half the single wire's and the bead slides at A - B / 2."""
    res = run_scene(scene_mod.as_scene(scene_mod.load(_double_wire(tmp_path, "min-norm"))))
    a, m = math.radians(30.0), 0.5
    N = m * G * math.cos(a)
    assert np.allclose(res.column("wire1.N"), N / 2, rtol=1e-10) and np.allclose(res.column("wire2.N"), N / 2, rtol=1e-10)
    u = np.array([math.cos(a), -math.sin(a)])
    s = res.column("bead.x") * u[0] + res.column("bead.y") * u[1]
    v = res.column("bead.vx") * u[0] + res.column("bead.vy") * u[1]
    A, B = G * math.sin(a), 0.2 * G * math.cos(a) / 2
    _assert_slide(res.time, s, v, A, B, 1e-4, "min-norm")


def test_compliant_wires_share_the_normal_force_by_their_stiffness(tmp_path):
    """redundancy = "compliant", both wires spring-dampers of equal stiffness (1e6 N/m, damping
    2e3 N s/m): once the start's transient has died out each carries half the normal force and
    wire1's friction is -mu N / 2 (the friction of a compliant joint from its deformation's force)."""
    comp = "[joints.compliance]\nstiffness = 1e6\nrotational_stiffness = 1e6\ndamping = 2e3\n"
    path = _double_wire(tmp_path, "compliant", "[]")
    mech = tmp_path / "double.toml"
    text = mech.read_text().replace("[joints.friction]", comp + "[joints.friction]")
    mech.write_text(text + comp)
    path.write_text(path.read_text().replace("tolerance = 1e-12", 'tolerance = 1e-10\nmethod = "radau"'))
    res = run_scene(scene_mod.as_scene(scene_mod.load(path)))
    N = 0.5 * G * math.cos(math.radians(30.0))
    late = res.time >= 0.2
    for w in ("wire1", "wire2"):
        assert np.allclose(res.column(f"{w}.N")[late], N / 2, rtol=1e-8), w
    assert np.allclose(res.column("wire1.friction")[late], -0.2 * N / 2, rtol=1e-8)


def _spin_scene(**solver):
    spec = scene_mod.as_scene(scene_mod.load(EXAMPLES / "bead_spin_slide.toml"), solver=solver or None)
    import dataclasses
    return dataclasses.replace(spec, energy=True)


def test_bead_on_a_spinning_rod_conserves_momentum_and_energy():
    """Friction inside the arm-bead pair: L_z = J_z w + m (x vy - y vx) stays 5.02 kg m^2/s, kinetic
    energy + dissipated work stays 25.1 J (the bead stays at z = 0), both to 1e-8 relative; the
    bead slides outward and the friction output is -mu hypot(Fx, Fy) (it opposes the slide)."""
    res = run_scene(_spin_scene())
    col = res.column
    Lz = 0.5 * col("arm.wz") + 0.2 * (col("bead.x") * col("bead.vy") - col("bead.y") * col("bead.vx"))
    assert np.max(np.abs(Lz / 5.02 - 1.0)) <= 1e-8
    total = col("energy.kinetic") + col("energy.dissipated")
    assert np.max(np.abs(total / 25.1 - 1.0)) <= 1e-8 and col("energy.dissipated")[-1] > 5.0
    assert np.max(np.abs(col("bead.z"))) <= 1e-10 and np.max(np.abs(col("energy.potential"))) <= 1e-9
    r = np.hypot(col("bead.x"), col("bead.y"))
    assert np.all(np.diff(r) > 0) and r[-1] > 5.0
    N = np.hypot(col("rod.Fx"), col("rod.Fy"))
    assert np.allclose(col("rod.Fy"), 0.2 * G, rtol=1e-9)  # y = b2 of the axis x: the vertical support
    radial = (col("bead.x") * col("bead.vx") + col("bead.y") * col("bead.vy")) / r  # arm along the bead
    fast = radial > 1e-2
    assert fast.sum() > 90
    assert np.allclose(col("rod.friction")[fast], -0.3 * N[fast], rtol=1e-9)


@pytest.mark.integration
def test_fmus_of_the_bead_examples_repeat_the_process_runs(tmp_path):
    """FMI 2.0 and FMI 3.0 co-simulation FMUs of both examples (`overcon build`), run by fmpy:
    the outputs equal the in-process runs' (the same core, the same steps)."""
    fmpy = pytest.importorskip("fmpy")
    scenes = [EXAMPLES / "bead_wire_slide.toml", EXAMPLES / "bead_spin_slide.toml"]
    refs = {p.stem: run_scene(scene_mod.as_scene(scene_mod.load(p))) for p in scenes}
    names = {"bead_wire_slide": ["bead.x", "bead.y", "wire.N", "wire.friction"],
             "bead_spin_slide": ["bead.x", "bead.y", "arm.wz", "rod.Fx", "rod.Fy", "rod.friction"]}
    for fmi in ("2", "3"):
        out = tmp_path / f"fmi{fmi}"
        assert main(["build", *map(str, scenes), "--out", str(out), "--fmi", fmi, "--no-ref", "--kind", "cs"]) == 0
        for p in scenes:
            ref = refs[p.stem]
            got = fmpy.simulate_fmu(str(out / f"{p.stem}.fmu"), stop_time=1.0, output_interval=0.01,
                                    fmi_type="CoSimulation", output=names[p.stem])
            for name in names[p.stem]:
                assert np.array_equal(got[name], ref.column(name)), (fmi, p.stem, name)


PLANAR = '[mechanism]\nname = "m"\nkind = "planar"\ngravity = [0.0, -9.81]\n'
SPATIAL = '[mechanism]\nname = "m"\nkind = "spatial"\ngravity = [0.0, 0.0, -9.81]\n'
BEAD2 = '[[bodies]]\nname = "bead"\nkind = "particle"\nmass = 1.0\nq0 = [1.0, 0.0]\n'
BEAD3 = '[[bodies]]\nname = "bead"\nkind = "particle"\nmass = 1.0\nq0 = [1.0, 0.0, 0.0]\n'
ROD2 = '[[bodies]]\nname = "rod"\nmass = 1.0\ninertia = 0.1\nq0 = [0.5, 0.0, 0.0]\n'


def _line(bi: str, bj: str, d: int, axis: str, extra: str = "") -> str:
    z = "[" + ", ".join(["0.0"] * d) + "]"
    return (f'[[joints]]\nname = "wire"\ntype = "point_on_line"\nbody_i = "{bi}"\nbody_j = "{bj}"\n'
            f's_i = {z}\ns_j = {z}\naxis_j = {axis}\n{extra}')


@pytest.mark.parametrize("text,field,words", [
    (SPATIAL + BEAD3 + '[[joints]]\nname = "slide"\ntype = "prismatic"\nbody_i = "bead"\nbody_j = "base"\n'
     's_i = [0.0, 0.0, 0.0]\ns_j = [0.0, 0.0, 0.0]\naxis_i = [1.0, 0.0, 0.0]\naxis_j = [1.0, 0.0, 0.0]\n',
     "joints[0] (slide).body_i", "joint slide: body 'bead' is a particle (no orientation), and a prismatic joint "
     "holds its body's orientation; a particle takes spherical, distance, point_on_line joints"),
    (SPATIAL + BEAD3 + '[[joints]]\nname = "hinge"\ntype = "revolute"\nbody_i = "bead"\nbody_j = "base"\n'
     's_i = [0.0, 0.0, 0.0]\ns_j = [0.0, 0.0, 0.0]\naxis_i = [0.0, 0.0, 1.0]\naxis_j = [0.0, 0.0, 1.0]\n',
     "joints[0] (hinge).body_i", "joint hinge: body 'bead' is a particle (no orientation), and a revolute joint "
     "holds its body's orientation; a particle takes spherical, distance, point_on_line joints"),
    (PLANAR + ROD2 + BEAD2 + _line("rod", "bead", 2, "[1.0, 0.0]"), "joints[0] (wire).body_j",
     "joint wire: body 'bead' is a particle (no orientation), and body j of a point_on_line joint carries its "
     "direction (axis_j)"),
    (PLANAR + BEAD2 + _line("bead", "base", 2, "[0.0, 0.0]"), "joints[0] (wire).axis_j", "zero"),
    (SPATIAL + BEAD3 + _line("bead", "base", 3, "[0.0, 0.0, 0.0]"), "joints[0] (wire).axis_j", "zero"),
    (PLANAR + BEAD2 + _line("bead", "base", 2, "[1.0, 0.0]", "[joints.friction]\nmu = 0.1\nradius = 0.01\n"),
     "joints[0] (wire).friction.radius", "the friction of a point_on_line joint has no size"),
    (PLANAR + BEAD2 + _line("bead", "base", 2, "[1.0, 0.0]", "[joints.friction]\nv_reg = 0.01\n"),
     "joints[0] (wire).friction.mu", "missing required field"),
    (PLANAR + BEAD2 + _line("bead", "base", 2, "[1.0, 0.0]").replace("axis_j = [1.0, 0.0]\n", ""),
     "joints[0] (wire)", "axis_j"),
    (SPATIAL + BEAD3 + _line("bead", "base", 3, "[1.0, 0.0, 0.0]", "[joints.compliance]\nstiffness = [1e6, 1e6, 1e5]\n"
                                                                  "rotational_stiffness = 1e6\n"),
     "joints[0] (wire).compliance", "a point_on_line joint takes scalar (isotropic) compliance values only"),
])
def test_refusals_name_the_body_joint_and_field(tmp_path, capsys, text, field, words):
    (tmp_path / "m.toml").write_text(text)
    assert main(["check", str(tmp_path / "m.toml")]) == 2
    err = capsys.readouterr().err
    assert field in err and words in err, err


def test_scene_friction_params_without_a_size(tmp_path):
    """A scene's friction_params for a point_on_line joint take mu and the law alone: mu = 0.1 in
    place of the file's 0.2 gives the acceleration A - B with B = 0.1 g cos a."""
    scene = tmp_path / "s.toml"
    scene.write_text((EXAMPLES / "bead_wire_slide.toml").read_text()
                     .replace('mechanism = "bead_wire.toml"', f'mechanism = "{EXAMPLES / "bead_wire.toml"}"')
                     + '\n[scene.friction_params.wire]\nmu = 0.1\n')
    spec = scene_mod.as_scene(scene_mod.load(scene), tolerance=1e-12)
    assert spec.friction_params["wire"].size is None and spec.friction_params["wire"].mu == 0.1
    res = run_scene(spec)
    a = math.radians(30.0)
    u = np.array([math.cos(a), -math.sin(a)])
    s = res.column("bead.x") * u[0] + res.column("bead.y") * u[1]
    v = res.column("bead.vx") * u[0] + res.column("bead.vy") * u[1]
    _assert_slide(res.time, s, v, G * math.sin(a), 0.1 * G * math.cos(a), 1e-4, "override")
