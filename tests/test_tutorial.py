"""The tutorial (docs/tutorial.md) cannot rot: every file it shows is written, every command it
shows is run in that order in an empty directory, and what each prints (stdout and stderr, as a
terminal shows them) is compared with the page, timings and the compiled library's path
normalised. ``python tests/test_tutorial.py --write`` runs the commands and writes their output
into the page (after a deliberate change of what they print)."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration  # builds and runs FMUs

PAGE = Path(__file__).resolve().parent.parent / "docs" / "tutorial.md"
FILE_BLOCK = re.compile(r"```\{code-block\} toml\n:caption: (?P<name>[\w.]+)\n\n(?P<text>.*?)```\n", re.S)
CONSOLE_BLOCK = re.compile(r"```console\n(?P<body>.*?)```\n", re.S)


def steps(page: str) -> list[tuple]:
    """In page order: ("file", name, text) and ("command", command line, expected output, span of
    the output in the page)."""
    out = []
    for m in FILE_BLOCK.finditer(page):
        out.append((m.start(), ("file", m["name"], m["text"])))
    for m in CONSOLE_BLOCK.finditer(page):
        body = m["body"]
        assert body.startswith("$ "), f"a console block starts with its command: {body[:60]!r}"
        command, _, expected = body[2:].partition("\n")
        start = m.start("body") + 2 + len(command) + 1
        out.append((m.start(), ("command", command, expected, (start, m.end("body")))))
    return [s for _, s in sorted(out, key=lambda x: x[0])]


def normalise(text: str) -> str:
    """Timings (any ``<number with a decimal point> s``) and the compiled library's path."""
    text = re.sub(r"\d+\.\d+ s\b", "<t> s", text)
    text = re.sub(r"\([^()\n]*libovercore\.so\)", "(libovercore.so)", text)
    return text.rstrip("\n")


def run(command: str, cwd: Path) -> subprocess.CompletedProcess:
    """One command of the page: ``overcon ...`` is this interpreter's ``-m overcon.cli``; output
    unbuffered, so stdout and stderr interleave as on a terminal."""
    args = command.split()
    assert args[0] == "overcon", command
    env = dict(os.environ, PYTHONUNBUFFERED="1", COLUMNS="100")
    return subprocess.run([sys.executable, "-m", "overcon.cli", *args[1:]], cwd=cwd, env=env, text=True,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=300)


def play(page: str, cwd: Path):
    """Yield (command, expected, got, span) for every command of the page, files written first."""
    for step in steps(page):
        if step[0] == "file":
            (cwd / step[1]).write_text(step[2], encoding="utf-8")
            continue
        _, command, expected, span = step
        yield command, expected, run(command, cwd).stdout, span


def test_the_page_has_files_and_commands():
    kinds = [s[0] for s in steps(PAGE.read_text(encoding="utf-8"))]
    assert kinds.count("file") == 3 and kinds.count("command") >= 8


def test_every_command_prints_what_the_page_shows(tmp_path):
    page = PAGE.read_text(encoding="utf-8")
    for command, expected, got, _ in play(page, tmp_path):
        assert normalise(got) == normalise(expected), f"$ {command}\n--- page\n{expected}\n--- printed\n{got}"
    assert (tmp_path / "comparison" / "report.md").is_file()
    assert (tmp_path / "block.png").stat().st_size > 1000


def write(tmp: Path) -> None:
    """Run the page's commands and put what they print into it (the library path shortened)."""
    page = PAGE.read_text(encoding="utf-8")
    edits = []
    for _, _, got, span in play(page, tmp):
        edits.append((span, re.sub(r"\([^()\n]*libovercore\.so\)", "(libovercore.so)", got)))
    for (a, b), text in reversed(edits):
        page = page[:a] + text + page[b:]
    PAGE.write_text(page, encoding="utf-8")


if __name__ == "__main__":
    import tempfile

    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python tests/test_tutorial.py --write")
    with tempfile.TemporaryDirectory() as d:
        write(Path(d))
