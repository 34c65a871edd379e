"""Two processes sharing a cold compile compile each function once (formats/jit/claims.py).

The quick tests drive the claim files directly; the others run real compiles in subprocesses: the command waits
for (and loads) a function the second process is compiling, and the second process skips one the command has
claimed, then takes over a claim whose process has ended.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from formats.jit import claims

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def sleeper():
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    yield proc
    proc.kill()
    proc.wait()


@pytest.fixture(autouse=True)
def _no_sharing_left():
    yield
    claims.stop_sharing()


def test_an_unclaimed_function_is_claimed_then_released(tmp_path):
    path = claims.claim_path(str(tmp_path / "k.f-1.py311.nbi"), ("float64",))
    assert claims.claim_or_wait(path, lambda: None) is None  # ours: compile it
    assert path.read_text() == str(os.getpid())
    assert not claims.claimed_by_other(path)
    claims.release(path)
    assert not path.exists()


def test_a_claim_of_a_running_process_is_waited_for(tmp_path, sleeper):
    path = claims.claim_path(str(tmp_path / "k.f-1.py311.nbi"), ("float64",))
    path.write_text(str(sleeper.pid))
    claims.share_with(sleeper.pid, lambda: sleeper.poll() is None)
    assert claims.claimed_by_other(path)
    asked = []

    def load():  # in the cache at the third look
        asked.append(1)
        return "loaded" if len(asked) >= 3 else None

    assert claims.claim_or_wait(path, load) == "loaded"
    assert path.read_text() == str(sleeper.pid)  # still the other's


def test_a_claim_of_an_ended_process_is_taken_over(tmp_path, sleeper):
    path = claims.claim_path(str(tmp_path / "k.f-1.py311.nbi"), ("float64",))
    path.write_text(str(sleeper.pid))
    claims.share_with(sleeper.pid, lambda: sleeper.poll() is None)
    sleeper.kill()
    sleeper.wait()
    assert not claims.claimed_by_other(path)
    assert claims.claim_or_wait(path, lambda: None) is None
    assert path.read_text() == str(os.getpid())
    claims.release_all()
    assert not path.exists()


def _env(tmp_path: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "IMUTOOL_KERNEL_TIMES")}
    env.update(PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(tmp_path / "numba"), IMUTOOL_KERNEL_WARM="1")
    return env


WAITS = textwrap.dedent(
    """
    import time
    from formats.jit import claims
    from formats.jit.warm import _index_file, argument_types, warm_in_background
    from imutool.filter_warm import AFTER_THE_EKF
    from imutool.gyro_check import pair_discrepancy_kernel as kernel
    entry = AFTER_THE_EKF[0]
    proc = warm_in_background(entry, [entry])  # the second process compiles the kernel (~1-3 s)
    assert proc is not None and claims.sharing()
    args = argument_types(entry[2])
    claim = claims.claim_path(str(_index_file(kernel)), args)
    while not claim.exists() and proc.poll() is None:  # the other has claimed it (it compiles for ~1-3 s)
        time.sleep(0.002)
    seen = claim.exists()
    kernel.compile(args)  # here while the other compiles it: waits, and loads its copy
    print(seen, sum(kernel.stats.cache_misses.values()), sum(kernel.stats.cache_hits.values()), proc.wait())
    """
)


def test_the_command_waits_for_what_the_second_process_is_compiling(tmp_path):
    r = subprocess.run(
        [sys.executable, "-c", WAITS], cwd=ROOT, env=_env(tmp_path), capture_output=True, text=True, timeout=600
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["True", "0", "1", "0"], r.stdout  # claimed there; no miss: not compiled here
    assert list((tmp_path / "numba").rglob("*.claim")) == []  # released once saved


SKIPS = textwrap.dedent(
    """
    import subprocess, sys
    from formats.jit import claims
    from formats.jit.warm import _index_file, argument_types, compile_entries, is_cached
    from imutool.filter_warm import AFTER_THE_EKF
    from imutool.gyro_check import pair_discrepancy_kernel as kernel
    entry = AFTER_THE_EKF[0]
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])  # the command, compiling it
    claims.share_with(other.pid, lambda: other.poll() is None)
    claim = claims.claim_path(str(_index_file(kernel)), argument_types(entry[2]))
    claim.write_text(str(other.pid))
    print(compile_entries([entry]), is_cached(kernel))  # skipped: the other one's
    other.kill(); other.wait()
    print(compile_entries([entry]), is_cached(kernel), claim.exists())  # its process ended: compiled here
    """
)


def test_the_second_process_skips_what_the_command_has_claimed(tmp_path):
    r = subprocess.run(
        [sys.executable, "-c", SKIPS], cwd=ROOT, env=_env(tmp_path), capture_output=True, text=True, timeout=600
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["0", "False", "1", "True", "False"], r.stdout


MEANWHILE = textwrap.dedent(
    """
    import subprocess, sys
    from numba.core.compiler import Flags
    from numba.core.cpu import FastMathOptions
    from numba.core.targetconfig import ConfigStack
    from formats.jit import claims
    from formats.jit.warm import CSV_WRITER, _one_at_a_time, argument_types
    import formats.csv_engine as engine
    sig = argument_types(CSV_WRITER[2])
    if sys.argv[1] == "waiting":  # compiled while waiting inside a compile with other flags (the EKF kernel's)
        other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
        claims.share_with(other.pid, lambda: other.poll() is None)
        claims.while_waiting(_one_at_a_time([CSV_WRITER]))
        claim = claims.claim_path(sys.argv[2], ("float64",))
        claim.write_text(str(other.pid))
        outer = Flags()
        outer.fastmath = FastMathOptions(True)
        outer.error_model = "numpy"
        with ConfigStack().enter(outer):
            assert claims.claim_or_wait(claim, lambda: engine.format_block.signatures or None)
        other.kill()
    else:
        engine.format_block.compile(sig)
    print(engine.format_block.inspect_asm(sig))
    """
)


def test_a_kernel_compiled_while_waiting_is_the_kernel_compiled_alone(tmp_path):
    """The command compiles a later kernel while it waits inside the EKF kernel's compile: with the flags it has
    when called on its own (numba would give it the EKF's fastmath and error model), so the same machine code."""
    from conftest import normalized_asm

    out = {}
    for how in ("alone", "waiting"):
        env = dict(_env(tmp_path), NUMBA_CACHE_DIR=str(tmp_path / how))
        r = subprocess.run(
            [sys.executable, "-c", MEANWHILE, how, str(tmp_path / "k.f-1.py311.nbi")],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert r.returncode == 0, r.stderr
        out[how] = normalized_asm(r.stdout)
    assert len(out["alone"]) > 10_000
    assert out["waiting"] == out["alone"]
