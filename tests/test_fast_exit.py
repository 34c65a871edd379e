"""The `imutool` executable (`imutool.cli:run`) ends the process without Python's module teardown: the same outputs,
stdout, stderr and exit status as `main`, the atexit handlers run and the worker threads joined first (a thread pool
never shut down stopped as Python's exit stops it, not waited for forever)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data" / "ship_imu.csv"

PRELUDE = (
    "import atexit, sys, threading, time\n"
    "from pathlib import Path\n"
    "mark = Path(sys.argv.pop(1))\n"
    "atexit.register(lambda: mark.with_suffix('.atexit').write_text('ran'))\n"
    "def late():\n"
    "    time.sleep(1.0)\n"
    "    mark.with_suffix('.thread').write_text('joined')\n"
    "threading.Thread(target=late).start()\n"
    "from concurrent.futures import ThreadPoolExecutor\n"
    "pool = ThreadPoolExecutor(2)  # a pool kept and never shut down: its workers told to stop, no hang\n"
    "pool.submit(time.sleep, 0.01)\n"
)


def _imutool(entry: str, args: list[str], mark: Path, fast: str = "1") -> subprocess.CompletedProcess:
    code = PRELUDE + f"from imutool.cli import {entry}\n{entry}()\n"
    env = dict(os.environ, PYTHONPATH=str(ROOT), IMUTOOL_FAST_EXIT=fast)
    return subprocess.run(
        [sys.executable, "-c", code, str(mark), *args], capture_output=True, text=True, env=env, timeout=300
    )


def test_run_gives_mains_outputs_status_and_exit_work(tmp_path):
    found = {}
    # once first: a kernel compiled on this run (an edited source, a cold cache) is announced on stderr
    _imutool("main", ["filter", str(SAMPLE), "-o", str(tmp_path / "warm.csv")], tmp_path / "warm.mark")
    for entry in ("main", "run"):
        out = tmp_path / f"{entry}.csv"
        mark = tmp_path / f"{entry}.mark"
        r = _imutool(entry, ["filter", str(SAMPLE), "-o", str(out), "--json"], mark)
        assert r.returncode == 0, r.stderr
        summary = json.loads(r.stdout)  # the whole JSON on stdout: flushed before the process ended
        summary.pop("output")
        found[entry] = (out.read_bytes(), summary, r.stderr)
        assert mark.with_suffix(".atexit").read_text() == "ran"  # the atexit handlers ran
        assert mark.with_suffix(".thread").read_text() == "joined"  # a non-daemon thread was waited for
    assert found["run"] == found["main"]


def test_run_keeps_the_exit_status_of_an_error_and_can_be_switched_off(tmp_path):
    for fast in ("1", "0"):
        mark = tmp_path / f"err{fast}.mark"
        r = _imutool("run", ["filter", str(tmp_path / "missing.csv"), "-o", str(tmp_path / "o.csv")], mark, fast)
        assert r.returncode == 2 and "imutool filter: error:" in r.stderr and len(r.stderr.strip().splitlines()) == 1
        assert mark.with_suffix(".atexit").read_text() == "ran"
        mark = tmp_path / f"version{fast}.mark"
        r = _imutool("run", ["--version"], mark, fast)
        assert r.returncode == 0 and "imutool, version" in r.stdout
        assert mark.with_suffix(".thread").read_text() == "joined"  # (the command is over long before the thread)


def test_the_console_script_is_run():
    text = (ROOT / "pyproject.toml").read_text()
    assert 'imutool = "imutool.cli:run"' in text


def test_a_standard_output_that_cannot_be_written_is_no_success(tmp_path):
    # stdout on /dev/full (a full disk): Python's exit says so with status 120; the fast exit too, not 0
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full on this system")
    code = "import sys\nsys.stdout = open('/dev/full', 'w', buffering=4096)\nfrom imutool.cli import run\nrun()\n"
    env = dict(os.environ, PYTHONPATH=str(ROOT), IMUTOOL_FAST_EXIT="1")
    done = subprocess.run([sys.executable, "-c", code, "--help"], capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode != 0, done
