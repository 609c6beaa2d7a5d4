"""Point masses and massless links (issue 37, item 3): ``[[bodies]] kind = "particle"`` and
``type = "distance"`` (docs/scene-format.md, "Particles" and "Distance joint").

- A particle on a distance joint of length 1 m released horizontally (the benchmark's A01,
  planar and spatial with both rotations): its period is 4 sqrt(L/g) K(1/sqrt(2)) within 1e-6
  relative, and the link's tension output equals m v^2/L + m g cos(psi) (psi from the downward
  vertical, v and psi from the run's outputs) to 1e-8 of the tension's scale, and to 1e-8
  relative wherever it is at least 1% of its largest value.
- A particle pinned at the end of a rigid rod (planar revolute, spatial spherical at the
  particle's position): the compound pendulum's period by quadrature.
- ``check`` counts a particle's position only (2 or 3 coordinates); the refusals name the body,
  the joint or load and the field; the FMUs (FMI 2 and 3, co-simulation and Model Exchange) run
  the particle as the in-process run does."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq
from scipy.special import ellipk

from overcon import scene as scene_mod
from overcon.cli import main
from overcon.simulate import run_scene

G, L = 9.81, 1.0
K = ellipk(0.5)  # K(k) at k = 1/sqrt(2): scipy's parameter is m = k^2


def _write(tmp_path: Path, name: str, mech: str, scene: str = "") -> Path:
    (tmp_path / f"{name}.toml").write_text(mech)
    path = tmp_path / f"{name}_scene.toml"
    path.write_text(f'[scene]\nname = "{name}_scene"\nmechanism = "{name}.toml"\nfriction = []\neliminate = []\n'
                    + scene)
    return path


def bead(tmp_path: Path, kind: str = "planar", rotation: str = "euler_zxz", tolerance: float = 1e-10) -> Path:
    """A 1 kg particle on a 1 m distance joint to the base, released at rest level with the pivot."""
    spatial = kind == "spatial"
    gravity = "[0.0, 0.0, -9.81]" if spatial else "[0.0, -9.81]"
    zero = "[0.0, 0.0, 0.0]" if spatial else "[0.0, 0.0]"
    q0 = "[1.0, 0.0, 0.0]" if spatial else "[1.0, 0.0]"
    rot = f'rotation = "{rotation}"\n' if spatial else ""
    mech = (f'[mechanism]\nname = "bead"\nkind = "{kind}"\n{rot}gravity = {gravity}\n'
            f'[[bodies]]\nname = "bob"\nkind = "particle"\nmass = 1.0\nq0 = {q0}\n'
            f'[[joints]]\nname = "link"\ntype = "distance"\nbody_i = "bob"\nbody_j = "base"\n'
            f's_i = {zero}\ns_j = {zero}\nlength = {L}\n')
    scene = ('stop_time = 10.0\n[outputs]\npositions = "all"\nreactions = "all"\nvelocities = "all"\n'
             f'[solver]\ntolerance = {tolerance}\noutput_interval = 0.001\n')
    return _write(tmp_path, f"bead_{kind}_{rotation}", mech, scene)


def periods(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Times between every other zero of x, located on a cubic spline of the output grid."""
    cs = CubicSpline(t, x)
    idx = np.where(np.sign(x[:-1]) != np.sign(x[1:]))[0]
    roots = np.array([brentq(cs, t[i], t[i + 1], xtol=1e-15) for i in idx])
    return roots[2:] - roots[:-2]


def _scene(path: Path):
    return scene_mod.as_scene(scene_mod.load(path))


@pytest.mark.parametrize("kind,rotation", [("planar", "euler_zxz"), ("spatial", "euler_zxz"),
                                           ("spatial", "quaternion")])
def test_particle_on_a_link_period_and_tension(tmp_path, kind, rotation):
    res = run_scene(_scene(bead(tmp_path, kind, rotation)))
    assert not res.events
    vertical = "bob.z" if kind == "spatial" else "bob.y"
    x, h = res.column("bob.x"), res.column(vertical)
    v2 = sum(res.column(f"bob.v{c}") ** 2 for c in ("xyz" if kind == "spatial" else "xy"))
    assert "bob.phi" not in res.names and "bob.alpha" not in res.names and "bob.e0" not in res.names
    p = periods(res.time, x)
    exact = 4.0 * math.sqrt(L / G) * K
    assert len(p) >= 6
    assert np.max(np.abs(p / exact - 1.0)) < 1e-6, (p, exact)
    # the tension: m v^2 / L + m g cos(psi), psi from the downward vertical (cos psi = -h / L)
    tension = res.column("link.tension")
    expected = 1.0 * v2 / L + 1.0 * G * (-h / L)
    scale = np.max(np.abs(expected))
    assert scale == pytest.approx(3 * G, rel=1e-6)  # 3 m g at the bottom
    assert np.max(np.abs(tension - expected)) <= 1e-8 * scale
    big = np.abs(expected) >= 1e-2 * scale
    assert np.max(np.abs(tension[big] / expected[big] - 1.0)) <= 1e-8
    # the global force on the particle is the tension along the link, towards the pivot
    fx = res.column("link.Fx0")
    assert np.allclose(fx, -tension * x / L, atol=1e-8 * scale)


def _compound(tmp_path: Path, kind: str) -> tuple[Path, float]:
    """A rod (2 kg, 1 m, pinned at one end to the base) with a 0.5 kg particle pinned at its
    other end (planar revolute, spatial spherical, both at the particle's position), released
    level; the exact period of that compound pendulum by quadrature."""
    m_r, m_p, j_c = 2.0, 0.5, 2.0 / 12.0
    spatial = kind == "spatial"
    if spatial:
        head = 'kind = "spatial"\nrotation = "quaternion"\ngravity = [0.0, 0.0, -9.81]\n'
        rod = f'inertia = [0.01, {j_c}, {j_c}]\nq0 = [0.5, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]\n'
        pin, z = "spherical", ", 0.0"
        q_p = "[1.0, 0.0, 0.0]"
    else:
        head = 'kind = "planar"\ngravity = [0.0, -9.81]\n'
        rod = f'inertia = {j_c}\nq0 = [0.5, 0.0, 0.0]\n'
        pin, z = "revolute", ""
        q_p = "[1.0, 0.0]"
    mech = (f'[mechanism]\nname = "compound"\n{head}'
            f'[[bodies]]\nname = "rod"\nmass = {m_r}\n{rod}'
            f'[[bodies]]\nname = "bob"\nkind = "particle"\nmass = {m_p}\nq0 = {q_p}\n'
            f'[[joints]]\nname = "pivot"\ntype = "{pin}"\nbody_i = "rod"\nbody_j = "base"\n'
            f's_i = [-0.5, 0.0{z}]\ns_j = [0.0, 0.0{z}]\n'
            f'[[joints]]\nname = "tip"\ntype = "{pin}"\nbody_i = "bob"\nbody_j = "rod"\n'
            f's_i = [0.0, 0.0{z}]\ns_j = [0.5, 0.0{z}]\n')
    scene = '\nstop_time = 6.0\n[outputs]\npositions = ["bob.x"]\nreactions = []\n[solver]\ntolerance = 1e-10\n' \
            'output_interval = 0.001\n'
    j_p = j_c + m_r * 0.25 + m_p * 1.0
    exact = 4.0 * math.sqrt(j_p / (G * (m_r * 0.5 + m_p * 1.0))) * K
    return _write(tmp_path, f"compound_{kind}", mech, scene), exact


@pytest.mark.parametrize("kind", ["planar", "spatial"])
def test_particle_pinned_to_a_rod(tmp_path, kind, capsys):
    path, exact = _compound(tmp_path, kind)
    assert main(["check", str(path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    per = 3 if kind == "planar" else 6
    dim = 2 if kind == "planar" else 3
    assert report["n_coordinates"] == per + dim  # the rod's coordinates and the particle's position
    assert report["dof"] == (1 if kind == "planar" else 3)  # spatial: the swing, a side swing and the rod's spin
    res = run_scene(_scene(path))
    p = periods(res.time, res.column("bob.x"))
    assert len(p) >= 3
    assert np.max(np.abs(p / exact - 1.0)) < 1e-6, (p, exact)


def test_check_counts_a_particle_by_its_position(tmp_path, capsys):
    for kind, n in (("planar", 2), ("spatial", 3)):
        assert main(["check", str(bead(tmp_path, kind)), "--json"]) == 0
        report = json.loads(capsys.readouterr().out)
        assert (report["n_coordinates"], report["n_equations"], report["rank"], report["dof"]) == (n, 1, 1, n - 1)
        assert report["joints"][0]["type"] == "distance"


PLANAR = '[mechanism]\nname = "m"\nkind = "planar"\ngravity = [0.0, -9.81]\n'
BOB = '[[bodies]]\nname = "bob"\nkind = "particle"\nmass = 1.0\nq0 = [1.0, 0.0]\n'
ROD = '[[bodies]]\nname = "rod"\nmass = 1.0\ninertia = 0.1\nq0 = [0.5, 0.0, 0.0]\n'
LINK = ('[[joints]]\nname = "link"\ntype = "distance"\nbody_i = "bob"\nbody_j = "base"\n'
        's_i = [0.0, 0.0]\ns_j = [0.0, 0.0]\nlength = 1.0\n')


@pytest.mark.parametrize("text,field,words", [
    (PLANAR + BOB.replace("mass = 1.0\n", "mass = 1.0\ninertia = 0.1\n") + LINK,
     "bodies[0] (bob).inertia", "a particle (kind = \"particle\") is a point mass: it has no inertia"),
    (PLANAR + BOB.replace("[1.0, 0.0]", "[1.0, 0.0, 0.0]") + LINK, "bodies[0] (bob).q0", "expected an array of 2 numbers, got 3"),
    (PLANAR + BOB.replace('"particle"', '"point"') + LINK, "bodies[0] (bob).kind", "rigid, particle"),
    (PLANAR + BOB + '[[joints]]\nname = "guide"\ntype = "translational"\nbody_i = "bob"\nbody_j = "base"\n'
     's_A = [0.0, 0.0]\ns_B = [0.0, 0.0]\nv = [0.0, 1.0]\n', "joints[0] (guide).body_i",
     "joint guide: body 'bob' is a particle (no orientation), and a translational joint holds its body's "
     "orientation; a particle takes revolute, distance, point_on_line joints"),
    (PLANAR + BOB + '[[joints]]\nname = "pin"\ntype = "revolute"\nbody_i = "bob"\nbody_j = "base"\n'
     's_i = [0.1, 0.0]\ns_j = [1.1, 0.0]\n', "joints[0] (pin).s_i",
     "joint pin: must be [0, 0] on particle 'bob': a joint acts at a particle's position"),
    (PLANAR + ROD + BOB + '[[joints]]\nname = "pin"\ntype = "revolute"\nbody_i = "rod"\nbody_j = "bob"\n'
     's_i = [0.5, 0.0]\ns_j = [0.0, 0.0]\n[joints.friction]\nmu = 0.1\nradius = 0.01\n', "joints[0] (pin).friction",
     "friction in a revolute joint on particle 'bob' is refused: a point mass has no rotational inertia"),
    (PLANAR + BOB + LINK + '[[loads]]\ntype = "torque"\nbody = "bob"\nvalue = 1.0\n', "loads[0].body",
     "body 'bob' is a particle: a point mass takes no torque"),
    (PLANAR + BOB + LINK + '[[loads]]\ntype = "spring"\nbody_i = "bob"\nbody_j = "base"\nstiffness = 1.0\n'
     'free_length = 0.0\ns_i = [0.0, 0.1]\n', "loads[0].s_i", "must be [0, 0] on particle 'bob'"),
    (PLANAR + BOB + LINK.replace("length = 1.0", "length = 0.0"), "joints[0] (link).length", "must be > 0"),
    (PLANAR + BOB + LINK.replace("length = 1.0\n", ""), "joints[0] (link)", "length"),
])
def test_refusals_name_the_body_joint_and_field(tmp_path, capsys, text, field, words):
    (tmp_path / "m.toml").write_text(text)
    assert main(["check", str(tmp_path / "m.toml")]) == 2
    err = capsys.readouterr().err
    assert field in err and words in err, err


def test_scene_friction_on_a_particle_pin_and_its_orientation_outputs_are_refused(tmp_path, capsys):
    mech = (PLANAR + ROD + BOB + '[[joints]]\nname = "pivot"\ntype = "revolute"\nbody_i = "rod"\nbody_j = "base"\n'
            's_i = [-0.5, 0.0]\ns_j = [0.0, 0.0]\n'
            '[[joints]]\nname = "pin"\ntype = "revolute"\nbody_i = "rod"\nbody_j = "bob"\n'
            's_i = [0.5, 0.0]\ns_j = [0.0, 0.0]\n')
    path = _write(tmp_path, "m", mech, 'stop_time = 1.0\n[scene.friction_params.pin]\nmu = 0.1\nradius = 0.01\n'
                                       '[outputs]\npositions = ["bob.phi"]\n')
    path.write_text(path.read_text().replace("friction = []", 'friction = ["pin"]'))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "scene.friction[0]: joint 'pin': friction in a revolute joint on particle 'bob' is refused" in err, err
    assert "outputs.positions[0]: unknown coordinate 'phi' (allowed: x, y) (a particle has no orientation)" in err, err


@pytest.mark.integration
def test_fmus_run_a_particle_as_the_process_does(tmp_path):
    """The bead as FMI 2.0 and FMI 3.0 FMUs (both kinds): co-simulation repeats the in-process
    run's outputs; Model Exchange under fmpy's CVode follows it to its tolerance."""
    fmpy = pytest.importorskip("fmpy")
    from overcon.fmu import build as fmu_build
    path = bead(tmp_path, "planar", tolerance=1e-9)
    path.write_text(path.read_text().replace("stop_time = 10.0", "stop_time = 2.0")
                    .replace("output_interval = 0.001", "output_interval = 0.01"))
    ref = run_scene(_scene(path))
    for fmi in (2, 3):
        lines = []
        code, results = fmu_build.build_all([str(path)], tmp_path / f"fmi{fmi}", refs=False, fmi=fmi,
                                            echo=lines.append, echo_err=lines.append)
        assert code == 0, lines
        fmu = str(results[0].fmu)
        cs = fmpy.simulate_fmu(fmu, stop_time=2.0, output_interval=0.01, fmi_type="CoSimulation",
                               output=["bob.x", "bob.y", "link.tension"])
        for name in ("bob.x", "bob.y", "link.tension"):
            assert np.array_equal(cs[name], ref.column(name)), (fmi, name)
        me = fmpy.simulate_fmu(fmu, stop_time=2.0, output_interval=0.01, fmi_type="ModelExchange",
                               output=["bob.x", "link.tension"], solver="CVode", relative_tolerance=1e-10)
        assert np.max(np.abs(me["bob.x"] - ref.column("bob.x"))) < 1e-6
        assert np.max(np.abs(me["link.tension"] - ref.column("link.tension"))) < 1e-5


@pytest.mark.parametrize("kind", ["planar", "spatial"])
def test_friction_in_the_pin_of_the_rod_that_carries_a_particle(tmp_path, kind):
    """Friction where a particle's mechanism has it: the rod's pivot (planar revolute, spatial
    spherical) with friction; the particle hangs on at its pin. The friction output is nonzero
    while the rod swings, and the energy balance closes: kinetic + potential + dissipated stays
    constant (energy outputs, core/energy.c) while the dissipated work grows."""
    path, _ = _compound(tmp_path, kind)
    text = path.read_text().replace('friction = []', 'friction = ["pivot"]')
    text = text.replace('reactions = []\n', 'reactions = []\nfriction = "all"\nenergy = true\n')
    text += '[scene.friction_params.pivot]\nmu = 0.2\nradius = 0.02\n'
    path.write_text(text.replace("stop_time = 6.0", "stop_time = 2.0"))
    res = run_scene(_scene(path))
    fr = res.column("pivot.friction")
    assert np.max(np.abs(fr)) > 0.01
    kin, pot, dis = (res.column(f"energy.{k}") for k in ("kinetic", "potential", "dissipated"))
    assert dis[-1] > 0.01
    total = kin + pot + dis
    assert np.max(np.abs(total - total[0])) < 1e-6 * max(1.0, float(np.max(np.abs(pot))))
