"""Writes the N-four-bar mechanism and its scene: problem A02 of the multibody benchmark library
(González, Dopico, Lugrís, Cuadrado, Multibody System Dynamics 16 (2006)).

    python mechanisms/examples/nfourbar.py N [--out DIR] [--stop-time T] [--tolerance TOL] [--singular pass]

writes ``nfourbar_N.toml`` (the mechanism) and ``nfourbar_N_scene.toml`` (its scene) into DIR
(default: this folder).

The mechanism (planar, SI units): N + 1 cranks of 1 m standing on the ground points (i, 0),
i = 0..N, and N couplers of 1 m joining the cranks' tops (i, 1) -> (i + 1, 1); every link is a
uniform rod of 1 kg (J = 1/12 kg m^2 about its centre). The bodies are listed along the chain
(crank0, coupler0, crank1, ...), so that every joint couples neighbours and the matrices of the
dynamics are banded (core/kkt_al.c factors them in O(N)). Revolute joints: G<i> crank<i>-ground,
L<i> crank<i>-coupler<i> and R<i> coupler<i>-crank<i+1>. Gravity 9.81 m/s^2 along -y. At t = 0 the
cranks are upright and every coupler moves at 1 m/s along +x (cranks at -1 rad/s).

3(2N + 1) coordinates, 2(3N + 1) equations, independent away from the flat positions (1 DOF, no
redundant equation). When the linkage lies flat on the ground line (every crank along x) the
Jacobian loses N of its rank and the DOF jumps to N + 1: the singular positions the benchmark is
about; a scene with ``singular = "pass"`` (``--singular pass``; the examples nfourbar_2, _10 and
_40 here) goes through them. The benchmark's measure is the x coordinate of the first crank's top B0,
``crank0.x + 0.5 cos(crank0.phi)``, over 20 s.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROD_INERTIA = 1.0 / 12.0  # kg m^2: a 1 kg rod of 1 m about its centre


def _body(name: str, q0, h0) -> list[str]:
    return ["[[bodies]]", f'name = "{name}"', "mass = 1.0", f"inertia = {ROD_INERTIA!r}",
            f"q0 = [{', '.join(repr(float(v)) for v in q0)}]", f"h0 = [{', '.join(repr(float(v)) for v in h0)}]", ""]


def _revolute(name: str, body_i: str, s_i, body_j: str, s_j) -> list[str]:
    return ["[[joints]]", f'name = "{name}"', 'type = "revolute"', f'body_i = "{body_i}"', f'body_j = "{body_j}"',
            f"s_i = [{float(s_i[0])!r}, {float(s_i[1])!r}]", f"s_j = [{float(s_j[0])!r}, {float(s_j[1])!r}]", ""]


def mechanism_text(n: int) -> str:
    """The mechanism file of the N-four-bar (see the module docstring)."""
    lines = ["[mechanism]", f'name = "nfourbar_{n}"', 'kind = "planar"', "gravity = [0.0, -9.81]",
             f'description = "N-four-bar (benchmark A02), N = {n}: {n + 1} cranks, {n} couplers, 1 m and 1 kg each"',
             ""]
    for i in range(n + 1):  # bodies along the chain: crank i, then coupler i (the matrices are banded in this order)
        # crank i: centre (i, 0.5), along +y; its top moves at +1 m/s along x
        lines += _body(f"crank{i}", (i, 0.5, math.pi / 2), (0.5, 0.0, -1.0))
        if i < n:  # coupler i: centre (i + 0.5, 1), along +x, translating at 1 m/s
            lines += _body(f"coupler{i}", (i + 0.5, 1.0, 0.0), (1.0, 0.0, 0.0))
    for i in range(n + 1):
        lines += _revolute(f"G{i}", f"crank{i}", (-0.5, 0.0), "base", (i, 0.0))
    for i in range(n):
        lines += _revolute(f"L{i}", f"crank{i}", (0.5, 0.0), f"coupler{i}", (-0.5, 0.0))
        lines += _revolute(f"R{i}", f"coupler{i}", (0.5, 0.0), f"crank{i + 1}", (0.5, 0.0))
    return "\n".join(lines)


def scene_text(n: int, stop_time: float, tolerance: float, output_interval: float, singular: str | None = None) -> str:
    """The scene of the N-four-bar: frictionless, no elimination (none is redundant); ``singular``:
    the scene's ``[solver] singular`` (None: not given, the default "stop")."""
    return "\n".join([
        "[scene]", f'name = "nfourbar_{n}_scene"', f'mechanism = "nfourbar_{n}.toml"', f'group = "nfourbar_{n}"',
        f'description = "N-four-bar, N = {n}: frictionless, passes a flat (singular) position about every second"',
        "friction = []", "eliminate = []", "start_time = 0.0", f"stop_time = {stop_time!r}", "",
        "[outputs]", 'positions = ["crank0.x", "crank0.y", "crank0.phi"]', "reactions = []", "",
        "[solver]", f"tolerance = {tolerance!r}", f"output_interval = {output_interval!r}"]
        + ([f'singular = "{singular}"'] if singular else []) + [""])


def write(n: int, out: Path, stop_time: float = 20.0, tolerance: float = 1e-9,
          output_interval: float = 0.01, singular: str | None = None) -> tuple[Path, Path]:
    """Write ``nfourbar_N.toml`` and ``nfourbar_N_scene.toml`` into ``out``; return both paths."""
    if n < 1:
        raise ValueError(f"N = {n}: the N-four-bar needs N >= 1 loops")
    out.mkdir(parents=True, exist_ok=True)
    mech, scene = out / f"nfourbar_{n}.toml", out / f"nfourbar_{n}_scene.toml"
    mech.write_text(mechanism_text(n))
    scene.write_text(scene_text(n, stop_time, tolerance, output_interval, singular))
    return mech, scene


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("n", type=int, help="number of loops N (>= 1)")
    ap.add_argument("--out", type=Path, default=HERE, help="folder to write into (default: this one)")
    ap.add_argument("--stop-time", type=float, default=20.0, help="s (default 20, the benchmark's)")
    ap.add_argument("--tolerance", type=float, default=1e-9)
    ap.add_argument("--output-interval", type=float, default=0.01, help="s")
    ap.add_argument("--singular", choices=("stop", "pass"),
                    help="the scene's [solver] singular (default: not written, so 'stop': the run stops at the "
                         "first flat position; 'pass' goes through them)")
    args = ap.parse_args(argv)
    try:
        for path in write(args.n, args.out, args.stop_time, args.tolerance, args.output_interval, args.singular):
            print(path)
    except ValueError as exc:
        print(f"nfourbar.py: {exc}")
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
