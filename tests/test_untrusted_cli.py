"""Untrusted input to the command line (docs/untrusted-input.md): FMU archives (a
modelIdentifier that is a path, a zip bomb, temp directories after failing runs, crafted facts
records), scene files that would make tomllib quadratic, and output paths that must never destroy
inputs or look complete when they are not."""
from __future__ import annotations

import io
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import pytest

fmpy = pytest.importorskip("fmpy")

from overcon import outfiles  # noqa: E402
from overcon.cli import main  # noqa: E402
from overcon.fmu import build as fmu_build  # noqa: E402
from overcon.tooling import InputError  # noqa: E402
from overcon.tooling.fmus import MAX_UNZIPPED_MB, inspect_fmu  # noqa: E402
from overcon.tooling.run import Experiment, Job, experiment, run_jobs  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MECH = ROOT / "mechanisms"


@pytest.fixture(scope="module")
def fmu(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("untrusted_cli")
    code, results = fmu_build.build_all([str(MECH / "planar_f45_wo4.toml")], out, refs=False, validate=False,
                                        allow_nonunique=True, echo=lambda s: None, echo_err=lambda s: None)
    assert code == 0
    return results[0].fmu


def rewritten(src: Path, dst: Path, change: dict) -> Path:
    """A copy of the FMU src with entries replaced (name -> bytes, or a function of the old bytes)."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            new = change.get(item.filename, data)
            zout.writestr(item, new(data) if callable(new) else new)
        for name, data in change.items():
            if name not in zin.namelist():
                zout.writestr(name, data)
    return dst


def run_cli(argv, capsys) -> tuple[int, str]:
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


# ------------------------------------------------------------------------------------ FMU archives

def test_model_identifier_that_is_a_path_is_refused(fmu, tmp_path, capsys):
    bad = rewritten(fmu, tmp_path / "bad.fmu", {"modelDescription.xml": lambda b: b.replace(
        b'modelIdentifier="planar_f45_wo4"', b'modelIdentifier="../../escaped"')})
    before = sorted(tmp_path.rglob("*"))
    for argv in (["run", bad, "--out", tmp_path / "a" / "b"], ["compare", bad, "--one-group", "--out", tmp_path / "c" / "d"]):
        code, err = run_cli(argv, capsys)
        assert code == 2, err
        assert "modelIdentifier '../../escaped' is not an identifier" in err
    assert not list(tmp_path.rglob("*.csv")) and not (tmp_path / "escaped.csv").exists()
    assert {p for p in tmp_path.rglob("*") if p.is_file()} == {p for p in before if p.is_file()}


def test_zip_bomb_is_refused_before_extraction(fmu, tmp_path, capsys):
    """A 6 MiB file of zeros (a few kB compressed) over a 1 MiB limit; the default limit is documented."""
    bomb = rewritten(fmu, tmp_path / "bomb.fmu", {"resources/zeros.bin": bytes(6 * 2 ** 20)})
    assert bomb.stat().st_size < 2 ** 20
    code, err = run_cli(["run", bomb, "--out", tmp_path / "out", "--max-unzipped-mb", "1"], capsys)
    assert code == 2
    assert "unzips to 6.6 MiB, more than the limit of 1 MiB (--max-unzipped-mb raises it)" in err or \
        "more than the limit of 1 MiB (--max-unzipped-mb raises it)" in err, err
    assert not (tmp_path / "out").exists()  # refused before anything was made
    os.environ.pop("OVERCON_MAX_UNZIPPED_MB", None)
    assert MAX_UNZIPPED_MB == 2048
    many = rewritten(fmu, tmp_path / "many.fmu", {f"resources/f{k}": b"" for k in range(30)})
    code, err = run_cli(["run", many, "--out", tmp_path / "out", "--max-unzipped-files", "20"], capsys)
    os.environ.pop("OVERCON_MAX_UNZIPPED_FILES", None)
    assert code == 2 and "files in the archive, more than the limit of 20 (--max-unzipped-files raises it)" in err


def test_entry_outside_the_archive_is_refused(fmu, tmp_path):
    bad = rewritten(fmu, tmp_path / "slip.fmu", {"../outside.txt": b"x"})
    with pytest.raises(InputError, match=r"archive entry '../outside.txt' points outside the FMU"):
        inspect_fmu(bad)


def test_temp_dirs_are_removed_after_twenty_failing_runs(fmu, tmp_path, monkeypatch):
    """Runs whose instantiation fails (a corrupt model file): no overcon-run-* directory is left."""
    broken = rewritten(fmu, tmp_path / "broken.fmu", {"resources/overcon_model.bin": b"OVKFMU01 but not a model"})
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    monkeypatch.setattr(tempfile, "tempdir", None)  # read TMPDIR again
    info = inspect_fmu(broken)
    jobs = [Job(f"run{k}", info, experiment(info, stop_time=0.05), tmp_path / f"run{k}.csv") for k in range(20)]
    results, failures = run_jobs(jobs, workers=2, progress=False, echo=lambda s: None)
    assert not results and len(failures) == 20
    assert all("overcon_model.bin" in str(f) or "instantiat" in str(f).lower() for f in failures.values()), failures
    assert list(tmp.iterdir()) == []
    assert not list(tmp_path.glob("*.csv")) and not list(tmp_path.glob("*.part"))


@pytest.mark.parametrize("facts, key", [
    (b'{"format": 1, "model": ' + b"[" * 5000 + b"]" * 5000 + b"}", "nested deeper than 32 levels"),
    (None, "key 'eliminate[0]' has the wrong type (array), expected integer"),
    (None, "key 'friction[0]' has the wrong type (int), expected string"),
    (None, "is not JSON: number 1e999 is not finite"),
])
def test_crafted_facts_record_exits_2_naming_file_and_key(fmu, tmp_path, capsys, facts, key):
    with zipfile.ZipFile(fmu) as zf:
        rec = json.loads(zf.read("resources/overcon_facts.json"))
    if facts is None:
        if "eliminate" in key:
            rec["eliminate"] = [[1]]
        elif "friction" in key:
            rec["friction"] = [1, None, {}]
        facts = json.dumps(rec).encode()
        if "1e999" in key:
            facts = facts.replace(b'"eliminate": [4]', b'"eliminate": [1e999]')
    bad = rewritten(fmu, tmp_path / "planar_f45_wo4.fmu", {"resources/overcon_facts.json": facts})
    code, err = run_cli(["compare", bad, "--one-group", "--out", tmp_path / "out"], capsys)
    assert code == 2, err
    assert f"{bad}: resources/overcon_facts.json" in err and key in err, err


# ------------------------------------------------------------------------------------ scene files

def test_dotted_key_scene_of_200_kb_is_refused_before_parsing(tmp_path):
    """The quadratic dotted key: refused by the pre-scan (tomllib never sees it), in a process that
    stays under 200 MB. (Measured: about 0.2 s for the refusal itself.)"""
    text = (MECH / "planar_f45_wo4.toml").read_text().replace("planar_sliders.toml", str(MECH / "planar_sliders.toml"))
    bomb = tmp_path / "bomb.toml"
    bomb.write_text(text + "gravity" + ".a" * 100_000 + " = 1\n")
    assert bomb.stat().st_size > 200_000
    # the child's own peak (VmHWM, kB): ru_maxrss keeps the forking parent's (a long pytest run's)
    code = ("import sys\nfrom overcon.cli import main\nrc = main(['check', sys.argv[1]])\n"
            "hwm = next(l for l in open('/proc/self/status') if l.startswith('VmHWM'))\n"
            "print('maxrss', hwm.split()[1])\nsys.exit(rc)")
    proc = subprocess.run([sys.executable, "-c", code, str(bomb)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert "invalid TOML (refused before parsing): line" in proc.stderr and "at most 32 parts" in proc.stderr
    rss_kb = int(proc.stdout.split("maxrss")[1])
    assert rss_kb < 200 * 1024, rss_kb


# ------------------------------------------------------------------------------------ output paths

def _scene(tmp_path) -> Path:
    shutil.copy(MECH / "planar_sliders.toml", tmp_path)
    scene = tmp_path / "s.toml"
    scene.write_text((MECH / "planar_f45_wo4.toml").read_text().replace("stop_time = 4.0", "stop_time = 0.05"))
    return scene


def test_outputs_never_overwrite_inputs_or_each_other(tmp_path, capsys):
    scene = _scene(tmp_path)
    mech = tmp_path / "planar_sliders.toml"
    before = {p: p.read_bytes() for p in (scene, mech)}
    same = tmp_path / "same.csv"
    cases = [(["--out", same, "--events", same], "--events " + str(same) + ": the same file as --out"),
             (["--out", scene], f"--out {scene}: is the input scene file"),
             (["--out", mech], f"--out {mech}: is the input mechanism file"),
             (["--out", "/dev/full"], "--out /dev/full: is not a regular file"),
             (["--out", tmp_path / "nodir" / "x.csv"], "the directory " + str(tmp_path / "nodir") + " does not exist")]
    for extra, message in cases:
        code, err = run_cli(["simulate", scene, *extra], capsys)
        assert code == 2 and message in err, err
    assert not same.exists()
    assert {p: p.read_bytes() for p in (scene, mech)} == before


def test_interrupted_write_keeps_the_old_file(tmp_path, capsys, monkeypatch):
    """Ctrl-C while simulate writes its CSV: the file that was there is left as it was, no .part."""
    import overcon.simulate as sim_mod
    scene = _scene(tmp_path)
    out = tmp_path / "out.csv"
    out.write_text("old\n")
    real = sim_mod.csv.writer

    class Interrupting:
        def __init__(self, fh):
            self.w, self.n = real(fh), 0

        def writerow(self, row):
            self.n += 1
            if self.n > 3:
                raise KeyboardInterrupt
            self.w.writerow(row)

    monkeypatch.setattr(sim_mod.csv, "writer", Interrupting)
    code, err = run_cli(["simulate", scene, "--out", out], capsys)
    assert code == 130 or "interrupted" in err, (code, err)
    assert out.read_text() == "old\n"
    assert not list(tmp_path.glob("*.part"))


def test_interrupted_build_leaves_no_part_file(tmp_path, monkeypatch):
    scene = _scene(tmp_path)

    def interrupt(*args, **kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(fmu_build, "_zip_write", interrupt)
    with pytest.raises(KeyboardInterrupt):
        fmu_build.build_all([str(scene)], tmp_path / "fmus", refs=False, validate=False, allow_nonunique=True,
                            echo=lambda s: None, echo_err=lambda s: None)
    assert not list((tmp_path / "fmus").glob("*.part"))


def test_atomic_write_is_whole_or_nothing(tmp_path):
    target = tmp_path / "t.txt"
    target.write_text("before")
    with pytest.raises(RuntimeError):
        with outfiles.atomic(target) as fh:
            fh.write("half")
            raise RuntimeError("disk full")
    assert target.read_text() == "before" and not outfiles.part_path(target).exists()
    with outfiles.atomic(target) as fh:
        fh.write("after")
    assert target.read_text() == "after"


def test_reference_with_non_finite_or_ragged_rows_exits_2(fmu, tmp_path, capsys):
    names = [v.name for v in fmpy.read_model_description(str(fmu)).modelVariables
             if v.causality == "output" and v.type == "Real"]
    header = ",".join(f'"{n}"' for n in ["time", *names])
    rows = [",".join([repr(0.01 * k)] + ["0.5"] * len(names)) for k in range(5)]
    inf_ref = tmp_path / "inf.csv"
    inf_ref.write_text("\n".join([header, rows[0], rows[1].replace("0.5", "1e999", 1), *rows[2:]]) + "\n")
    code, err = run_cli(["compare", fmu, "--ref", inf_ref, "--out", tmp_path / "o1"], capsys)
    assert code == 2 and f"{inf_ref}: row 2, column '{names[0]}': 1e999 is not finite" in err, err
    ragged = tmp_path / "ragged.csv"
    ragged.write_text("\n".join([header] + ["0.0,1,2"] * 3) + "\n")
    code, err = run_cli(["compare", fmu, "--ref", ragged, "--out", tmp_path / "o2"], capsys)
    assert code == 2 and f"{ragged}: row 1 has 3 columns, the header has {len(names) + 1}" in err, err


def test_reference_that_is_an_output_of_the_comparison_is_refused(fmu, tmp_path, capsys):
    out = tmp_path / "cmp"
    out.mkdir()
    ref = out / "planar_f45_wo4.csv"
    ref.write_text('"time","slider1.x"\n0.0,1.0\n0.01,1.0\n')
    before = ref.read_bytes()
    code, err = run_cli(["compare", fmu, "--ref", ref, "--out", out], capsys)
    assert code == 2 and f"is the input --ref {ref}" in err, err
    assert ref.read_bytes() == before


def test_unwritable_out_is_found_before_the_run(fmu, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code, err = run_cli(["run", fmu, "--out", blocker / "sub"], capsys)
    assert code == 2 and f"--out {blocker / 'sub'}: cannot write there" in err, err
    assert "simulation failed" not in err


def test_set_redundancy_by_item_name(fmu, tmp_path, capsys):
    code, err = run_cli(["run", fmu, "--out", tmp_path / "o", "--stop-time", "0.02", "--set", "redundancy=bogus"],
                        capsys)
    assert code == 2 and "--set redundancy=bogus: not one of redundancy's items (eliminate (1), min-norm (2), " \
        "compliant (3))" in err, err
    assert "no such parameter" not in err


@pytest.mark.parametrize("definition, message", [
    ('{"inputs": [], "params": ["a=1"], "samples": 1e999, "seed": null, "stop_time": null, "lockstep_step": null}',
     "number 1e999 is not finite"),
    ('{"inputs": "x", "params": [], "samples": null, "seed": null, "stop_time": null, "lockstep_step": null}',
     "key 'inputs' has the wrong type (str), expected array"),
    ('{"inputs": [], "params": []}', "key 'samples' missing"),
])
def test_crafted_sweep_definition_exits_2_naming_the_key(tmp_path, capsys, definition, message):
    (tmp_path / "sweep.json").write_text(definition)
    code, err = run_cli(["sweep", "--resume", tmp_path], capsys)
    assert code == 2 and f"{tmp_path / 'sweep.json'}" in err and message in err, err


def test_ctrl_c_during_a_run_removes_its_temp_dir(fmu, tmp_path, monkeypatch):
    import overcon.tooling.run as run_mod
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    monkeypatch.setattr(tempfile, "tempdir", None)
    seen = []

    def interrupted(argv, **kw):
        seen.append(json.loads(argv[-1])["unzip_dir"])
        assert Path(seen[-1]).is_dir()
        raise KeyboardInterrupt

    monkeypatch.setattr(run_mod.subprocess, "run", interrupted)
    info = inspect_fmu(fmu)
    with pytest.raises(KeyboardInterrupt):
        run_mod.run_one(info, experiment(info, stop_time=0.05), tmp_path / "x.csv", False, None)
    assert seen and list(tmp.iterdir()) == []
