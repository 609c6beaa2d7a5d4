"""overcon against peer multibody codes at matched accuracy: the frictionless door and the N-four-bar.

    pip install -e ".[bench]"          # MuJoCo, Exudyn, OpenSim (optional: a missing peer is skipped)
    python benchmarks/peers.py [--rounds 3] [--nfourbar-rounds 1] [--cases door,nfourbar] [--n 2 10]
                               [--plot docs/peers.png]

Two cases, each run by every code over a sweep of its accuracy setting (overcon: the tolerance;
MuJoCo, Exudyn: the time step; OpenSim: its integrator accuracy), interleaved: every round runs
every (code, setting) once, and a setting's time is its best round, so that a busy machine's
slower rounds do not count. Times are wall times in this process of building the model plus
integrating it with its outputs (overcon: compile, pre-check and run; MuJoCo: parse the MJCF and
step; Exudyn: build and SolveDynamic; OpenSim: build, initSystem and integrate), and the run alone.

- **door**: the frictionless door of mechanisms/examples/door_none_wo_hinge2.toml (one 20 kg plate,
  two coaxial revolute hinges on a line tilted 0.1 rad, 1 rad/s about it, gravity), 2 s, the
  centre of mass every 1 ms. Error: the largest distance of the centre of mass from the exact
  motion (the rotation about the hinge line, one coordinate, integrated by SciPy's DOP853 at
  1e-13). overcon runs both hinges (10 equations, 5 redundant: the scene eliminates hinge2);
  MuJoCo one hinge (its joint) and a free body held by two ball connections on the hinge line
  (its soft loop closures, ``mujoco free+2 connect``); Exudyn both hinges (its revolute joints,
  ``ignoreSingularJacobian``); OpenSim one pin joint.
- **nfourbar**: the N-four-bar (benchmark A02; benchmarks/nfourbar.py: the scene generator, the
  exact branch), 20 s, B0's x every 10 ms. Error: the largest difference of B0's x from the exact
  branch. overcon with ``[solver] singular = "pass"``; MuJoCo as a tree of hinges (crank0,
  coupler0, crank1, ...) closed by N ball connections of the other cranks to the ground; Exudyn
  with planar bodies and its 2D revolute joints, generalized-alpha at spectral radius 0.9; OpenSim
  as a tree of pin joints closed by N point constraints of the cranks' feet. A run
  whose error exceeds 0.1 m has left the branch (at a flat position): reported as ``wrong
  branch``, never as a time; a run that raises is ``failed`` with its message.

For each target accuracy the table gives, per code, the cheapest setting whose error is at most
the target, and the ratio overcon / best peer. ``--plot`` draws time against error for every code
and setting (log-log), one panel per case. The figures in docs/benchmarks.md ("Peers") come from
this script; peer runs are never part of the test suite.
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from overcon import scene as scene_mod  # noqa: E402
from overcon.checks import compile_checked  # noqa: E402
from overcon.cli import single_threaded_blas  # noqa: E402
from overcon.simulate import run  # noqa: E402

WRONG_BRANCH = 0.1  # m: an N-four-bar run this far from the exact branch took another branch

# ------------------------------------------------------------------------------- the door
DOOR_SCENE = ROOT / "mechanisms" / "examples" / "door_none_wo_hinge2.toml"
MASS, WIDTH, THICK, HEIGHT = 20.0, 0.8, 0.04, 2.0
AXIS = np.array([math.sin(0.1), 0.0, math.cos(0.1)])
COM0 = np.array([0.5, 0.0, 1.0])
INERTIA = np.array([MASS / 12 * (HEIGHT ** 2 + THICK ** 2), MASS / 12 * (WIDTH ** 2 + HEIGHT ** 2),
                    MASS / 12 * (WIDTH ** 2 + THICK ** 2)])
P1, P2 = AXIS / AXIS[2] * 0.2, AXIS / AXIS[2] * 1.8  # the hinges on the line through the origin
GRAVITY = np.array([0.0, 0.0, -9.81])
DOOR_STOP, DOOR_DT = 2.0, 1e-3


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * k @ k


def door_reference(times: np.ndarray) -> np.ndarray:
    """The door's centre of mass at ``times``: the rotation theta about the hinge line,
    I theta'' = a . (r(theta) x m g), I = a^T J a + m |a x r0|^2, theta(0) = 0, theta'(0) = 1 rad/s."""
    r0 = COM0 - P1
    inertia = float(AXIS @ (INERTIA * AXIS)) + MASS * float(np.cross(AXIS, r0) @ np.cross(AXIS, r0))

    def rhs(_t, y):
        r = _rotation(AXIS, y[0]) @ r0
        return [y[1], float(AXIS @ np.cross(r, MASS * GRAVITY)) / inertia]

    sol = solve_ivp(rhs, (0.0, float(times[-1])), [0.0, 1.0], t_eval=times, rtol=1e-13, atol=1e-13, method="DOP853")
    return np.array([P1 + _rotation(AXIS, th) @ r0 for th in sol.y[0]])


def overcon_door(tolerance: float, method: str = "dop853"):
    """(build s, run s, centre of mass (rows, 3)) of overcon in process."""
    start = time.perf_counter()
    spec = scene_mod.load(DOOR_SCENE)
    spec = dataclasses.replace(spec, positions=("door.x", "door.y", "door.z"), reactions=(), friction_outputs=(),
                               solver=dataclasses.replace(spec.solver, method=method, tolerance=tolerance,
                                                          output_interval=DOOR_DT))
    model = compile_checked(spec)
    built = time.perf_counter()
    res = run(model, spec.solver)
    return built - start, time.perf_counter() - built, res.values


def _mujoco_steps(mujoco, model, data, stop: float, dt_out: float, read) -> np.ndarray:
    every = int(round(dt_out / model.opt.timestep))
    mujoco.mj_forward(model, data)  # the positions at t = 0
    rows = [read(data)]
    for _ in range(int(round(stop / dt_out))):
        for _ in range(every):
            mujoco.mj_step(model, data)
        rows.append(read(data))
    return np.array(rows)


def mujoco_door(step: float, integrator: str, free: bool = False):
    """MuJoCo's door: one hinge, or (``free``) a free body held by two ball connections on the
    hinge line (its soft equality constraints)."""
    import mujoco
    start = time.perf_counter()
    ixx, iyy, izz = (float(v) for v in INERTIA)
    if free:
        joint, eq = "<freejoint/>", "".join(
            f'<connect body1="door" body2="world" anchor="{" ".join(repr(float(v)) for v in p - COM0)}"/>' for p in (P1, P2))
        eq = f"<equality>{eq}</equality>"
    else:
        pos = " ".join(repr(float(v)) for v in P1 - COM0)
        joint, eq = f'<joint name="h" type="hinge" pos="{pos}" axis="{" ".join(repr(float(v)) for v in AXIS)}"/>', ""
    xml = f"""<mujoco><option timestep="{step!r}" integrator="{integrator}" gravity="0 0 -9.81"/>
      <worldbody><body name="door" pos="{' '.join(repr(float(v)) for v in COM0)}">
        <inertial pos="0 0 0" mass="{MASS!r}" diaginertia="{ixx!r} {iyy!r} {izz!r}"/>{joint}
      </body></worldbody>{eq}</mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    if free:
        data.qvel[:3] = np.cross(AXIS, COM0 - P1)
        data.qvel[3:6] = AXIS  # body frame = world frame at t = 0
    else:
        data.qvel[0] = 1.0
    built = time.perf_counter()
    xyz = _mujoco_steps(mujoco, model, data, DOOR_STOP, DOOR_DT, lambda d: d.xipos[1].copy())
    return built - start, time.perf_counter() - built, xyz


def _exudyn_settings(exu, stop: float, step: float, rho: float, sensor_period: float):
    """Exudyn's settings shared by both cases: generalized-alpha at the fixed step ``step`` (s) to
    ``stop`` (s) with spectral radius ``rho``, singular Jacobians accepted (redundant joints), no
    files or printing, the sensors stored every ``sensor_period`` (s)."""
    ss = exu.SimulationSettings()
    ss.timeIntegration.numberOfSteps = int(round(stop / step))
    ss.timeIntegration.endTime = stop
    ss.timeIntegration.verboseMode = 0
    ss.timeIntegration.generalizedAlpha.spectralRadius = rho
    ss.solution.file.write = False
    ss.show.statistics = False
    ss.show.computationTime = False
    ss.linearSolver.ignoreSingularJacobian = True
    ss.solution.sensors.writePeriod = sensor_period
    return ss


def exudyn_door(step: float):
    """Exudyn's door: both hinges (its revolute joints), generalized-alpha without numerical damping
    at the fixed step ``step``."""
    import exudyn as exu
    from exudyn.utilities import RigidBodyInertia, SensorBody
    start = time.perf_counter()
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.CreateGround()
    door = mbs.CreateRigidBody(inertia=RigidBodyInertia(mass=MASS, inertiaTensor=np.diag(INERTIA)),
                               referencePosition=COM0, initialVelocity=np.cross(AXIS, COM0 - P1),
                               initialAngularVelocity=AXIS, gravity=list(GRAVITY),
                               nodeType=exu.NodeType.RotationEulerParameters)
    for p in (P1, P2):
        mbs.CreateRevoluteJoint(itemNumbers=[ground, door], position=p, axis=AXIS, useGlobalFrame=True)
    sensor = mbs.AddSensor(SensorBody(bodyNumber=door, storeInternal=True,
                                      outputVariableType=exu.OutputVariableType.Position))
    mbs.Assemble()
    ss = _exudyn_settings(exu, DOOR_STOP, step, 1.0, DOOR_DT)
    ss.timeIntegration.newton.relativeTolerance = 1e-12
    ss.timeIntegration.newton.absoluteTolerance = 1e-12
    ss.linearSolver.solverType = exu.LinearSolverType.EigenDense
    built = time.perf_counter()
    exu.SolveDynamic(mbs, ss)
    data = mbs.GetSensorStoredData(sensor)
    return built - start, time.perf_counter() - built, data[:, 1:4]


def opensim_door(accuracy: float):
    """OpenSim's door: one pin joint on the hinge line (its frames turned 0.1 rad about y, so
    that their z is the line), the default integrator at ``accuracy``."""
    import opensim as osim
    osim.Logger.setLevelString("Off")  # its manager's report at every integrate() call
    osim.Logger.removeFileSink()  # no opensim.log in the working directory
    start = time.perf_counter()
    model = osim.Model()
    model.setGravity(osim.Vec3(*GRAVITY))
    body = osim.Body("door", MASS, osim.Vec3(0.0), osim.Inertia(*INERTIA))
    model.addBody(body)
    turn = osim.Vec3(0.0, 0.1, 0.0)
    joint = osim.PinJoint("hinge", model.getGround(), osim.Vec3(*P1), turn, body, osim.Vec3(*(P1 - COM0)), turn)
    model.addJoint(joint)
    state = model.initSystem()
    joint.getCoordinate().setSpeedValue(state, 1.0)
    manager = osim.Manager(model)
    manager.setIntegratorAccuracy(accuracy)
    state.setTime(0.0)
    manager.initialize(state)
    built = time.perf_counter()
    rows = []
    for k in range(int(round(DOOR_STOP / DOOR_DT)) + 1):
        state = manager.integrate(k * DOOR_DT) if k else state
        model.realizePosition(state)
        p = body.getPositionInGround(state)
        rows.append([p.get(0), p.get(1), p.get(2)])
    return built - start, time.perf_counter() - built, np.array(rows)


def door_runs() -> list[tuple[str, str, object]]:
    """(code, setting label, run) of the door's sweep; a run returns (build s, run s, xyz)."""
    runs = [("overcon dop853", f"tol {tol:g}", lambda tol=tol: overcon_door(tol)) for tol in (1e-3, 1e-5, 1e-7, 1e-9)]
    runs += [("overcon dopri5", f"tol {tol:g}", lambda tol=tol: overcon_door(tol, "dopri5")) for tol in (1e-5, 1e-7, 1e-9)]
    runs += [("mujoco RK4", f"dt {dt:g}", lambda dt=dt: mujoco_door(dt, "RK4")) for dt in (1e-3, 5e-4, 2.5e-4)]
    runs += [("mujoco implicitfast", f"dt {dt:g}", lambda dt=dt: mujoco_door(dt, "implicitfast"))
             for dt in (1e-3, 2.5e-4, 1e-4)]
    runs += [("mujoco free+2 connect", f"dt {dt:g}", lambda dt=dt: mujoco_door(dt, "implicitfast", True))
             for dt in (1e-3, 2.5e-4, 1e-4)]
    runs += [("exudyn", f"dt {dt:g}", lambda dt=dt: exudyn_door(dt)) for dt in (1e-3, 5e-4, 2.5e-4)]
    runs += [("opensim", f"acc {acc:g}", lambda acc=acc: opensim_door(acc)) for acc in (1e-5, 1e-7, 1e-9)]
    return runs


def door_error(xyz: np.ndarray, ref: np.ndarray) -> float:
    if xyz.shape != ref.shape:
        raise ValueError(f"{xyz.shape[0]} rows for the grid's {ref.shape[0]}")
    return float(np.max(np.linalg.norm(xyz - ref, axis=1)))


# ------------------------------------------------------------------------------ the N-four-bar
NFB_STOP, NFB_DT = 20.0, 0.01


def _nfourbar_module():
    spec = importlib.util.spec_from_file_location("nfourbar_bench", ROOT / "benchmarks" / "nfourbar.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def overcon_nfourbar(n: int, tolerance: float, tmp: Path, method: str = "dop853"):
    """(build s, run s, B0's x) of overcon in process, ``singular = "pass"``."""
    mod = _nfourbar_module()
    _, path = mod._generator().write(n, tmp / f"n{n}_{tolerance:g}_{method}", stop_time=NFB_STOP, tolerance=tolerance,
                                     singular="pass")
    start = time.perf_counter()
    spec = scene_mod.load(path)
    spec = dataclasses.replace(spec, positions=("crank0.x", "crank0.phi"), reactions=(), friction_outputs=(),
                               solver=dataclasses.replace(spec.solver, method=method, output_interval=NFB_DT))
    model = compile_checked(spec)
    built = time.perf_counter()
    res = run(model, spec.solver)
    x = res.column("crank0.x") + 0.5 * np.cos(res.column("crank0.phi"))
    return built - start, time.perf_counter() - built, x


def mujoco_nfourbar(n: int, step: float, integrator: str, solref: str | None = None):
    """MuJoCo's N-four-bar: a tree of hinges about z (crank0 on the ground, coupler0 on its top,
    crank1 on coupler0's end, ...) closed by a ball connection of each crank i >= 1 to the ground
    point (i, 0) (its soft constraint: MuJoCo's default solref, or ``solref`` for stiffer ones);
    every rod 1 kg, 1/12 kg m^2 about z; B0 a site on crank0's top."""
    import mujoco
    start = time.perf_counter()
    rod = 'mass="1" diaginertia="0.0833333333333333 0.001 0.0833333333333333"'
    hinge = '<joint type="hinge" axis="0 0 1" pos="{}"/>'
    xml = ['<body name="crank0" pos="0 0.5 0">', f'<inertial pos="0 0 0" {rod}/>', hinge.format("0 -0.5 0"),
           '<site name="B0" pos="0 0.5 0"/>']
    close = 1
    for i in range(n):
        xml += [f'<body name="coupler{i}" pos="0.5 0.5 0">', f'<inertial pos="0 0 0" {rod}/>', hinge.format("-0.5 0 0"),
                f'<body name="crank{i + 1}" pos="0.5 -0.5 0">', f'<inertial pos="0 0 0" {rod}/>', hinge.format("0 0.5 0")]
        close += 2
    xml += ["</body>"] * close
    ref = f' solref="{solref}"' if solref else ""
    eq = "".join(f'<connect body1="crank{i}" body2="world" anchor="0 -0.5 0"{ref}/>' for i in range(1, n + 1))
    text = (f'<mujoco><option timestep="{step!r}" integrator="{integrator}" gravity="0 -9.81 0"/>'
            f'<worldbody>{"".join(xml)}</worldbody><equality>{eq}</equality></mujoco>')
    model = mujoco.MjModel.from_xml_string(text)
    data = mujoco.MjData(model)
    data.qvel[:] = [-1.0 if k % 2 == 0 else 1.0 for k in range(model.nv)]  # cranks -1 rad/s, couplers still
    built = time.perf_counter()
    x = _mujoco_steps(mujoco, model, data, NFB_STOP, NFB_DT, lambda d: float(d.site_xpos[0][0]))
    return built - start, time.perf_counter() - built, x


def exudyn_nfourbar(n: int, step: float, rho: float = 0.9):
    """Exudyn's N-four-bar: planar rigid bodies (NodeRigidBody2D) and its 2D revolute joints,
    generalized-alpha with spectral radius ``rho`` (some numerical damping: without it its Newton
    stops at the flat positions) at the fixed step ``step``; B0 a sensor on crank0's top."""
    import exudyn as exu
    from exudyn.utilities import (LoadMassProportional, MarkerBodyMass, MarkerBodyPosition, NodeRigidBody2D,
                                  ObjectGround, ObjectJointRevolute2D, ObjectRigidBody2D, SensorBody)
    start = time.perf_counter()
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.AddObject(ObjectGround())

    def rod(x, y, phi, v):
        node = mbs.AddNode(NodeRigidBody2D(referenceCoordinates=[x, y, phi], initialVelocities=v))
        body = mbs.AddObject(ObjectRigidBody2D(mass=1.0, inertia=1.0 / 12.0, nodeNumber=node))
        mbs.AddLoad(LoadMassProportional(markerNumber=mbs.AddMarker(MarkerBodyMass(bodyNumber=body)),
                                         loadVector=[0.0, -9.81, 0.0]))
        return body

    def pin(a, pa, b, pb):
        ma = mbs.AddMarker(MarkerBodyPosition(bodyNumber=a, localPosition=[pa[0], pa[1], 0.0]))
        mb = mbs.AddMarker(MarkerBodyPosition(bodyNumber=b, localPosition=[pb[0], pb[1], 0.0]))
        mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[ma, mb]))

    cranks = [rod(i, 0.5, math.pi / 2, [0.5, 0.0, -1.0]) for i in range(n + 1)]
    couplers = [rod(i + 0.5, 1.0, 0.0, [1.0, 0.0, 0.0]) for i in range(n)]
    for i, c in enumerate(cranks):
        pin(c, (-0.5, 0.0), ground, (float(i), 0.0))
    for i, c in enumerate(couplers):
        pin(cranks[i], (0.5, 0.0), c, (-0.5, 0.0))
        pin(c, (0.5, 0.0), cranks[i + 1], (0.5, 0.0))
    sensor = mbs.AddSensor(SensorBody(bodyNumber=cranks[0], localPosition=[0.5, 0.0, 0.0], storeInternal=True,
                                      outputVariableType=exu.OutputVariableType.Position))
    mbs.Assemble()
    ss = _exudyn_settings(exu, NFB_STOP, step, rho, NFB_DT)
    ss.timeIntegration.adaptiveStep = False
    built = time.perf_counter()
    ok = exu.SolveDynamic(mbs, ss)
    if not ok:
        raise RuntimeError("SolveDynamic did not converge")
    data = mbs.GetSensorStoredData(sensor)
    return built - start, time.perf_counter() - built, data[:, 1]


def opensim_nfourbar(n: int, accuracy: float):
    """OpenSim's N-four-bar: a tree of pin joints (about z; crank0 on the ground, coupler0 on its top,
    crank1 on coupler0's end, ...) closed by a point constraint of each crank i >= 1's foot to the
    ground point (i, 0); rods along their body x, 1 kg, 1/12 kg m^2 about z; the default integrator
    at ``accuracy``."""
    import opensim as osim
    osim.Logger.setLevelString("Off")
    osim.Logger.removeFileSink()
    start = time.perf_counter()
    model = osim.Model()
    model.setGravity(osim.Vec3(0.0, -9.81, 0.0))
    joints, parent, at = [], model.getGround(), osim.Vec3(0.0)
    cranks = []
    for k in range(2 * n + 1):  # crank0, coupler0, crank1, ...: each hinged to the one before
        crank = k % 2 == 0
        body = osim.Body(f"{'crank' if crank else 'coupler'}{k // 2}", 1.0, osim.Vec3(0.0),
                         osim.Inertia(1e-3, 1.0 / 12.0, 1.0 / 12.0))
        model.addBody(body)
        # a crank hangs from its foot (the ground) or its top (a coupler's end); a coupler from its left end
        child = osim.Vec3(-0.5 if (crank and k == 0) or not crank else 0.5, 0.0, 0.0)
        joint = osim.PinJoint(f"J{k}", parent, at, osim.Vec3(0.0), body, child, osim.Vec3(0.0))
        model.addJoint(joint)
        joints.append(joint)
        if crank:
            cranks.append(body)
        parent, at = body, osim.Vec3(0.5, 0.0, 0.0)
    for i, crank in enumerate(cranks[1:], start=1):
        model.addConstraint(osim.PointConstraint(model.getGround(), osim.Vec3(float(i), 0.0, 0.0), crank,
                                                 osim.Vec3(-0.5, 0.0, 0.0)))
    for k, joint in enumerate(joints):  # absolute angles: cranks pi/2, couplers 0; cranks at -1 rad/s
        c = joint.upd_coordinates(0)
        c.setDefaultValue(math.pi / 2 if k == 0 else (-math.pi / 2 if k % 2 else math.pi / 2))
        c.setDefaultSpeedValue(-1.0 if k % 2 == 0 else 1.0)
    state = model.initSystem()
    manager = osim.Manager(model)
    manager.setIntegratorAccuracy(accuracy)
    state.setTime(0.0)
    manager.initialize(state)
    built = time.perf_counter()
    top, x = osim.Vec3(0.5, 0.0, 0.0), []
    for k in range(int(round(NFB_STOP / NFB_DT)) + 1):
        state = manager.integrate(k * NFB_DT) if k else state
        model.realizePosition(state)
        x.append(cranks[0].findStationLocationInGround(state, top).get(0))
    return built - start, time.perf_counter() - built, np.array(x)


def nfourbar_runs(n: int, tmp: Path, stiff: bool = False) -> list[tuple[str, str, object]]:
    runs = [("overcon dop853", f"tol {tol:g}", lambda tol=tol: overcon_nfourbar(n, tol, tmp))
            for tol in (1e-3, 1e-5, 1e-7, 1e-9)]
    runs += [("mujoco RK4", f"dt {dt:g}", lambda dt=dt: mujoco_nfourbar(n, dt, "RK4")) for dt in (1e-3, 1e-4)]
    runs += [("mujoco implicitfast", f"dt {dt:g}", lambda dt=dt: mujoco_nfourbar(n, dt, "implicitfast"))
             for dt in (1e-3, 1e-4)]
    runs += [("exudyn rho 0.9", f"dt {dt:g}", lambda dt=dt: exudyn_nfourbar(n, dt)) for dt in (1e-3, 5e-4)]
    runs += [("opensim", f"acc {acc:g}", lambda acc=acc: opensim_nfourbar(n, acc)) for acc in (1e-3, 1e-5, 1e-7)]
    if stiff:  # MuJoCo's closures 40 times stiffer than its default (solref 0.02): a minute a run
        runs += [("mujoco RK4 solref 0.0005", "dt 5e-05", lambda: mujoco_nfourbar(n, 5e-5, "RK4", "0.0005 1"))]
    return runs


# ------------------------------------------------------------------------------ sweep and table
@dataclasses.dataclass
class Outcome:
    code: str
    setting: str
    build: float = math.inf  # s, best round
    run: float = math.inf    # s, best round (integration and outputs)
    error: float | None = None
    failure: str | None = None

    @property
    def total(self) -> float:
        return self.build + self.run


def _short(text: str, size: int = 150) -> str:
    """A peer's message on one line, its start and its end when it is long (the cause is often last)."""
    text = " ".join(line.strip() for line in text.splitlines() if line.strip()).replace("|", "/")
    return text if len(text) <= size else f"{text[:60]} ... {text[-(size - 65):]}"


def sweep(runs, reference: np.ndarray, error, rounds: int, branch: float | None = None) -> list[Outcome]:
    """Every run once per round, interleaved; a run's times are its best round's."""
    out = [Outcome(code, setting) for code, setting, _ in runs]
    for _ in range(rounds):
        for o, (_, _, fn) in zip(out, runs):
            if o.failure:
                continue
            try:
                build, wall, values = fn()
                err = error(np.asarray(values), reference)
            except ImportError as exc:
                o.failure = f"not installed ({exc.name})"
                continue
            except Exception as exc:  # a peer's own failure (no convergence, a refused model): reported as such
                o.failure = f"failed: {type(exc).__name__}: {_short(str(exc))}"
                continue
            if not math.isfinite(err):
                o.failure = "failed: non-finite result"
                continue
            if branch is not None and err > branch:
                o.failure = f"off the branch (error {err:.2g} m > {branch:g} m)"
                continue
            o.error = err
            if build + wall < o.total:
                o.build, o.run = build, wall
    return out


def table(title: str, outcomes: list[Outcome], targets: tuple[float, ...]) -> list[str]:
    lines = [f"### {title}", "", "| code | setting | error (m) | build + run (s) | run (s) |", "|---|---|---:|---:|---:|"]
    for o in outcomes:
        if o.failure:
            lines.append(f"| {o.code} | {o.setting} | {o.failure} | | |")
        else:
            lines.append(f"| {o.code} | {o.setting} | {o.error:.2g} | {o.total:.4f} | {o.run:.4f} |")
    lines += ["", "| target error (m) | overcon (s) | best peer (s) | peer | overcon / best peer |", "|---:|---:|---:|---|---:|"]
    for target in targets:
        ok = [o for o in outcomes if o.failure is None and o.error <= target]
        ours = min((o for o in ok if o.code.startswith("overcon")), key=lambda o: o.total, default=None)
        peer = min((o for o in ok if not o.code.startswith("overcon")), key=lambda o: o.total, default=None)
        cell = lambda o: f"{o.total:.4f}" if o else "none reaches it"  # noqa: E731
        ratio = f"{ours.total / peer.total:.2f}" if ours and peer else "-"
        lines.append(f"| {target:g} | {cell(ours)} | {cell(peer)} | {f'{peer.code} {peer.setting}' if peer else '-'} | {ratio} |")
    return lines + [""]


def plot(panels: list[tuple[str, list[Outcome]]], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(panels), figsize=(5.5 * len(panels), 4.2), squeeze=False)
    for ax, (title, outcomes) in zip(axes[0], panels):
        codes = sorted({o.code for o in outcomes})
        for code in codes:
            pts = sorted((o.error, o.total) for o in outcomes if o.code == code and o.failure is None)
            if pts:
                ax.loglog(*zip(*pts), "o-" if code.startswith("overcon") else "s--", label=code)
            bad = [o for o in outcomes if o.code == code and o.failure]
            if bad:
                ax.plot([], [], " ", label=f"{code}: {len(bad)} run(s) failed / wrong branch")
        ax.set_xlabel("error (m)")
        ax.set_ylabel("build + run wall time (s)")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3, help="rounds of the door (default 3)")
    ap.add_argument("--nfourbar-rounds", type=int, default=1, help="rounds of the N-four-bar (default 1: its peers "
                    "take seconds to minutes a run)")
    ap.add_argument("--cases", default="door,nfourbar")
    ap.add_argument("--n", type=int, nargs="+", default=[2, 10])
    ap.add_argument("--plot", help="write the speed/accuracy plot (PNG) here")
    ap.add_argument("--mujoco-stiff", action="store_true",
                    help="also MuJoCo's N-four-bar with closures of solref 0.0005 at dt 5e-5 (a minute a run)")
    args = ap.parse_args(argv)
    cases = set(args.cases.split(","))
    panels = []
    with single_threaded_blas(), tempfile.TemporaryDirectory() as tmp:
        if "door" in cases:
            grid = np.round(np.arange(int(round(DOOR_STOP / DOOR_DT)) + 1) * DOOR_DT, 12)
            out = sweep(door_runs(), door_reference(grid), door_error, args.rounds)
            print("\n".join(table(f"door, {DOOR_STOP:g} s, output every {DOOR_DT * 1e3:g} ms", out, (1e-5, 1e-7, 1e-9))),
                  flush=True)
            panels.append(("door (2 s, 1 ms output)", out))
        for n in args.n if "nfourbar" in cases else ():
            times = np.round(np.arange(int(round(NFB_STOP / NFB_DT)) + 1) * NFB_DT, 10)
            ref = _nfourbar_module().reference_x(n, times)
            out = sweep(nfourbar_runs(n, Path(tmp), args.mujoco_stiff), ref, lambda x, r: float(np.max(np.abs(np.asarray(x).reshape(-1) - r))),
                        args.nfourbar_rounds, branch=WRONG_BRANCH)
            print("\n".join(table(f"N-four-bar N = {n}, {NFB_STOP:g} s", out, (1e-3, 1e-5))), flush=True)
            panels.append((f"N-four-bar N = {n} (20 s)", out))
    if args.plot and panels:
        plot(panels, Path(args.plot))
        print(f"plot: {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
