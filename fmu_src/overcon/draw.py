"""Pictures of a mechanism (``overcon draw``) and of a run (``overcon animate``), with matplotlib.

What is drawn, at the initial configuration q0 or at the coordinates of a run's CSV:

- **bodies** as lines from the centre of mass (a dot, the body's name beside it) to every point a
  joint or a spring attaches to it, so a body's outline is the linkage it forms;
- **joints** by a symbol at body i's joint point, their name beside it: planar revolute and
  spherical ``o``, translational a slider ``s`` with its guide (a dashed line through B, across
  the normal ``v``); spatial revolute ``o``, prismatic ``s``, cylindrical ``D``, universal ``X``,
  fixed ``P``, each with its axis (``axis_i``, both for a universal joint) as a short line; any
  other type (one added later) a ``*`` at its point;
- **ground**: a hatched triangle where a joint or spring holds a body to the base;
- **loads**: forces as arrows at the body origin, springs as zigzags.

Planar: one view (x right, y up). Spatial: three orthographic views (x-y from above, x-z from the
front, y-z from the side) and one isometric view (along -(1, 1, 1)). A joint's fields are placed
by their names (the shapes of :data:`overcon.joints.TYPES`): a point field ending in ``_i`` or
``_A`` is on body i, ``_j`` or ``_B`` on body j; ``axis_i``/``axis_j`` and ``v`` are directions on
body i/j. Decided: the picture is a check of what the file says (where the points and axes are),
not a rendering of shapes, which the files do not have.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import scene as sc
from . import spec as S
from .joints import TYPES
from .kinematics import euler_R, quat_R_rows

SYMBOLS = {"revolute": "o", "spherical": "o", "translational": "s", "spatial_revolute": "o",
           "spatial_prismatic": "s", "spatial_cylindrical": "D", "spatial_universal": "X", "spatial_fixed": "P"}
ISO = np.array([[-1.0, 1.0, 0.0], [-1.0, -1.0, 2.0]]) / np.array([[math.sqrt(2.0)], [math.sqrt(6.0)]])
VIEWS = {"planar": (("x", "y", np.eye(2)),),
         "spatial": (("x", "y", np.array([[1.0, 0, 0], [0, 1.0, 0]])), ("x", "z", np.array([[1.0, 0, 0], [0, 0, 1.0]])),
                     ("y", "z", np.array([[0, 1.0, 0], [0, 0, 1.0]])), ("isometric", "", ISO))}


class DrawError(ValueError):
    """Bad input for a drawing (the message names the file, column or time at fault)."""


@dataclass(frozen=True)
class Pose:
    """Where every body is: name -> (centre of mass r (dim,), rotation R (dim, dim), body -> global)."""

    frames: dict

    def point(self, body: str, local) -> np.ndarray:
        r, R = self.frames[body]
        return r + R @ np.asarray(local, float)

    def direction(self, body: str, local) -> np.ndarray:
        d = self.frames[body][1] @ np.asarray(local, float)
        n = float(np.linalg.norm(d))
        return d / n if n > 0 else d


def pose(mech: S.MechanismSpec, coords: dict[str, tuple]) -> Pose:
    """The :class:`Pose` of body coordinates ``coords`` (name -> q_i in the order of
    :func:`overcon.spec.coordinates`); the base at the origin."""
    dim = 2 if mech.kind == "planar" else 3
    frames = {S.BASE: (np.zeros(dim), np.eye(dim))}
    for b in mech.bodies:
        q = np.asarray(coords[b.name], float)
        if len(q) <= dim:  # a body with a position only (no orientation coordinates): not rotated
            frames[b.name] = (q[:dim], np.eye(dim))
        elif mech.kind == "planar":
            c, s = math.cos(q[2]), math.sin(q[2])
            frames[b.name] = (q[:2], np.array([[c, -s], [s, c]]))
        elif mech.rotation == "quaternion":
            frames[b.name] = (q[:3], quat_R_rows(q[3:7].reshape(1, 4))[0])
        else:
            frames[b.name] = (q[:3], euler_R(q[3:6]))
    return Pose(frames)


def initial_pose(mech: S.MechanismSpec) -> Pose:
    return pose(mech, {b.name: b.q0 for b in mech.bodies})


def _side(field: str) -> str | None:
    """"i" or "j": the body a joint field belongs to, by its name (module docstring)."""
    if field.endswith(("_i", "_A")):
        return "i"
    if field.endswith(("_j", "_B")) or field == "v":
        return "j"
    return None


def joint_geometry(j: S.JointSpec, p: Pose) -> tuple[dict, dict]:
    """(points, directions) of a joint in the global frame: field name -> (body, vector)."""
    jt = TYPES.get(j.type)
    shapes = {}
    if jt is not None:
        shapes = {n: s for n, (s, *_r) in {**jt.required, **jt.optional}.items()}
    points, dirs = {}, {}
    for name, value in j.params.items():
        side = _side(name)
        if value is None or side is None or not isinstance(value, (tuple, list)):
            continue
        body = j.body_i if side == "i" else j.body_j
        if shapes.get(name, "vec") == "dir":
            dirs[name] = (body, p.direction(body, value))
        else:
            points[name] = (body, p.point(body, value))
    return points, dirs


def _attachments(mech: S.MechanismSpec, p: Pose) -> dict[str, list]:
    """Body -> the global points attached to it (joints, springs)."""
    out = {b.name: [] for b in mech.bodies}
    for j in mech.joints:
        for body, x in joint_geometry(j, p)[0].values():
            out.setdefault(body, []).append(x)
    for ld in mech.loads:
        if ld.type == "spring":
            for end in ("i", "j"):
                body, local = ld.params[f"body_{end}"], ld.params.get(f"s_{end}")
                out.setdefault(body, []).append(p.point(body, local if local is not None else
                                                         np.zeros(len(p.frames[S.BASE][0]))))
    return out


def extent(mech: S.MechanismSpec, p: Pose) -> float:
    """A length scale of the picture: the largest distance between any two of its points (>= 0.1)."""
    pts = [r for r, _R in p.frames.values()] + [x for xs in _attachments(mech, p).values() for x in xs]
    pts = np.array(pts)
    return max(0.1, float(np.max(np.ptp(pts, axis=0))))


def _zigzag(a: np.ndarray, b: np.ndarray, width: float) -> np.ndarray:
    d = b - a
    n = np.array([-d[1], d[0]]) / (np.linalg.norm(d) or 1.0)
    t = np.linspace(0.0, 1.0, 14)
    off = np.array([0, 0] + [(-1) ** k for k in range(10)] + [0, 0], float) * width
    return a[None, :] + t[:, None] * d[None, :] + off[:, None] * n[None, :]


def draw_view(ax, mech: S.MechanismSpec, p: Pose, P: np.ndarray, scale: float, *, labels: bool = True) -> None:
    """One view of the mechanism in ``ax``: ``P`` projects global points onto the view's plane."""
    attach = _attachments(mech, p)
    for k, b in enumerate(mech.bodies):
        r = P @ p.frames[b.name][0]
        color = f"C{k % 10}"
        for x in attach.get(b.name, []):
            y = P @ x
            ax.plot([r[0], y[0]], [r[1], y[1]], "-", color=color, lw=3, alpha=0.75, solid_capstyle="round")
        ax.plot(*r, "o", color=color, ms=5)
        if labels:
            ax.annotate(b.name, r, textcoords="offset points", xytext=(4, 4), fontsize=7, color=color)
    _draw_joints(ax, mech, p, P, scale, labels)
    _draw_loads(ax, mech, p, P, scale)
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.25)


def _ground(ax, y: np.ndarray, size: float) -> None:
    """The ground symbol under the point ``y`` of the view: a triangle on a hatched strip."""
    from matplotlib.patches import Polygon, Rectangle

    s = size * 0.035
    ax.add_patch(Polygon([y, y + [-s, -1.5 * s], y + [s, -1.5 * s]], closed=True, fc="white", ec="0.3", lw=1, zorder=1))
    ax.add_patch(Rectangle(y + [-1.6 * s, -2.1 * s], 3.2 * s, 0.6 * s, fc="white", ec="0.3", hatch="////", lw=0.8,
                           zorder=1))


def _draw_joints(ax, mech, p: Pose, P: np.ndarray, scale: float, labels: bool) -> None:
    taken: dict[tuple, int] = {}  # label positions used: joints at one point get their names stacked
    for j in mech.joints:
        points, dirs = joint_geometry(j, p)
        if not points:
            continue
        first = next(iter(points.values()))[1]
        at = P @ first
        ground = None
        if j.type == "translational" and "v" in dirs:  # the guide: the line through B across the normal
            n = dirs["v"][1]
            t = np.array([-n[1], n[0]])
            b = points.get("s_B", (None, first))[1]
            foot = b + t * float(t @ (first - b))  # where A is on the guide
            along = t * scale * 0.3
            ax.plot([foot[0] - along[0], foot[0] + along[0]], [foot[1] - along[1], foot[1] + along[1]], "--",
                    color="0.35", lw=1)
            ground = P @ foot
        if S.BASE in (j.body_i, j.body_j):
            on_base = [x for body, x in points.values() if body == S.BASE]
            _ground(ax, ground if ground is not None else P @ on_base[0] if on_base else at, scale)
        for name, (_body, d) in dirs.items():
            if name == "v":
                continue
            e = P @ (first + d * scale * 0.18)
            s = P @ (first - d * scale * 0.18)
            ax.plot([s[0], e[0]], [s[1], e[1]], "-", color="k", lw=1.2)
        ax.plot(*at, SYMBOLS.get(j.type, "*"), mfc="white", mec="k", ms=8, mew=1.4, zorder=5)
        if labels:
            key = (round(float(at[0]) / scale, 3), round(float(at[1]) / scale, 3))
            taken[key] = taken.get(key, 0) + 1
            ax.annotate(j.name, at, textcoords="offset points", xytext=(6, -4 - 9 * taken[key]), fontsize=6.5,
                        color="0.2")


def _draw_loads(ax, mech, p: Pose, P: np.ndarray, scale: float) -> None:
    forces = [ld for ld in mech.loads if ld.type == "force"]
    biggest = max((float(np.linalg.norm(ld.params["value"])) for ld in forces), default=0.0)
    for ld in mech.loads:
        if ld.type == "force" and biggest > 0:
            r = P @ p.frames[ld.params["body"]][0]
            d = P @ (np.asarray(ld.params["value"], float) / biggest * scale * 0.25)
            ax.annotate("", xy=r + d, xytext=r, arrowprops=dict(arrowstyle="->", color="C3", lw=1.5))
        elif ld.type == "spring":
            zero = np.zeros(len(p.frames[S.BASE][0]))
            a = P @ p.point(ld.params["body_i"], ld.params.get("s_i") if ld.params.get("s_i") is not None else zero)
            b = P @ p.point(ld.params["body_j"], ld.params.get("s_j") if ld.params.get("s_j") is not None else zero)
            if np.linalg.norm(b - a) > 0:
                z = _zigzag(a, b, scale * 0.02)
                ax.plot(z[:, 0], z[:, 1], "-", color="C2", lw=1)
            if S.BASE in (ld.params["body_i"], ld.params["body_j"]):
                _ground(ax, a if ld.params["body_i"] == S.BASE else b, scale)


def figure(mech: S.MechanismSpec, p: Pose, title: str, scale: float | None = None, limits=None):
    """The matplotlib figure of ``mech`` at ``p``: one view (planar) or four (spatial)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    views = VIEWS[mech.kind]
    scale = scale or extent(mech, p)
    if len(views) == 1:
        fig, axes = plt.subplots(1, 1, figsize=(6.4, 4.8), squeeze=False)
    else:
        fig, axes = plt.subplots(2, 2, figsize=(9.0, 8.0), squeeze=False)
    for ax, (h, v, P) in zip(axes.flat, views):
        draw_view(ax, mech, p, P, scale)
        ax.set_xlabel(h if v else "isometric view", fontsize=8)
        ax.set_ylabel(v, fontsize=8)
        if v == "":
            ax.set_xticks([])
            ax.set_yticks([])
        if limits is not None:
            _set_limits(ax, limits[(h, v)])
        ax.tick_params(labelsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def _set_limits(ax, limits) -> None:
    """Fixed limits (an animation's frames share them), equal scales on both axes."""
    lo, hi = limits
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])


def load_mechanism(path) -> S.MechanismSpec:
    """The mechanism of a mechanism or scene file (SceneError for a bad file)."""
    spec = sc.load(Path(path))
    return spec.mechanism if isinstance(spec, S.SceneSpec) else spec


def read_run(path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(time, column name -> values) of a CSV written by ``overcon simulate`` or ``overcon run``."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
        names = [n.strip() for n in rows[0]]
        data = np.array([[float(x) for x in r] for r in rows[1:] if r], float)
    except (OSError, IndexError, ValueError, UnicodeDecodeError) as exc:
        raise DrawError(f"{path}: not a CSV of a run (a header, then rows of numbers): {exc}") from None
    if "time" not in names or data.ndim != 2 or len(data) == 0 or data.shape[1] != len(names):
        raise DrawError(f"{path}: not a CSV of a run: needs a 'time' column and at least one row")
    cols = {n: data[:, k] for k, n in enumerate(names)}
    return cols["time"], cols


def run_coordinates(mech: S.MechanismSpec, cols: dict, where: str) -> tuple[dict[str, np.ndarray], list[str]]:
    """(body -> (rows, coordinates), the coordinates not in the run) from a run's columns
    ``<body>.<coordinate>``. A coordinate the run does not have (a scene lists only the positions
    it needs: the paper's sliders have no ``phi``) is drawn at its q0 value, and named: the caller
    says so in the picture and on stderr. A body none of whose coordinates is in the run is bad
    input (``positions = "all"`` in the scene's [outputs] has them all)."""
    out, held = {}, []
    for b in mech.bodies:
        names = S.coordinates(mech.kind, mech.rotation)[:len(b.q0)]  # a body may have fewer coordinates
        cols_b = []
        for k, c in enumerate(names):
            col = cols.get(f"{b.name}.{c}")
            if col is None:
                held.append(f"{b.name}.{c}")
                col = np.full(len(cols["time"]), b.q0[k])
            cols_b.append(col)
        if all(f"{b.name}.{c}" in held for c in names):
            raise DrawError(f"{where}: the run has no coordinate of body {b.name} ({', '.join(names)}): list them "
                            "in the scene's [outputs] positions (positions = \"all\")")
        out[b.name] = np.column_stack(cols_b)
    return out, held


def draw(source, out, *, csv_path=None, at: float | None = None, dpi: int = 120) -> tuple[Path, str]:
    """``overcon draw``: write ``out`` (.png or .svg) of the mechanism of ``source`` at q0, or at
    the output point of ``csv_path`` nearest ``at`` (default its first). Returns (path, what)."""
    out = Path(out)
    if out.suffix.lower() not in (".png", ".svg"):
        raise DrawError(f"--out {out}: give a .png or .svg file")
    mech = load_mechanism(source)
    if csv_path is None:
        if at is not None:
            raise DrawError("--at T needs --csv RUN.csv (the run to take the coordinates from)")
        p, what = initial_pose(mech), "at q0"
    else:
        time, cols = read_run(csv_path)
        q, held = run_coordinates(mech, cols, str(csv_path))
        t = time[0] if at is None else at
        if not (time[0] - 1e-9 <= t <= time[-1] + 1e-9):
            raise DrawError(f"--at {t:g}: outside the run {csv_path} (t = {time[0]:g}..{time[-1]:g} s)")
        k = int(np.argmin(np.abs(time - t)))
        p, what = pose(mech, {b: v[k] for b, v in q.items()}), f"at t = {time[k]:g} s of {Path(csv_path).name}"
        if held:
            what += f" ({', '.join(held)} not in the run: at q0)"
    fig = figure(mech, p, f"{mech.name} ({mech.kind}) {what}")
    fig.savefig(out, dpi=dpi)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return out, what


def _limits(mech: S.MechanismSpec, poses: list[Pose], scale: float) -> dict:
    """Per view, the data limits that hold every frame (so the picture does not jump)."""
    out = {}
    for h, v, P in VIEWS[mech.kind]:
        pts = np.array([P @ x for p in poses for x in
                        [r for r, _R in p.frames.values()] + [y for ys in _attachments(mech, p).values() for y in ys]])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        pad = 0.12 * max(scale, float(np.max(hi - lo)))
        out[(h, v)] = (lo - pad, hi + pad)
    return out


def animate(csv_path, scene_path, out, *, fps: int = 20, max_frames: int = 120, dpi: int = 80) -> tuple[Path, int, list]:
    """``overcon animate``: write ``out`` (.gif with Pillow, .mp4 with ffmpeg) of the run
    ``csv_path`` of the scene ``scene_path``: at most ``max_frames`` output points, evenly spread,
    shown at ``fps`` frames per second. Returns (path, frames, coordinates drawn at q0)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import animation

    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise DrawError(f"--out {out}: give a .gif or .mp4 file")
    if suffix == ".mp4" and not animation.writers.is_available("ffmpeg"):
        raise DrawError(f"--out {out}: an MP4 needs ffmpeg on the PATH (none found); write a .gif instead")
    mech = load_mechanism(scene_path)
    time, cols = read_run(csv_path)
    q, held = run_coordinates(mech, cols, str(csv_path))
    note = f"; {', '.join(held)} at q0 (not in the run)" if held else ""
    rows = np.unique(np.linspace(0, len(time) - 1, min(max_frames, len(time))).round().astype(int))
    poses = [pose(mech, {b: v[k] for b, v in q.items()}) for k in rows]
    scale = max(extent(mech, p) for p in poses)
    limits = _limits(mech, poses, scale)
    fig = figure(mech, poses[0], "", scale=scale, limits=limits)

    def frame(i):
        for ax, (h, v, P) in zip(fig.axes, VIEWS[mech.kind]):
            ax.clear()
            draw_view(ax, mech, poses[i], P, scale)
            _set_limits(ax, limits[(h, v)])
            ax.set_xlabel(h if v else "isometric view", fontsize=8)
            ax.set_ylabel(v, fontsize=8)
            ax.tick_params(labelsize=7)
        fig.suptitle(f"{mech.name}: t = {time[rows[i]]:.3f} s ({Path(csv_path).name}{note})", fontsize=9)
        return fig.axes

    anim = animation.FuncAnimation(fig, frame, frames=len(poses), blit=False)
    writer = animation.PillowWriter(fps=fps) if suffix == ".gif" else animation.FFMpegWriter(fps=fps)
    anim.save(out, writer=writer, dpi=dpi)
    plt.close(fig)
    return out, len(poses), held
