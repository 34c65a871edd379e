"""Progress: a tqdm bar on stderr with done/total and ETA when stderr is a terminal; silent when piped or --quiet."""

from __future__ import annotations

import io
import os
import subprocess
import sys

import pytest
from conftest import run_cli_on_pty

from imutool.progress import Bar, chunk_ranges, estimate_rows, report, stages


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_bar_on_a_terminal_shows_done_total_and_eta():
    out = _Tty()
    with Bar("work", total=10, unit="rows", stream=out) as b:
        assert b.shown
        for done in (3, 6, 10):
            b._tq.refresh()
            b(done)
            b._tq.refresh()
    text = out.getvalue()
    assert "work" in text and "3/10" in text and "10/10" in text
    assert "<" in text  # tqdm's "[elapsed<remaining" ETA field


def test_bar_silent_when_not_a_terminal_or_quiet():
    for stream, quiet in ((io.StringIO(), False), (_Tty(), True)):
        with Bar("work", total=5, stream=stream, quiet=quiet) as b:
            assert not b.shown
            b(5)
            assert b.done == 5  # still counts
        assert stream.getvalue() == ""


def test_library_callbacks_and_chunks():
    seen = []
    assert list(chunk_ranges(10, 4, lambda d, t: seen.append((d, t)))) == [(0, 4), (4, 8), (8, 10)]
    assert seen == [(4, 10), (8, 10), (10, 10)]
    report(None, 1, 2)  # no callback: nothing happens
    with stages("x", ["a", "b"]) as s:
        s.stage("a")
        s.stage("b")
        assert s.done == 1
    assert s.done == 2


def test_estimate_rows(tmp_path):
    p = tmp_path / "a.csv"
    p.write_text("time,x\n" + "".join(f"{i:05d},{i * 2:06d}\n" for i in range(5000)))
    est = estimate_rows(p, sample_bytes=4096)
    assert 4500 < est < 5600
    assert estimate_rows(tmp_path / "missing.csv") is None


def _run(args, cwd, tty: bool) -> tuple[int, str, str]:
    """Run the CLI with stderr on a pseudo-terminal (tty=True) or a pipe; stdout always a pipe."""
    cmd = [sys.executable, "-c", "from imutool.cli import main; main()", *args]
    env = {**os.environ, "COLUMNS": "100"}
    if not tty:
        r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=120, env=env)
        return r.returncode, r.stdout, r.stderr
    return run_cli_on_pty(args, cwd, env)


@pytest.mark.slow
def test_cli_bar_on_a_pty_and_silent_when_piped(tmp_path):
    args = ["simulate", "ship-roll", "--duration", "20", "-o"]
    rc, out, err = _run([*args, "a.csv"], tmp_path, tty=True)
    assert rc == 0, err
    assert "simulate" in err and "/2" in err and "step" in err, err  # stage bar: done/total steps
    assert "rows: " in out  # the summary still goes to stdout
    rc, out, err = _run([*args, "b.csv"], tmp_path, tty=False)
    assert rc == 0 and err == "", err
    assert "rows: " in out
    rc, out, err = _run([*args, "c.csv", "--quiet"], tmp_path, tty=True)
    assert rc == 0 and "step" not in err, err


@pytest.mark.slow
def test_streamed_convert_counts_rows_on_a_pty(tmp_path):
    rc, _, err = _run(["simulate", "static", "--duration", "60", "-o", "s.csv", "-q"], tmp_path, tty=False)
    assert rc == 0, err
    rc, _, err = _run(["convert", "s.csv", "t.csv", "--chunk-rows", "2000"], tmp_path, tty=True)
    assert rc == 0, err
    assert "converting" in err and "rows" in err and "<" in err, err
