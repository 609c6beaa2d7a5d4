"""Regression check (``overcon regress``, overcon.tooling.regress): every scene FMU of mechanisms/
is built, validated, run with fmpy and compared with its committed baseline in ci/baselines/; and
the check's own behaviour: a 1% mass change fails naming scene, output and difference, a scene
without a baseline fails clearly, the tolerance table meets the acceptance floor (1e-6 m, 1e-4 N),
regeneration round trip, JUnit XML with one test case per scene and a perturbed baseline failing.
"""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest

pytestmark = pytest.mark.integration  # every test here builds or runs FMUs, or shares a fixture that does

ROOT = Path(__file__).resolve().parent.parent
MECH = ROOT / "mechanisms"
BASELINES = ROOT / "ci" / "baselines"
TOLERANCES = ROOT / "ci" / "tolerances.toml"
COMMAND = [sys.executable, "-m", "overcon.cli", "regress"]

from overcon.tooling import regress  # noqa: E402

SCENES, _PROBLEMS = regress.discover_scenes(MECH)
PAPER = {f"planar_{f}_wo{k}" for f in ("none", "f45", "f1", "f145") for k in (4, 6)} | \
        {f"spatial_{f}_wo{k}" for f in ("none", "MN", "GH", "GHMN") for k in (5, 9, 18)}
FINDING = re.compile(r"^(?P<scene>\w+): (?P<output>[\w.]+) \((?P<unit>[^,]+), (?P<what>[^)]*)\) differs from the "
                     r"baseline by (?P<diff>[-+.e0-9]+) .*tolerance (?P<tol>[-+.e0-9]+)")


def _mech_copy(dst: Path, scenes: list[str] = (), mech_text: dict | None = None) -> Path:
    """mechanisms/ copied to ``dst``: both mechanism files (``mech_text`` replaces some) and the
    scene files named (all when empty)."""
    dst.mkdir(parents=True, exist_ok=True)
    for f in MECH.glob("*.toml"):
        if f.stem in ("planar_sliders", "spatial_parallelogram") or not scenes or f.stem in scenes:
            shutil.copyfile(f, dst / f.name)
    for name, text in (mech_text or {}).items():
        (dst / name).write_text(text)
    return dst


def _new_scene(dst: Path, name: str, source: str = "planar_none_wo4") -> Path:
    text = (MECH / f"{source}.toml").read_text()
    assert f'name = "{source}"' in text
    f = dst / f"{name}.toml"
    f.write_text(text.replace(f'name = "{source}"', f'name = "{name}"'))
    return f


def test_every_scene_has_a_baseline():
    """Every scene (the 20 paper scenes and any added one) has its _ref.csv, _ref.opt and
    provenance; no baseline without a scene. The paper scenes' baselines cover the FMUs' full
    default experiment (4 s planar, 10 s spatial) every 0.05 s."""
    assert not _PROBLEMS
    assert PAPER <= set(SCENES)
    prov = regress.load_provenance(BASELINES)
    for name in SCENES:
        csv, opt = regress.baseline_files(BASELINES, name)
        assert csv.is_file() and opt.is_file(), f"{name}: no baseline"
        assert prov["scenes"][name]["platform"] in prov["platforms"]
        grid = regress.read_opt(opt)
        if name in PAPER:
            assert grid["StepSize"] == 0.05 and grid["StopTime"] == (4.0 if name.startswith("planar") else 10.0)
    names = {f.name[: -len("_ref.csv")] for f in BASELINES.glob("*_ref.csv")}
    assert names == set(SCENES)


@pytest.mark.integration
def test_every_scene_matches_its_baseline(tmp_path):
    """The CI command itself, with the repository's defaults (mechanisms/, ci/baselines/,
    ci/tolerances.toml from the working directory): build, fmpy validate, run, compare every
    scene; exit 0; the JUnit XML has one passing test case per scene."""
    junit = tmp_path / "out.xml"
    proc = subprocess.run(COMMAND + ["--out", str(tmp_path), "--junit", str(junit)], capture_output=True,
                          text=True, cwd=ROOT, timeout=1200)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-6000:]
    ok = {m.group(1) for m in re.finditer(r"^ok +(\w+): \d+ outputs within tolerance", proc.stdout, re.M)}
    assert ok == set(SCENES), out[-6000:]
    assert f"{len(SCENES)} scene(s) match their baselines, 0 regression(s), 0 bad input(s)" in proc.stdout
    assert (tmp_path / "report.md").is_file()
    suite = ET.parse(junit).getroot().find("testsuite")
    cases = suite.findall("testcase")
    assert sorted(c.get("name") for c in cases) == sorted(SCENES)
    assert all(len(c) == 0 for c in cases)  # no failure, no error
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == (str(len(SCENES)), "0", "0")


@pytest.mark.integration
def test_a_perturbed_baseline_fails_in_the_junit_report(tmp_path):
    """One baseline value moved by 1e-5 m: exit 1, and the JUnit XML has one failure naming the
    scene and the output (the other scene passes)."""
    names = ["planar_none_wo4", "planar_none_wo6"]
    mdir = _mech_copy(tmp_path / "mech", names)
    bl = tmp_path / "baselines"
    bl.mkdir()
    for n in names:
        for ext in ("_ref.csv", "_ref.opt"):
            shutil.copyfile(BASELINES / f"{n}{ext}", bl / f"{n}{ext}")
    shutil.copyfile(BASELINES / "provenance.json", bl / "provenance.json")
    csv = bl / "planar_none_wo6_ref.csv"
    lines = csv.read_text().splitlines()
    header = [h.strip('"') for h in lines[0].split(",")]
    col = header.index("slider1.x")
    row = lines[40].split(",")
    row[col] = repr(float(row[col]) + 1e-5)
    lines[40] = ",".join(row)
    csv.write_text("\n".join(lines) + "\n")
    junit = tmp_path / "junit.xml"
    proc = subprocess.run(COMMAND + [str(mdir), "--baselines", str(bl), "--tolerances", str(TOLERANCES),
                                     "--out", str(tmp_path / "out"), "--junit", str(junit)],
                          capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    cases = {c.get("name"): c for c in ET.parse(junit).getroot().iter("testcase")}
    assert sorted(cases) == names
    assert len(cases["planar_none_wo4"]) == 0
    failure = cases["planar_none_wo6"].find("failure")
    assert failure is not None and "planar_none_wo6" in failure.get("message")
    assert "slider1.x" in failure.get("message") and "slider1.x" in failure.text


@pytest.mark.integration
def test_mass_changed_by_1_percent_fails_naming_scene_output_and_difference(tmp_path):
    mech = (MECH / "planar_sliders.toml").read_text()
    assert mech.count("mass = 3.0\n") == 4
    changed = mech.replace("mass = 3.0\n", "mass = 3.03\n", 1)  # slider1: 3 kg -> 3.03 kg
    mdir = _mech_copy(tmp_path / "mech", ["planar_none_wo4"], {"planar_sliders.toml": changed})
    lines: list[str] = []
    out = regress.regress(["planar_none_wo4"], mechanisms=mdir, baselines=BASELINES, tolerances=TOLERANCES,
                          out=tmp_path / "out", echo=lines.append)
    text = "\n".join(lines)
    assert out.code == regress.EXIT_REGRESSION, text
    found = [FINDING.match(ln[len("REGRESSION "):]) for ln in lines if ln.startswith("REGRESSION ")]
    found = [m for m in found if m]
    assert found, text
    for m in found:
        assert m["scene"] == "planar_none_wo4"
        assert float(m["diff"]) > float(m["tol"]) > 0
    positions = [m for m in found if m["unit"] in ("m", "rad")]
    assert positions and float(positions[0]["diff"]) > 1e-5, text  # 1% of a mass: far beyond round-off
    assert "--regenerate --scenes planar_none_wo4" in text  # how to accept it, if intended
    assert "planar_none_wo4" in (tmp_path / "out" / "report.md").read_text()


def test_scene_without_baseline_fails_with_a_clear_message(tmp_path):
    mdir = _mech_copy(tmp_path / "mech", ["planar_none_wo4"])
    _new_scene(mdir, "my_slider_scene")
    lines: list[str] = []
    out = regress.regress(["my_slider_scene"], mechanisms=mdir, baselines=BASELINES, tolerances=TOLERANCES,
                          out=tmp_path / "out", echo=lines.append)
    text = "\n".join(lines)
    assert out.code == regress.EXIT_INPUT, text
    assert "my_slider_scene: no baseline" in text
    assert "my_slider_scene_ref.csv" in text
    # DIR before --scenes, which takes every word after it
    assert re.search(rf"overcon regress {re.escape(str(mdir))} --regenerate( --tolerances \S+)? --scenes my_slider_scene$",
                     text, re.M), text
    assert not (tmp_path / "out" / "fmus").exists()  # fails before building anything


def test_command_line_exit_codes(tmp_path):
    mdir = _mech_copy(tmp_path / "mech", ["planar_none_wo4"])
    _new_scene(mdir, "my_slider_scene")
    run = COMMAND + [str(mdir), "--out", str(tmp_path / "out")]
    p = subprocess.run(run + ["--scenes", "my_slider_scene"], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 2 and "my_slider_scene: no baseline" in p.stdout
    p = subprocess.run(run + ["--scenes", "no_such_scene"], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 2 and "--scenes no_such_scene: matches no scene" in p.stdout
    p = subprocess.run(run + ["--step", "0.1"], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 2 and "only with --regenerate" in p.stderr
    bad = tmp_path / "tol.toml"
    bad.write_text("[same_platform]\nm = -1\n")
    p = subprocess.run(run + ["--tolerances", str(bad)], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 2 and "same_platform.m must be a positive finite number" in p.stdout


@pytest.mark.integration
def test_regenerate_round_trip_and_orphan_baseline(tmp_path):
    """--regenerate writes a checkable baseline (bit-identical on the same platform); a baseline
    whose scene is gone fails the full check."""
    mdir = _mech_copy(tmp_path / "mech", ["planar_f45_wo4"])
    (mdir / "planar_f45_wo4.toml").unlink()
    _new_scene(mdir, "my_friction_scene", "planar_f45_wo4")
    bl = tmp_path / "baselines"
    lines: list[str] = []
    kw = dict(mechanisms=mdir, baselines=bl, out=tmp_path / "out", echo=lines.append)
    assert regress.regenerate(stop_time=1.0, **kw).code == 0, "\n".join(lines)
    assert regress.read_opt(bl / "my_friction_scene_ref.opt")["StopTime"] == 1.0
    assert "my_friction_scene: wrote" in "\n".join(lines) and "new baseline" in "\n".join(lines)
    out = regress.regress(**kw)
    assert out.code == 0, "\n".join(lines)
    assert out.checks["my_friction_scene"].bit_identical
    assert out.checks["my_friction_scene"].tier == "same_platform"
    # regenerating again keeps the grid and reports "unchanged"
    lines.clear()
    assert regress.regenerate(**kw).code == 0
    assert "unchanged (bit-identical)" in "\n".join(lines)
    assert regress.read_opt(bl / "my_friction_scene_ref.opt")["StopTime"] == 1.0
    # a baseline without a scene
    shutil.copyfile(bl / "my_friction_scene_ref.csv", bl / "gone_scene_ref.csv")
    lines.clear()
    out = regress.regress(**kw)
    assert out.code == regress.EXIT_INPUT
    assert "baseline of scene gone_scene, which is not in" in "\n".join(lines)


# ------------------------------------------------------------------------------- tolerances

@pytest.fixture(scope="module")
def infos(tmp_path_factory):
    from overcon.fmu.build import build_all
    from overcon.tooling.fmus import inspect_fmu

    out = tmp_path_factory.mktemp("fmus")
    code, res = build_all(sorted(SCENES.values()), out, allow_nonunique=True, refs=False, validate=False,
                          echo=lambda s: None, echo_err=lambda s: None)
    assert code == 0
    return {r.name: inspect_fmu(r.fmu) for r in res if r.status == "built"}


def test_tolerance_table_meets_the_floor(infos):
    """Same platform: every position/angle tolerance < 1e-6, every reaction tolerance < 1e-4
    (unique or not). Cross platform: the same, except outputs covered by a documented rule."""
    table = regress.load_tolerances(TOLERANCES)
    assert set(infos) == set(SCENES)
    n = 0
    for scene, info in infos.items():
        for o in info.outputs:
            floor = 1e-6 if o.unit in ("m", "rad") else 1e-4
            assert o.unit in ("m", "rad", "N", "N.m", "rad/s", "m/s")  # rates: the joint sensors (issue 38)
            tol, src = table.lookup("same_platform", scene, o.name, o.unit)
            assert tol < floor, (scene, o.name, tol, src)
            tol, src = table.lookup("cross_platform", scene, o.name, o.unit)
            assert tol < floor or ".rule]]" in src, (scene, o.name, tol, src)
            n += 1
    assert n >= 8 * 40 + 12 * 27  # the paper scenes' outputs, at least


def test_a_change_of_1e6_m_or_1e4_N_is_caught(infos):
    """Baseline against itself with one output shifted: a position by 1e-6 m, a unique reaction
    and a non-unique one by 1e-4 N -- each is a finding naming scene, output, difference; the
    non-unique one is reported as such. Every scene, same-platform tier."""
    from overcon.tooling.run import Series, read_series

    table = regress.load_tolerances(TOLERANCES)
    all_unique = set()
    for scene, info in infos.items():
        csv, _ = regress.baseline_files(BASELINES, scene)
        ref = read_series(csv)
        same = regress.compare_scene(scene, info, ref, ref, csv, table, "same_platform")
        assert not same.findings and same.bit_identical
        pos = next(o for o in info.outputs if o.unit == "m")
        # a unique and a non-unique reaction, where the scene has one (the door, the four-bar and
        # the carriage examples have no unique reaction; the compliant examples no non-unique one:
        # their redundant hinges are compliant, the rigid rest unique; the N-four-bar scenes output
        # positions only; the bead examples have no redundant equation)
        uniq = next((o for o in info.outputs if o.kind == "reaction" and info.reaction_unique[o.joint]), None)
        nonu = next((o for o in info.outputs if o.kind == "reaction" and not info.reaction_unique[o.joint]), None)
        if nonu is None:
            all_unique.add(scene)
        for o, delta in ((pos, 1e-6), (uniq, 1e-4), (nonu, 1e-4)):
            if o is None:
                continue
            vals = dict(ref.values)
            vals[o.name] = vals[o.name] + delta
            chk = regress.compare_scene(scene, info, Series(ref.time, vals), ref, csv, table, "same_platform")
            assert [f.output for f in chk.findings] == [o.name], (scene, o.name)
            text = chk.findings[0].describe()
            m = FINDING.match(text)
            assert m and m["scene"] == scene and m["output"] == o.name, text
            assert np.isclose(float(m["diff"]), delta, rtol=1e-2), text
            if o is nonu:
                assert "reaction NOT unique" in text
            elif o is uniq:
                assert "reaction, unique" in text
    assert all_unique == {s for s in infos if s.startswith(("compliant_", "nfourbar_", "bead_"))}, all_unique
