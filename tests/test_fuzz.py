"""Fuzz test of the input side: mutated copies of the paper's scene and mechanism files, run
through ``overcon check`` and ``overcon simulate`` in process (``overcon.cli.main``).

Seeded (deterministic): the same 240 cases every run. Each case mutates one value or the text of a
paper file (huge, tiny, negative, NaN, inf numbers; wrong types; missing and extra keys; long
names, keywords, unicode; truncated files; duplicated tables; ...) and then runs ``check`` and
``simulate --stop-time 0.05`` on it. A case fails when the command raises anything but SystemExit
(a traceback), returns an exit code outside {0, 1, 2, 3}, or takes longer than CASE_LIMIT
seconds (a hang; ``signal.alarm`` ends it). Simulations also get a wall-time budget
(``--max-wall-time``) far below the limit, so a slow but legitimate case ends as exit 3.
"""
from __future__ import annotations

import contextlib
import io
import random
import re
import signal
import time
from pathlib import Path

import pytest

from overcon.cli import main

MECH = Path(__file__).resolve().parent.parent / "mechanisms"
SEED = 20261122
N_CASES = 240
CASE_LIMIT = 20  # s per command: a hang, far above any case measured (< 2 s)
WALL_BUDGET = "5"  # s: --max-wall-time of each simulate
ALLOWED_CODES = {0, 1, 2, 3}

SCENES = ["planar_f45_wo4", "planar_f1_wo6", "planar_none_wo4", "spatial_MN_wo5", "spatial_GH_wo9"]
MECHANISMS = ["planar_sliders", "spatial_parallelogram"]

NUMBERS = ["1e308", "-1e308", "1e-308", "5e-324", "-5e-324", "0", "-0.0", "-1", "nan", "inf", "-inf",
           "1e-300", "1e300", "123456789012345678901234567890", "-9223372036854775809", "1e-13", "1e-12",
           "1e-8", "1e7", "3", "0.5"]
OTHERS = ['"text"', "true", "false", "[]", "[1, 2]", '["a", "b"]', "{}", "{ a = 1 }", "1979-05-27T07:32:00Z",
          '"' + "x" * 5000 + '"', '"base"', '"auto"', '"all"', '"none"', '"solver"', '"\u00e9\u4e2d\U0001F600"',
          '"joint1"', '"G"', '""', '"\\u0000"', "[[1, 2], [3]]", "[nan, inf]", '"' + "j" * 40 + '"']
EXTRA = ["\n[extra_table]\nkey = 1\n", "\nunknown_key = 3\n", "\n[solver]\nmethod = \"rk4\"\n",
         "\n[[bodies]]\nname = \"extra\"\n", "\n[[joints]]\nname = \"joint1\"\n", "\n[outputs]\nfriction = \"all\"\n",
         "\n[scene]\nname = \"dup\"\n", "\n[mechanism]\nname = \"dup\"\n", "\n[[loads]]\ntype = \"spring\"\n"]
VALUE_LINE = re.compile(r"^(?P<key>[A-Za-z_0-9]+) = (?P<value>.+)$", re.M)


def _mutations(rng: random.Random, text: str) -> str:
    """One random mutation of a TOML text (line based, so every key of the file can be hit)."""
    lines = [m for m in VALUE_LINE.finditer(text)]
    kind = rng.choice(["number", "number", "number", "other", "other", "delete", "rename", "extra",
                       "truncate", "duplicate", "bytes", "solver"])
    if kind in ("number", "other", "delete", "rename") and lines:
        m = rng.choice(lines)
        a, b = m.span()
        if kind == "number":
            value = m["value"]
            nums = list(re.finditer(r"-?\d+(\.\d+)?(e-?\d+)?", value))
            if nums:
                n = rng.choice(nums)
                value = value[: n.start()] + rng.choice(NUMBERS) + value[n.end():]
            else:
                value = rng.choice(NUMBERS)
            return text[:a] + f"{m['key']} = {value}" + text[b:]
        if kind == "other":
            return text[:a] + f"{m['key']} = {rng.choice(OTHERS)}" + text[b:]
        if kind == "delete":
            return text[:a] + text[b:]
        return text[:a] + f"{m['key']}{rng.choice(['_x', '', 'Ä', ' '])}x = {m['value']}" + text[b:]
    if kind == "extra":
        return text + rng.choice(EXTRA)
    if kind == "truncate":
        return text[: rng.randrange(len(text))]
    if kind == "duplicate":
        block = rng.choice(re.findall(r"^\[\[?[^\n]+\]\]?\n(?:[^\[\n][^\n]*\n)*", text, re.M) or [text])
        return text + "\n" + block
    if kind == "bytes":
        i = rng.randrange(len(text))
        return text[:i] + rng.choice(["\x00", "\udcff", "\ufeff", "]]]", "\"", "'''", "#", "\t"]) + text[i:]
    # a solver value
    key = rng.choice(["tolerance", "step", "max_step", "output_interval", "baumgarte", "friction_tol",
                      "friction_max_iter", "method"])
    value = rng.choice(NUMBERS + ['"rk4"', '"radau"', '"dop853"'])
    return re.sub(r"^\[solver\]\n", f"[solver]\n{key} = {value}\n", text, count=1, flags=re.M) \
        if "[solver]" in text else text + f"\n[solver]\n{key} = {value}\n"


def _cases():
    rng = random.Random(SEED)
    cases = []
    for k in range(N_CASES):
        target_is_mech = rng.random() < 0.35
        name = rng.choice(MECHANISMS if target_is_mech else SCENES)
        text = (MECH / f"{name}.toml").read_text(encoding="utf-8")
        for _ in range(rng.choice([1, 1, 1, 2, 3])):
            text = _mutations(rng, text)
        cases.append((k, name, target_is_mech, text))
    return cases


class Hang(Exception):
    pass


def _alarm(signum, frame):
    raise Hang()


def _run(argv) -> tuple[object, float, str]:
    """(exit code or the exception raised, seconds, stderr) of ``main(argv)``, output captured."""
    out, err = io.StringIO(), io.StringIO()
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(CASE_LIMIT)
    start = time.perf_counter()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(argv)
    except SystemExit as exc:
        code = exc.code
    except Hang as exc:
        code = exc
    except BaseException as exc:  # noqa: BLE001 - every other exception is a traceback
        code = exc
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    return code, time.perf_counter() - start, err.getvalue()


def test_fuzz_no_traceback_no_hang(tmp_path):
    """240 seeded mutations x (check, simulate): 0 tracebacks, 0 hangs; and the mutations are
    not all refused (some run, so the engine side is exercised too)."""
    (tmp_path / "planar_sliders.toml").write_text((MECH / "planar_sliders.toml").read_text())
    (tmp_path / "spatial_parallelogram.toml").write_text((MECH / "spatial_parallelogram.toml").read_text())
    failures, codes = [], {}
    for k, name, is_mech, text in _cases():
        case_dir = tmp_path / f"case{k}"
        case_dir.mkdir()
        if is_mech:  # the scenes of this mechanism read the mutated file
            path = case_dir / f"{name}.toml"
        else:
            for m in MECHANISMS:
                (case_dir / f"{m}.toml").write_text((MECH / f"{m}.toml").read_text())
            path = case_dir / f"{name}.toml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        runs = {"check": ["check", str(path)],
                "simulate": ["simulate", str(path), "--stop-time", "0.05", "--out", str(case_dir / "out.csv"),
                             "--max-wall-time", WALL_BUDGET]}
        for cmd, argv in runs.items():
            code, secs, _ = _run(argv)
            codes.setdefault(cmd, []).append(code)
            if isinstance(code, Hang):
                failures.append(f"case {k} ({name}) {cmd}: HANG (> {CASE_LIMIT} s)")
            elif isinstance(code, BaseException):
                failures.append(f"case {k} ({name}) {cmd}: {type(code).__name__}: {code}")
            elif code not in ALLOWED_CODES:
                failures.append(f"case {k} ({name}) {cmd}: exit code {code!r}")
    assert not failures, "\n".join(failures[:30])
    assert len(codes["check"]) == N_CASES >= 200
    for cmd in ("check", "simulate"):  # the fuzzing reaches both refusals and runs
        assert 2 in codes[cmd] and {0, 1} & set(codes[cmd]), (cmd, sorted(set(map(str, codes[cmd]))))


def test_mutations_are_deterministic():
    assert [c[3] for c in _cases()[:20]] == [c[3] for c in _cases()[:20]]
    assert len({c[3] for c in _cases()}) > 200  # distinct files


@pytest.mark.parametrize("value", ["nan", "inf", "-1", "0", "1e-300", "1e300", '"x"', "true", "[1]"])
@pytest.mark.parametrize("key", ["tolerance", "step", "max_step", "output_interval", "baumgarte", "friction_tol",
                                 "friction_max_iter"])
def test_every_solver_field_any_value_is_ok_or_refused_by_name(tmp_path, key, value):
    """Each solver field with a hostile value: exit 0 or 2; with 2 the file and field are named."""
    text = (MECH / "planar_f45_wo4.toml").read_text()
    assert "[solver]\n" in text
    (tmp_path / "planar_sliders.toml").write_text((MECH / "planar_sliders.toml").read_text())
    path = tmp_path / "s.toml"
    path.write_text(text.replace("[solver]\n", f"[solver]\n{key} = {value}\n", 1)
                    if f"\n{key} =" not in text else re.sub(rf"^{key} = .*$", f"{key} = {value}", text, flags=re.M))
    code, _, err = _run(["check", str(path)])
    assert code in (0, 2), code
    if code == 2:
        assert f"{path}: solver.{key}:" in err, err
