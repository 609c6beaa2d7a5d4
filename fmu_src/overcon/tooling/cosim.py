"""Putting an overcon FMU in a system: the coupling example of ``mechanisms/examples/coupling``
(the door with a motor input and a hinge angle sensor, held at a set angle by a PI controller FMU)
built and run in libcosim, DNV's co-simulation master (``libcosimpy``), from the OSP system
structure file that ships with it; and the plot of its response (docs/coupling.md).

Commands (``python -m overcon.tooling.cosim ...``)::

    example [--out DIR] [--stop T] [--png FILE]
        build both FMUs and the system file into DIR (default: a temporary directory), run the
        system in libcosim to T s (default 5), print the settling figures, write DIR/system.csv
        and, with --png, the plot (docs/coupling_door.png is made by this command).
    run SYSTEM.xml --stop T --csv OUT.csv --record SIM:VAR [--record ...]
        run any OSP system structure in libcosim in this process and write the recorded variables
        at every communication point (t = step, 2 step, ..., T) to OUT.csv.

libcosim runs in a child process (``run``) when called through :func:`run_osp_isolated`: the
controller is a pythonfmu FMU, whose wrapper can corrupt the heap when its library is unloaded
at exit (see :mod:`overcon.tooling.run`); the child writes its CSV and leaves with ``os._exit``.

``libcosimpy`` is an optional dependency (the ``test`` extra); pythonfmu is a dependency.
"""
from __future__ import annotations

import argparse
import csv
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from . import InputError, SimulationFailed

EXAMPLE = Path(__file__).resolve().parents[3] / "mechanisms" / "examples" / "coupling"
"""The example's sources: door_motor.toml (the plant's scene), controller.py (the PI controller for
pythonfmu) and OspSystemStructure.xml (the system: which FMU, which connection, the step)."""
SYSTEM_FILE = "OspSystemStructure.xml"
SETPOINT = 0.5  # rad: the controller's set angle in the system file
RECORD = ("door:hinge1.angle", "door:hinge1.rate", "controller:torque", "door:hinge1.friction")


def build_controller(dest) -> Path:
    """Build the example's PI controller FMU (``DoorController.fmu``) into ``dest`` with
    ``pythonfmu build`` in a child process (it imports the script as a module)."""
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run([sys.executable, "-m", "pythonfmu", "build", "-f", str(EXAMPLE / "controller.py"),
                           "-d", str(dest)], capture_output=True, text=True, timeout=300)
    fmu = dest / "DoorController.fmu"
    if proc.returncode != 0 or not fmu.is_file():
        raise SimulationFailed(f"pythonfmu build of {EXAMPLE / 'controller.py'} failed (exit {proc.returncode}): "
                               f"{(proc.stderr or proc.stdout)[-2000:]}")
    return fmu


def build_door(dest, fmi: int = 2) -> Path:
    """Build the example's door (``coupled_door.fmu``, co-simulation) into ``dest``. Friction in
    hinge1 acts on a reaction that is not unique (the door's coaxial hinges: the paper's point),
    so the build is asked to go ahead (``allow_nonunique``): the FMU runs the elimination the
    scene names (hinge2) and publishes the verdict (``motion_unique`` false)."""
    from ..fmu.build import build_all

    code, results = build_all([EXAMPLE / "door_motor.toml"], dest, refs=False, fmi=fmi, kind="cs", allow_nonunique=True,
                              echo=lambda s: None)
    ok = [r for r in results if r.status == "built"]
    if code != 0 or not ok:
        why = "; ".join(m for r in results for m in r.messages) or f"exit {code}"
        raise SimulationFailed(f"build of {EXAMPLE / 'door_motor.toml'} failed: {why}")
    return Path(ok[0].fmu)


def build_example(dest) -> Path:
    """Both FMUs and the system file in ``dest``; returns the system file's path."""
    dest = Path(dest)
    build_door(dest)
    build_controller(dest)
    shutil.copy2(EXAMPLE / SYSTEM_FILE, dest / SYSTEM_FILE)
    return dest / SYSTEM_FILE


def run_osp(system: str | Path, stop: float, record) -> tuple[np.ndarray, dict]:
    """Run the OSP system structure ``system`` in libcosim (in this process) to ``stop`` s and
    return (times, {"SIM:VAR": values}) of the Real variables ``record`` ("SIM:VAR") after every
    communication step. :class:`InputError` for an unknown simulator or variable,
    :class:`SimulationFailed` for a step libcosim reports failed."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimObserver import CosimObserver

    if not Path(system).is_file():
        raise InputError(f"{system}: no such system structure file")
    try:
        ex = CosimExecution.from_osp_config_file(str(system))
    except AssertionError as exc:  # libcosimpy asserts with libcosim's reason
        raise InputError(f"{system}: libcosim cannot set up the system: {exc}") from exc
    observer = CosimObserver.create_last_value()
    ex.add_observer(observer)
    where = {}
    for key in record:
        sim, _, var = key.partition(":")
        index = ex.slave_index_from_instance_name(sim)
        if index is None or index < 0:
            raise InputError(f"{system}: no simulator {sim!r} (record {key!r})")
        refs = {v.name.decode() if isinstance(v.name, bytes) else v.name: v.reference
                for v in ex.slave_variables(index)}
        if var not in refs:
            raise InputError(f"{system}: simulator {sim!r} has no variable {var!r}")
        where[key] = (index, refs[var])
    step = _base_step(system)
    n = int(round(stop / step))
    times, rows = [], []
    for k in range(n):
        if not ex.step():
            raise SimulationFailed(f"{system}: libcosim step {k} (t = {k * step:g} s) failed")
        times.append((k + 1) * step)
        rows.append([observer.last_real_values(i, [r])[0] for i, r in where.values()])
    data = np.array(rows, dtype=float).reshape(len(rows), len(where))
    return np.array(times), {key: data[:, j] for j, key in enumerate(where)}


def _base_step(system) -> float:
    import xml.etree.ElementTree as ET

    root = ET.parse(str(system)).getroot()
    for el in root.iter():
        if el.tag.endswith("BaseStepSize"):
            return float(el.text)
    raise InputError(f"{system}: no BaseStepSize")


def write_series(path, times, values: dict) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["time", *values])
        for k, t in enumerate(times):
            w.writerow([repr(float(t)), *(repr(float(v[k])) for v in values.values())])


def read_series(path) -> tuple[np.ndarray, dict]:
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    head, data = rows[0], np.array(rows[1:], dtype=float)
    return data[:, 0], {h: data[:, j + 1] for j, h in enumerate(head[1:])}


def run_osp_isolated(system, stop: float, record=RECORD, timeout: float = 600) -> tuple[np.ndarray, dict]:
    """:func:`run_osp` in a child process (module docstring)."""
    with tempfile.TemporaryDirectory(prefix="overcon-cosim-") as tmp:
        out = Path(tmp) / "system.csv"
        cmd = [sys.executable, "-m", "overcon.tooling.cosim", "run", str(system), "--stop", repr(stop),
               "--csv", str(out)] + [a for r in record for a in ("--record", r)]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        if not out.is_file():
            raise SimulationFailed(f"libcosim run of {system} failed (exit {proc.returncode}): "
                                   f"{proc.stderr[-3000:]}")
        return read_series(out)


def settling(times: np.ndarray, angle: np.ndarray, setpoint: float = SETPOINT, band: float = 1e-3) -> float:
    """The first time from which |angle - setpoint| stays within ``band`` (rad); inf if never."""
    outside = np.flatnonzero(np.abs(angle - setpoint) > band)
    if outside.size == 0:
        return float(times[0])
    if outside[-1] == len(times) - 1:
        return float("inf")
    return float(times[outside[-1] + 1])


def plot(times, values: dict, png, title: str = "") -> Path:
    """The response: the hinge angle with the set point, its error on a finer scale with the
    ±1e-3 rad band, and the motor and friction torques on a scale that shows the holding torque
    (the start's peak is clipped and its value written)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    angle, torque = values["door:hinge1.angle"], values["controller:torque"]
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(7.5, 8), sharex=True)
    a1.plot(times, angle, label="hinge1.angle (door FMU)")
    a1.axhline(SETPOINT, color="k", lw=0.8, ls="--", label=f"set point {SETPOINT} rad")
    a1.set_ylabel("angle [rad]")
    a1.legend(loc="lower right")
    a2.plot(times, angle - SETPOINT, label="angle - set point")
    a2.axhspan(-1e-3, 1e-3, color="g", alpha=0.2, label="±1e-3 rad")
    a2.set_ylim(-5e-3, 5e-3)
    a2.set_ylabel("error [rad]")
    a2.legend(loc="lower right")
    a3.plot(times, torque, label="motor torque (controller FMU)")
    if "door:hinge1.friction" in values:
        a3.plot(times, values["door:hinge1.friction"], label="hinge1.friction (door FMU)")
    k = int(np.argmax(np.abs(torque)))
    a3.set_ylim(-15, 15)
    a3.annotate(f"peak {torque[k]:.0f} N·m at t = {times[k]:g} s (clipped)", (0.3, 0.06), xycoords="axes fraction")
    a3.set_xlabel("time [s]")
    a3.set_ylabel("torque [N·m]")
    a3.legend(loc="upper right")
    for a in (a1, a2, a3):
        a.grid(alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return png


def _main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m overcon.tooling.cosim", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("system")
    r.add_argument("--stop", type=float, required=True)
    r.add_argument("--csv", required=True)
    r.add_argument("--record", action="append", required=True)
    e = sub.add_parser("example")
    e.add_argument("--out")
    e.add_argument("--stop", type=float, default=5.0)
    e.add_argument("--png")
    args = p.parse_args(argv)
    if args.cmd == "run":
        code = 0
        try:
            times, values = run_osp(args.system, args.stop, args.record)
            write_series(args.csv, times, values)
        except InputError as exc:
            print(f"overcon.tooling.cosim: {exc}", file=sys.stderr)
            code = 2
        except SimulationFailed as exc:
            print(f"overcon.tooling.cosim: {exc}", file=sys.stderr)
            code = 3
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)  # the pythonfmu library is never unloaded (module docstring)
    if args.out is None:
        with tempfile.TemporaryDirectory(prefix="overcon-coupling-") as tmp:
            return _example(Path(tmp), args.stop, args.png)
    return _example(Path(args.out), args.stop, args.png)


def _example(out: Path, stop: float, png) -> int:
    system = build_example(out)
    times, values = run_osp_isolated(system, stop)
    write_series(out / "system.csv", times, values)
    angle = values["door:hinge1.angle"]
    print(f"system {system}: {len(times)} steps to t = {times[-1]:g} s; angle at the end {float(angle[-1])!r} rad "
          f"(set point {SETPOINT}); within 1e-3 rad from t = {settling(times, angle):g} s; "
          f"torque at the end {values['controller:torque'][-1]:.6g} N·m; CSV {out / 'system.csv'}")
    if png:
        print(f"plot {plot(times, values, png, 'door + PI controller in libcosim (OSP system structure)')}")
    return 0


if __name__ == "__main__":
    sys.exit(_main())
