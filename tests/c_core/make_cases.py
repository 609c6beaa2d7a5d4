"""Writes the C core's test cases for driver.c (``python tests/c_core/make_cases.py OUT``): packed
models, exactly as overcon.kernel packs them, and evaluations with what the installed core returns
for each (status, friction force evaluations, damped flag, y', lam, qf, reactions, friction
outputs). ci/sanitize.sh then runs the same cases through the core compiled with AddressSanitizer
and UndefinedBehaviorSanitizer and requires the same bits: both builds use -ffp-contract=off
without fast-math, so the compiler may not change any floating-point result.

The cases: the paper's planar mechanism (friction in two revolute and one translational joint) and
its spatial mechanism (friction in two spherical joints) at random states, cold and warm-started;
the quaternion examples (door: spatial revolute joints; carriage: prismatic and cylindrical; loop:
revolute and spherical, each with friction) and a random chain of every spatial joint type in
Euler angles (universal and fixed joints too); redundancy "min-norm" (the paper's planar group, the door) and
"compliant" (the door, the four-bar with per-axis values, the paper's group), evaluated and run;
the point-on-line examples with friction on a particle (bead_wire_slide planar, bead_spin_slide spatial);
spatial states where Newton gives up and damped Newton finishes; and every failure status: a
singular position (tests/data/two_pins: two pins on one bar, rows exactly dependent), the friction solve giving up
(friction_max_iter = 2), a non-finite state, an Euler singularity, a spring whose points coincide.
Runs in C with every integrator: dopri5, rk4, dop853 (its dense stages) and radau (its real and
complex LU), and a radau run whose step collapses on failing friction solves (status 8).
The script refuses to write a file that lacks any of these.

File layout (native byte order): b"OVKCASE1", then records. 'M' a model: 13 int32 counts (ovk_model
order), baumgarte and tol (float64), then per array field of ovk_model an int32 length and its
items (int32 or float64). 'E' an evaluation of the last model: guess mode, y, guess, expected
status, iterations, damped, for status 2 the status of the robust path (ovk_evaluate_robust) and
for its success y' and lam, and for status 0 y', lam, qf, reactions, friction outputs (each an
int32 length and float64 items). 'R' a run of the last model in C (core/sim.c): method, energy ledger (0/1), tolerance,
max_step, step, end time, y0, then what the installed core's run gave: status, y at the end, the
first 10 entries of ovk_sim_info (all but the wall time), reactions, friction outputs and energies at the end
(a run the watch stops: its status and empty arrays). The model record ends with ovk_model's
formulation (int32). 'P' a projection of the last model (ovk_project): tol (float64), max_iter
(int32), y, then what the installed core gave: status, the projected y and the drift (empty on a
failure).
"""
from __future__ import annotations

import argparse
import dataclasses
import struct
import sys
import tempfile
from pathlib import Path

import numpy as np

from overcon import kernel, scene as scene_mod
from overcon.checks import compile_checked
from overcon.spec import DriverSpec
from overcon.fmu.cmodel import watch_rows

MECH = Path(__file__).resolve().parents[2] / "mechanisms"
COUNTS = ("dim", "nb", "nq_b", "nh_b", "m", "nR", "nj", "nl", "nx", "ncols", "nfj", "nfg", "max_iter")
FLOATS = ("baumgarte", "tol")
DOUBLE_FIELDS = {"Minv", "mass", "inertia", "gravity", "jconst", "jlawp", "lp"}
BRICARD = Path(__file__).resolve().parents[1] / "data" / "bricard" / "bricard_wo2.toml"
TWO_PINS = Path(__file__).resolve().parents[1] / "data" / "two_pins" / "two_pins_wo3.toml"


class Writer:
    def __init__(self):
        self.parts = [b"OVKCASE1"]
        self.counts = {"models": 0, "evaluations": 0, "statuses": {}, "damped_ok": 0}
        self.kernel = None

    def ints(self, a):
        a = np.ascontiguousarray(a, dtype=np.int32).reshape(-1)
        self.parts.append(struct.pack("=i", a.size) + a.tobytes())

    def doubles(self, a):
        a = np.ascontiguousarray(a, dtype=np.float64).reshape(-1)
        self.parts.append(struct.pack("=i", a.size) + a.tobytes())

    def model(self, model, solver):
        assert kernel.support(model) is None, kernel.support(model)
        k = kernel.Kernel(kernel.library()[0], model, solver, watch_rows(model))  # the rows of the 'R' runs' watch
        cm = k._cmodel
        by_address = {a.ctypes.data: a for a in k._keep}
        self.parts.append(b"M" + struct.pack("=13i", *(getattr(cm, n) for n in COUNTS))
                          + struct.pack("=2d", *(getattr(cm, n) for n in FLOATS)))
        red = set(kernel.REDUNDANCY_COUNTS + kernel.REDUNDANCY_ARRAYS)
        for name, ctype in cm._fields_:
            if name in COUNTS or name in FLOATS or name in red or name in ("formulation", "nu") \
                    or name in kernel.INPUT_ARRAYS:
                continue
            (self.doubles if name in DOUBLE_FIELDS else self.ints)(by_address[getattr(cm, name)])
        self.parts.append(struct.pack("=5i", *(getattr(cm, n) for n in kernel.REDUNDANCY_COUNTS)))
        for name in kernel.REDUNDANCY_ARRAYS:
            (self.doubles if name in kernel.REDUNDANCY_DOUBLES else self.ints)(by_address[getattr(cm, name)])
        self.parts.append(struct.pack("=i", cm.formulation))
        self.parts.append(struct.pack("=i", cm.nu))  # the inputs (core/inputs.c)
        self.ints(by_address[cm.ukind])
        self.ints(by_address[cm.uidx])
        self.doubles(by_address[cm.up])
        self.kernel = k
        self.counts["models"] += 1
        return k

    def evaluation(self, y, lam_guess=None, qf_guess=None):
        k = self.kernel
        got = k.evaluate(0.0, y, lam_guess, qf_guess)
        if qf_guess is not None and k._ncols:
            mode, guess = 1, qf_guess
        elif lam_guess is not None:
            mode, guess = 2, lam_guess
        else:
            mode, guess = 0, np.zeros(0)
        status = k.last_status
        self.parts.append(b"E" + struct.pack("=i", mode))
        self.doubles(y)
        self.doubles(guess)
        self.parts.append(struct.pack("=3i", status, k._its.value, k._damped.value))
        if status == 2:  # the robust path (friction_robust.c) finishes it or gives up too
            robust = k.evaluate_robust(y, guess if mode == 2 else None)
            self.parts.append(struct.pack("=i", k.last_status))
            if robust is not None:
                self.doubles(robust[0])
                self.doubles(robust[1])
            key = "robust_ok" if robust is not None else "robust_failed"
            self.counts[key] = self.counts.get(key, 0) + 1
        if status == 0:
            ydot, lam, qf, _ = got
            reac, fric = k.outputs(y, lam)
            for a in (ydot, lam, qf, reac, fric):
                self.doubles(a)
            self.counts["damped_ok"] += int(k.damped)
        st = self.counts["statuses"]
        st[status] = st.get(status, 0) + 1
        self.counts["evaluations"] += 1
        return status

    def run(self, model, solver, method: str, t_end: float) -> int:
        """A run of the model with ``method`` to t_end (the driver also saves and restores its
        state half-way and requires the same bits, or the same stop); its status."""
        solver = dataclasses.replace(solver, method=method)
        run = kernel.Run(model, solver, watch=watch_rows(model))
        y0 = np.concatenate([model.q0, model.h0])
        self.parts.append(b"R" + struct.pack("=2i4d", kernel.C_METHODS[method], int(model.energy_outputs),
                                             solver.tolerance, solver.max_step, solver.step, t_end))
        self.doubles(y0)
        try:
            run.advance(t_end / 2)
            y = run.advance(t_end)
            reac, fric = run.outputs(t_end, y)
            energies = run.energies(t_end, y)
            status = 0
        except kernel.RunStopped as exc:  # a stop (the watch's) in the second half: the driver expects it
            status, reac, fric, energies = exc.status, np.zeros(0), np.zeros(0), np.zeros(0)
            y = np.zeros(0)
        info = run.info if status == 0 else {k: 0.0 for k in kernel.INFO}
        self.parts.append(struct.pack("=i", status))
        for a in (y, [info[k] for k in kernel.INFO[:10]], reac, fric, energies):
            self.doubles(a)
        self.counts["runs"] = self.counts.get("runs", 0) + 1
        return status

    def projection(self, y, tol: float, max_iter: int) -> int:
        """A 'P' record: ovk_project of the last model at y (core/project.c) and what it gave."""
        k = self.kernel
        try:
            out, drift = k.project(0.0, y, tol, max_iter)
        except kernel.ProjectionFailed:
            out, drift = np.zeros(0), 0.0
        self.parts.append(b"P" + struct.pack("=di", tol, max_iter))
        self.doubles(y)
        self.parts.append(struct.pack("=i", k.last_status))
        self.doubles(out)
        self.doubles([drift] if out.size else [])
        self.counts["projections"] = self.counts.get("projections", 0) + 1
        return k.last_status

    def write(self, path: Path):
        path.write_bytes(b"".join(self.parts))


def spec_of(path: Path, **solver):
    spec = scene_mod.as_scene(scene_mod.load(path))
    return dataclasses.replace(spec, solver=dataclasses.replace(spec.solver, **solver)) if solver else spec


def states(model, n, seed):
    rng = np.random.default_rng(seed)
    for i in range(n):
        q = model.q0 + (0.02 * rng.standard_normal(model.n) if i else 0.0)
        h = model.h0 + (0.5 * rng.standard_normal(model.nh) if i else 0.0)
        yield np.concatenate([q, h])


def random_states(w: Writer, model, n, seed):
    """n states around the initial one, each cold and warm-started from lam and from qf."""
    rng = np.random.default_rng(seed + 100)
    for y in states(model, n, seed):
        w.evaluation(y)
        w.evaluation(y, lam_guess=rng.standard_normal(model.m))
        if w.kernel._ncols:
            w.evaluation(y, qf_guess=rng.standard_normal(w.kernel._ncols))


def watch_stops(w: "Writer", tmp: Path) -> None:
    """Runs through the watch (core/watch.c): the N-four-bar passing its flat position (a singular
    position located inside a step, status 12), the parallelogram whose elimination expires and
    the Bricard linkage whose elimination degrades (both chosen again: the run goes on, status 0),
    and the parallelogram with friction on a joint with a non-unique reaction, whose expiring
    elimination stops it on a failed step (status 14)."""
    import subprocess
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from test_watch import _parallelogram
    subprocess.run([sys.executable, str(MECH / "examples" / "nfourbar.py"), "2", "--out", str(tmp)], check=True,
                   capture_output=True)
    for path, t_end, want in ((tmp / "nfourbar_2_scene.toml", 0.8, 12), (_parallelogram(tmp, None, "[11]"), 0.3, 0),
                              (BRICARD, 1.3, 0)):
        spec = scene_mod.as_scene(scene_mod.load(path), stop_time=t_end)
        model = compile_checked(spec)
        w.model(model, spec.solver)
        status = w.run(model, spec.solver, "dopri5", t_end)
        if status != want:
            raise SystemExit(f"make_cases: {path.name} stopped with status {status}, not {want}")
    # a failed step whose cause is the elimination expiring (watch.c, ovk_sim_expiring): status 14
    spec = scene_mod.as_scene(scene_mod.load(_parallelogram(tmp, "G0", "[11]")), stop_time=0.3)
    spec = dataclasses.replace(spec, friction_params={k: dataclasses.replace(v, mu=0.5)
                                                      for k, v in spec.friction_params.items()})
    model = compile_checked(spec)
    w.model(model, spec.solver)
    if w.run(model, dataclasses.replace(spec.solver, tolerance=1e-8), "dopri5", 0.3) != 14:
        raise SystemExit("make_cases: the parallelogram with friction did not stop as its elimination expired")


def singular_pass(w: "Writer", tmp: Path) -> None:
    """Formulation AL (solver.singular = "pass": core/kkt_al.c, core/project.c): evaluations of a
    friction scene and of the N-four-bar at its flat position (where S is singular), projections
    of perturbed states (one that reaches the constraints, one that runs out of corrections), and
    C runs through the N-four-bar's flat position (the watch passing it) and of a friction scene."""
    import subprocess
    subprocess.run([sys.executable, str(MECH / "examples" / "nfourbar.py"), "2", "--out", str(tmp / "al"),
                    "--singular", "pass"], check=True, capture_output=True)
    spec = scene_mod.as_scene(scene_mod.load(tmp / "al" / "nfourbar_2_scene.toml"), stop_time=1.0)
    model = compile_checked(spec)
    w.model(model, spec.solver)
    flat = np.concatenate([model.q0, model.h0])
    for b, name in enumerate(model.body_names):  # every link on the ground line: cranks along +x
        i = int(name[-1])
        flat[3 * b: 3 * b + 3] = (i + 0.5, 0.0, 0.0) if name.startswith("crank") else (i + 1.5, 0.0, 0.0)
    if w.evaluation(flat) != 0:
        raise SystemExit("make_cases: the AL evaluation at the N-four-bar's flat position failed")
    rng = np.random.default_rng(5)
    y = np.concatenate([model.q0, model.h0]) + 1e-4 * rng.standard_normal(model.n + model.nh)
    if w.projection(y, 1e-11, 20) != 0 or w.projection(y + 0.1, 1e-11, 1) != 15:
        raise SystemExit("make_cases: the projections did not give status 0 and 15")
    if w.run(model, spec.solver, "dopri5", 1.0) != 0:
        raise SystemExit("make_cases: the C run with singular = 'pass' did not pass the flat position")
    spec = spec_of(MECH / "planar_f145_wo6.toml", singular="pass")
    model = compile_checked(spec)
    w.model(model, spec.solver)
    random_states(w, model, 4, seed=11)
    w.run(model, spec.solver, "dopri5", 0.2)


PARTICLES = {
    "planar": ('kind = "planar"\ngravity = [0.0, -9.81]\n', "[0.5, 0.0, 0.0]", "0.1", "[1.0, 0.2]",
               "[0.0, 0.0]", "[0.5, 0.0]", "revolute"),
    "spatial": ('kind = "spatial"\nrotation = "quaternion"\ngravity = [0.0, 0.0, -9.81]\n',
                "[0.5, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]", "[0.01, 0.1, 0.1]", "[1.0, 0.2, 0.0]", "[0.0, 0.0, 0.0]",
                "[0.5, 0.0, 0.0]", "spherical"),
}


def particles(w: Writer, tmp: Path) -> None:
    """A rod pinned to the base (planar revolute, spatial spherical) with a particle on a distance
    joint of 0.2 m from its free end (joints_distance.c, a particle's frozen orientation), planar
    and spatial: evaluations at random states and a run."""
    for kind, (head, q_rod, inertia, q_p, zero, tip, pin) in PARTICLES.items():
        mech = (f'[mechanism]\nname = "p_{kind}"\n{head}'
                f'[[bodies]]\nname = "rod"\nmass = 2.0\ninertia = {inertia}\nq0 = {q_rod}\n'
                f'[[bodies]]\nname = "bob"\nkind = "particle"\nmass = 0.5\nq0 = {q_p}\n'
                f'[[joints]]\nname = "pivot"\ntype = "{pin}"\nbody_i = "rod"\nbody_j = "base"\n'
                f's_i = {tip.replace("0.5", "-0.5", 1)}\ns_j = {zero}\n'
                f'[[joints]]\nname = "link"\ntype = "distance"\nbody_i = "bob"\nbody_j = "rod"\n'
                f's_i = {zero}\ns_j = {tip}\nlength = 0.2\n')
        (tmp / f"p_{kind}.toml").write_text(mech)
        (tmp / f"p_{kind}_scene.toml").write_text(f'[scene]\nname = "p_{kind}_scene"\nmechanism = "p_{kind}.toml"\n'
                                                  'friction = []\neliminate = []\nstop_time = 1.0\n')
        spec = spec_of(tmp / f"p_{kind}_scene.toml")
        model = compile_checked(spec)
        w.model(model, spec.solver)
        random_states(w, model, 4, seed=5)
        w.run(model, spec.solver, "dopri5", 0.2)


def beads(w: Writer) -> None:
    """The point-on-line examples with friction (mechanisms/examples/bead_wire_slide.toml, planar,
    joints_planar.c's line rows and friction; bead_spin_slide.toml, spatial, joints_spatial.c's):
    evaluations at random states (friction solves at arbitrary sliding speeds) and a run."""
    for name in ("bead_wire_slide", "bead_spin_slide"):
        spec = spec_of(MECH / "examples" / f"{name}.toml")
        model = compile_checked(spec)
        w.model(model, spec.solver)
        random_states(w, model, 6, seed=9)
        w.run(model, spec.solver, "dopri5", 0.2)


def build(tmp: Path) -> Writer:
    w = Writer()
    singular_pass(w, tmp)
    watch_stops(w, tmp)
    particles(w, tmp)
    beads(w)
    for name, n in (("planar_f145_wo6", 12), ("spatial_MN_wo5", 12), ("spatial_GH_wo9", 30), ("spatial_GHMN_wo18", 30)):
        spec = spec_of(MECH / f"{name}.toml")
        model = compile_checked(spec)
        w.model(model, spec.solver)
        random_states(w, model, n, seed=7)
        if name in ("planar_f145_wo6", "spatial_GH_wo9"):
            w.run(model, spec.solver, "dopri5", 0.2)
            w.run(dataclasses.replace(model, energy_outputs=True), spec.solver, "dopri5", 0.2)  # energy.c
            w.run(model, spec.solver, "rk4", 0.05)
            w.run(model, spec.solver, "dop853", 0.2)  # integrate_rk.c's dop853 with its dense stages
            w.run(model, spec.solver, "radau", 0.2)  # integrate_radau.c, lu.c
    # quaternions and the spatial axis joints, with friction
    for name in ("door_h1_wo_hinge2", "carriage_guide_wo_rod", "loop_A1_wo_A2"):
        spec = spec_of(MECH / "examples" / f"{name}.toml")
        model = compile_checked(spec)
        w.model(model, spec.solver)
        random_states(w, model, 6, seed=3)
        w.run(model, spec.solver, "dopri5", 0.2)
        if name == "door_h1_wo_hinge2":
            w.run(model, spec.solver, "radau", 0.2)
    # inputs (core/inputs.c: a joint torque at its start value) and drivers (core/drivers.c: a rotation,
    # constant speed; a planar displacement, a quintic ramp; a spatial displacement, harmonic)
    spec = spec_of(MECH / "examples" / "motor_door.toml")
    spec = dataclasses.replace(spec, inputs=tuple(dataclasses.replace(u, start=5.0) for u in spec.inputs))
    for spec in (spec, spec_of(MECH / "examples" / "driven_door.toml")):
        model = compile_checked(spec)
        w.model(model, spec.solver)
        random_states(w, model, 4, seed=3)
        w.run(dataclasses.replace(model, energy_outputs=True), spec.solver, "dopri5", 0.2)
    for path, driver in ((MECH / "planar_none_wo4.toml", ("joint1", "ramp", {"from": 0.0, "to": 0.3, "t0": 0.0,
                                                                               "t1": 0.5})),
                         (MECH / "examples" / "carriage_none_wo_rod.toml",
                          ("guide", "harmonic", {"amplitude": 0.5 / (2 * np.pi), "frequency": 1.0, "phase": 0.0,
                                                 "offset": 0.0}))):
        spec = spec_of(path)
        spec = dataclasses.replace(spec, drivers=(DriverSpec("d", driver[0], driver[1], driver[2], "displacement"),))
        model = compile_checked(spec)
        w.model(model, spec.solver)
        random_states(w, model, 4, seed=3)
        w.run(model, spec.solver, "dopri5", 0.2)
    # redundancy "min-norm" (kkt_minnorm.c) and "compliant" (compliance.c: scalar and per-axis
    # values, friction on compliant joints), evaluations and runs
    for path, redundancy in ((MECH / "planar_f1_wo4.toml", "min-norm"), (MECH / "examples" / "door_h1_wo_hinge2.toml",
                                                                         "min-norm"),
                             (MECH / "examples" / "compliant_door_h1_wo_hinge2.toml", None),
                             (MECH / "examples" / "compliant_fourbar_A_wo3_4_5.toml", None),
                             (MECH / "examples" / "compliant_planar_f1_wo4.toml", None)):
        spec = spec_of(path)
        if redundancy:
            spec = dataclasses.replace(spec, redundancy=redundancy, eliminate=())
        model = compile_checked(spec)
        w.model(model, spec.solver)
        random_states(w, model, 4, seed=5)
        w.run(model, dataclasses.replace(spec.solver, method="dopri5"), "dopri5", 0.02)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from test_kernel import random_axis_model

    spec, model = random_axis_model(tmp, "euler_zxz", 1)
    w.model(model, spec.solver)
    random_states(w, model, 6, seed=3)
    # Newton and damped Newton give up, the robust path finishes (mu = 3, fast velocities)
    spec = spec_of(MECH / "spatial_MN_wo5.toml")
    spec = dataclasses.replace(spec, friction_params={n: dataclasses.replace(v, mu=3.0)
                                                      for n, v in spec.friction_params.items()})
    model = compile_checked(spec)
    w.model(model, spec.solver)
    rng = np.random.default_rng(1)
    for _ in range(12):
        w.evaluation(np.concatenate([model.q0 + 0.05 * rng.standard_normal(model.n),
                                     model.h0 + 3.0 * rng.standard_normal(model.nh)]))
    # radau's Newton iterations fail (one force evaluation per friction solve): the step collapses
    solver = dataclasses.replace(spec.solver, friction_max_iter=1, tolerance=1e-6)
    w.model(model, solver)
    if w.run(model, solver, "radau", 0.2) != 8:
        raise SystemExit("make_cases: radau's step did not collapse on the failing friction solve")
    # the friction solve gives up: two force evaluations are not enough for either Newton
    spec = spec_of(MECH / "planar_f45_wo4.toml", friction_max_iter=2)
    model = compile_checked(spec)
    w.model(model, spec.solver)
    random_states(w, model, 3, seed=1)
    # a non-finite state, an Euler singularity (beta of the first body 1e-4 rad)
    spec = spec_of(MECH / "spatial_MN_wo5.toml")
    model = compile_checked(spec)
    w.model(model, spec.solver)
    y = np.concatenate([model.q0, model.h0])
    bad, flat = y.copy(), y.copy()
    bad[0] = np.nan
    flat[4] = 1e-4
    w.evaluation(bad)
    w.evaluation(flat)
    # a spring of free length 0.5 m whose points coincide (slider2 at its base point)
    (tmp / "planar_sliders.toml").write_text(
        (MECH / "planar_sliders.toml").read_text().replace("free_length = 3.0", "free_length = 0.5"))
    (tmp / "s.toml").write_text((MECH / "planar_f45_wo4.toml").read_text())
    spec = scene_mod.as_scene(scene_mod.load(tmp / "s.toml"))
    model = compile_checked(spec, check_initial=False)
    w.model(model, spec.solver)
    ld = next(ld for ld in model.loads if ld.type == "spring")
    q = model.q0.copy()
    q[3 * ld.bi: 3 * ld.bi + 2] = 0.0
    w.evaluation(np.concatenate([q, model.h0]))
    # a singular position
    spec = scene_mod.as_scene(scene_mod.load(TWO_PINS))
    model = compile_checked(spec, check_initial=False)
    w.model(model, spec.solver)
    w.evaluation(np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    w.evaluation(np.array([0.0, 0.0, 0.3, 0.0, 0.0, 0.0]))
    return w


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        w = build(Path(tmp))
    st = w.counts["statuses"]
    missing = [s for s in (0, 1, 2, 3, 4, 5) if not st.get(s)]  # every status but out of memory
    if (missing or not w.counts["damped_ok"] or not w.counts.get("runs") or not w.counts.get("robust_ok")
            or not w.counts.get("projections")
            or not w.counts.get("robust_failed")):
        print(f"make_cases: the cases lack statuses {missing} or a damped Newton that finished "
              f"({w.counts['damped_ok']}): {w.counts}", file=sys.stderr)
        return 1
    w.write(args.out)
    print(f"make_cases: {w.counts['models']} models, {w.counts['evaluations']} evaluations, statuses "
          f"{dict(sorted(st.items()))}, damped Newton finished {w.counts['damped_ok']} times, robust path finished {w.counts.get('robust_ok', 0)} and "
          f"gave up {w.counts.get('robust_failed', 0)} times, {w.counts.get('runs', 0)} runs -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
