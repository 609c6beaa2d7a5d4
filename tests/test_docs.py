"""The first hour of a new user: the README (short, the set-up commands first, the same test
command as .ci/run), every relative link and anchor of the README and the documentation pages,
``overcon --version`` and ``--help`` written for users, the deliberate public API, and
``reproduce`` taking the paper's scenes only."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
INSTALL = 'python3 -m venv .venv && .venv/bin/pip install -e ".[test]" && .venv/bin/overcon reproduce --out reproduce'
TESTS = ".venv/bin/python -m pytest -q"
LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)\)")


def pages() -> list[Path]:
    return [ROOT / "README.md"] + sorted(p for p in DOCS.rglob("*.md") if "_build" not in p.parts)


def slug(title: str) -> str:
    """A heading's anchor as GitHub and MyST (myst_heading_anchors) make it."""
    return re.sub(r"[^\w\- ]", "", title.strip().lower().replace(" ", "-"))


def unfenced(text: str) -> str:
    """The text outside fenced code blocks."""
    return re.sub(r"^(```|~~~).*?^\1\s*$", "", text, flags=re.M | re.S)


def prose(text: str) -> str:
    """The text outside fenced code blocks and inline code."""
    return re.sub(r"`[^`\n]*`", "", unfenced(text))


def anchors(path: Path) -> set[str]:
    out: set[str] = set()
    for line in unfenced(path.read_text(encoding="utf-8")).splitlines():
        m = re.match(r"#{1,6} +(.*?)\s*$", line)
        if m:
            base = slug(re.sub(r"[`*]", "", m.group(1)))
            name, k = base, 1
            while name in out:  # GitHub numbers repeated headings
                name, k = f"{base}-{k}", k + 1
            out.add(name)
    return out


def broken_links(path: Path) -> list[str]:
    bad = []
    for target in LINK.findall(prose(path.read_text(encoding="utf-8"))):
        if re.match(r"[a-z]+:", target):
            continue  # http(s), mailto: not checked here
        file, _, anchor = target.partition("#")
        dest = path if not file else (path.parent / file).resolve()
        if not dest.exists():
            bad.append(f"{path.relative_to(ROOT)}: {target}: no such file")
        elif anchor and (dest.suffix != ".md" or anchor not in anchors(dest)):
            bad.append(f"{path.relative_to(ROOT)}: {target}: no heading with that anchor")
    return bad


def test_every_relative_link_and_anchor_resolves():
    assert [b for p in pages() for b in broken_links(p)] == []


def test_the_link_checker_finds_a_broken_anchor_and_file(tmp_path):
    (tmp_path / "a.md").write_text("# Title\n\n## Some `code` heading\n\n[ok](#some-code-heading) [bad](#nope) "
                                   "[gone](b.md) [ok2](a.md#title)\n```\n[in code](nowhere.md)\n```\n")
    global ROOT
    old, ROOT = ROOT, tmp_path
    try:
        assert broken_links(tmp_path / "a.md") == ["a.md: #nope: no heading with that anchor",
                                                   "a.md: b.md: no such file"]
    finally:
        ROOT = old


def test_readme_is_short_and_starts_with_the_two_commands():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 200
    first = lines[lines.index("```bash") + 1: lines.index("```")]
    commands = [ln for ln in first if not ln.startswith("#")]
    assert commands == [INSTALL, TESTS]
    assert lines.index("```bash") < 3
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert f"\n{TESTS}\n" in ci  # CI runs the README's test command verbatim


def _overcon(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "overcon.cli", *args], capture_output=True, text=True, timeout=60)


def test_version_and_help_are_for_users():
    from importlib.metadata import version

    p = _overcon("--version")
    assert p.returncode == 0 and p.stdout.strip() == f"overcon {version('overcon')}"
    help_text = _overcon("--help").stdout
    assert "argument parsing only" not in help_text
    for command in ("check", "simulate", "build", "run", "compare", "regress", "schema", "draw", "animate"):
        assert re.search(rf"^    {command} ", help_text, re.M), command
        assert _overcon(command, "--help").returncode == 0


def test_public_api_is_named_and_works():
    import overcon

    assert set(overcon.__all__) >= {"load", "check", "simulate_scene", "build", "run", "compare", "regress"}
    for name in overcon.__all__:
        assert getattr(overcon, name) is not None
    with pytest.raises(AttributeError):
        overcon.no_such_name  # noqa: B018
    spec = overcon.load(ROOT / "mechanisms" / "planar_f1_wo4.toml")
    assert overcon.check(spec).motion_unique is False
    assert overcon.check(spec, friction="none").motion_unique is True
    res = overcon.simulate_scene(spec, stop_time=0.1, output_interval=0.05)
    assert list(res.time) == [0.0, 0.05, 0.1] and res.column("slider1.x")[-1] != res.column("slider1.x")[0]
    with pytest.raises(overcon.SceneError):
        overcon.load(ROOT / "README.md")


def test_reproduce_takes_the_papers_scenes_only(tmp_path):
    from overcon.tooling.pipeline import paper_scenes

    for f in ("planar_sliders.toml", "planar_f1_wo4.toml", "planar_f1_wo6.toml"):
        (tmp_path / f).write_text((ROOT / "mechanisms" / f).read_text())
    mine = (ROOT / "mechanisms" / "planar_f1_wo4.toml").read_text().replace('group = "planar_f1"', 'group = "mine"')
    assert 'group = "mine"' in mine
    (tmp_path / "my_scene.toml").write_text(mine.replace('name = "planar_f1_wo4"', 'name = "my_scene"'))
    paper, others = paper_scenes(tmp_path)
    assert [p.name for p in paper] == ["planar_f1_wo4.toml", "planar_f1_wo6.toml"]
    assert [p.name for p in others] == ["my_scene.toml"]
    real, foreign = paper_scenes(ROOT / "mechanisms")
    assert len(real) == 20 and foreign == []


@pytest.mark.integration
def test_public_api_builds_runs_and_compares(tmp_path):
    import overcon

    scenes = [ROOT / "mechanisms" / "planar_f45_wo4.toml", ROOT / "mechanisms" / "planar_f45_wo6.toml"]
    fmus = overcon.build(scenes, tmp_path / "fmus")
    assert [f.name for f in fmus] == ["planar_f45_wo4.fmu", "planar_f45_wo6.fmu"]
    with pytest.raises(overcon.InputError, match="refused"):
        overcon.build(ROOT / "mechanisms" / "planar_f1_wo4.toml", tmp_path / "nonunique")
    runs = overcon.run(fmus[0], tmp_path / "results", stop_time=0.5, settings={"joint4.mu": 0.2})
    assert runs[0].csv.is_file()
    outcome = overcon.compare(fmus, tmp_path / "comparison", stop_time=0.5)
    (c,) = outcome.comparisons
    assert c.group == "planar_f45" and c.matches and (tmp_path / "comparison" / "report.md").is_file()
