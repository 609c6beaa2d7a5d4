"""``overcon draw`` and ``overcon animate`` (overcon.draw): a picture of every scene of mechanisms/
and mechanisms/examples/ (PNG, small resolution), an SVG, a picture at a time of a run, an
animated GIF of a 2 s run, and bad input refused with exit 2."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from overcon.draw import DrawError, animate, draw, initial_pose, joint_geometry, load_mechanism

ROOT = Path(__file__).resolve().parent.parent
SCENES = sorted((ROOT / "mechanisms").glob("*.toml")) + sorted((ROOT / "mechanisms" / "examples").glob("*.toml"))
PNG = b"\x89PNG\r\n\x1a\n"


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "overcon.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=120)


def test_a_png_for_every_scene_and_mechanism(tmp_path):
    assert len(SCENES) > 40
    for f in SCENES:
        out, what = draw(f, tmp_path / f"{f.stem}.png", dpi=25)
        assert what == "at q0" and out.read_bytes()[:8] == PNG, f


def test_an_svg_through_the_command(tmp_path):
    p = _cli("draw", ROOT / "mechanisms" / "spatial_parallelogram.toml", "--out", tmp_path / "s.svg")
    assert p.returncode == 0, p.stderr
    text = (tmp_path / "s.svg").read_text()
    assert text.lstrip().startswith("<?xml") and "<svg" in text
    for view in ("isometric view",):
        assert view in text or "isometric" in text


def test_joint_points_are_where_the_file_puts_them():
    """The planar mechanism at q0: joint 4 (revolute slider1-link3 at s_i of slider1) is at slider1's
    centre of mass (2, 0) moved by s_i; the guide of joint 1 is on the base."""
    mech = load_mechanism(ROOT / "mechanisms" / "planar_sliders.toml")
    p = initial_pose(mech)
    joints = {j.name: j for j in mech.joints}
    points, dirs = joint_geometry(joints["joint4"], p)
    body, x = points["s_i"]
    slider1 = next(b for b in mech.bodies if b.name == "slider1")
    assert body == "slider1"
    assert x == pytest.approx([slider1.q0[0] + joints["joint4"].params["s_i"][0],
                               slider1.q0[1] + joints["joint4"].params["s_i"][1]])
    _points, dirs = joint_geometry(joints["joint1"], p)
    assert dirs["v"][0] == "base"


def test_a_run_drawn_at_a_time_and_animated(tmp_path):
    """A 2 s run of the tutorial's block (one body on two guides): draw at t = 1 s, then a GIF."""
    from PIL import Image

    tut = (ROOT / "docs" / "tutorial.md").read_text()
    import re
    for name in ("block.toml", "block_wo_guide2.toml"):
        m = re.search(r"```\{code-block\} toml\n:caption: " + re.escape(name) + r"\n\n(.*?)```", tut, re.S)
        (tmp_path / name).write_text(m.group(1))
    p = _cli("simulate", "block_wo_guide2.toml", "--out", "run.csv", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    p = _cli("draw", "block_wo_guide2.toml", "--csv", "run.csv", "--at", "1", "--out", "t1.png", cwd=tmp_path)
    assert p.returncode == 0 and "at t = 1 s of run.csv" in p.stdout, p.stdout + p.stderr
    # block.y and block.phi are not outputs of this scene: drawn at q0, and said so
    assert "block.y, block.phi not in the run" in p.stderr
    out, frames, held = animate(tmp_path / "run.csv", tmp_path / "block_wo_guide2.toml", tmp_path / "run.gif",
                                max_frames=8, dpi=40)
    assert frames == 8 and held == ["block.y", "block.phi"]
    with Image.open(out) as im:
        assert im.format == "GIF" and im.n_frames == 8


def test_bad_input_is_refused(tmp_path):
    mech = ROOT / "mechanisms" / "planar_sliders.toml"
    with pytest.raises(DrawError, match="give a .png or .svg"):
        draw(mech, tmp_path / "x.jpg")
    with pytest.raises(DrawError, match="--at T needs --csv"):
        draw(mech, tmp_path / "x.png", at=1.0)
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    p = _cli("draw", mech, "--csv", tmp_path / "bad.csv", "--out", tmp_path / "x.png")
    assert p.returncode == 2 and "needs a 'time' column" in p.stderr
    p = _cli("animate", tmp_path / "bad.csv", "--scene", mech, "--out", tmp_path / "x.avi")
    assert p.returncode == 2 and "give a .gif or .mp4" in p.stderr
