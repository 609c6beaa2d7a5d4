"""Progress bars (overcon.progress, tqdm): drawn on a terminal, absent when stderr is not one (CI
logs, pipes), so what the commands print elsewhere is unchanged."""
from __future__ import annotations

import fcntl
import os
import pty
import struct
import termios
import subprocess
import sys

from overcon import progress


def test_no_bar_when_stderr_is_not_a_terminal():
    with progress.bar(5, "runs") as b:  # pytest captures stderr: not a terminal
        b.update()
    assert isinstance(b, progress._Quiet) and b.n == 1


def test_a_bar_on_a_terminal():
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a terminal 100 columns wide
    code = ("from overcon import progress\nprogress.DELAY = 0\n"
            "with progress.bar(3, 'FMU runs', 'run') as b:\n    [b.update() for _ in range(3)]\n"
            "import sys; print(type(b).__module__, file=sys.stderr)\n")
    p = subprocess.Popen([sys.executable, "-c", code], stderr=slave, stdout=subprocess.DEVNULL)
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 4096)
        except OSError:
            break
        if not data:
            break
        chunks.append(data)
    p.wait(timeout=60)
    os.close(master)
    text = b"".join(chunks).decode(errors="replace")
    assert p.returncode == 0 and "FMU runs" in text and "/3 [" in text and "tqdm" in text, text


def test_commands_in_a_pipe_draw_no_bar(tmp_path):
    p = subprocess.run([sys.executable, "-m", "overcon.cli", "simulate", "mechanisms/planar_f45_wo4.toml", "--out",
                        str(tmp_path / "r.csv"), "--stop-time", "0.5"], capture_output=True, text=True,
                       cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))), timeout=120)
    assert p.returncode == 0 and "\r" not in p.stderr and "simulate:" not in p.stderr
