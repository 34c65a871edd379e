"""Shared test fixtures: the real recordings in ../shared/data (skipped with a reason where absent)."""

from __future__ import annotations

import os
import re
import textwrap
from pathlib import Path

import pytest
from hypothesis import settings

# property tests: reproducible in CI (the same examples every run, so a change cannot fail or pass by chance);
# free exploration on a developer's machine. Examples that once failed are kept as explicit @example cases.
settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("IMUTOOL_SHARED_DATA", ROOT.parent / "shared" / "data"))


def shared_data(*parts: str) -> Path:
    """Path to a file in ../shared/data, or skip the test with a clear reason."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"real recording not available: {p} (../shared/data is absent in a fresh clone)")
    return p


@pytest.fixture
def shared():
    return shared_data


def run_main(args, capsys) -> tuple[int, str, str]:
    """imutool's console entry point in-process (the real error handling): (exit status, stdout, stderr)."""
    from imutool.cli import main

    with pytest.raises(SystemExit) as e:
        main([str(a) for a in args])
    out = capsys.readouterr()
    return e.value.code, out.out, out.err


def run_cli_on_pty(args: list[str], cwd, env: dict) -> tuple[int, str, str]:
    """`imutool ARGS` in a subprocess with stderr on a pseudo-terminal (a real tty, as on deck) and stdout on a
    pipe; returns (exit status, stdout, what the terminal showed)."""
    import pty
    import subprocess
    import sys

    master, slave = pty.openpty()
    try:
        p = subprocess.Popen(
            [sys.executable, "-c", "from imutool.cli import main; main()", *args],
            cwd=cwd,
            stdout=subprocess.PIPE,
            stderr=slave,
            stdin=subprocess.DEVNULL,
            env=env,
        )
        os.close(slave)
        chunks = []
        while True:
            try:
                data = os.read(master, 65536)
            except OSError:  # EIO: the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        out = p.stdout.read().decode()
        p.wait(timeout=120)
        return p.returncode, out, b"".join(chunks).decode(errors="replace")
    finally:
        os.close(master)


@pytest.fixture
def copy_sizes(monkeypatch) -> list[int]:
    """The bytes of each copy the CSV writer makes behind its final header (``formats.csv.copy_range``), in order;
    the copies still happen."""
    import formats.csv as fcsv

    sizes: list[int] = []
    real_copy = fcsv.copy_range

    def counting_copy(src, dst, offset):
        before = dst.tell()
        real_copy(src, dst, offset)
        sizes.append(dst.tell() - before)

    monkeypatch.setattr(fcsv, "copy_range", counting_copy)
    return sizes


def normalized_asm(text: str) -> str:
    """Machine code with numba's mangled names numbered by first appearance (their flag hashes vary per process)."""
    names: dict[str, str] = {}
    text = re.sub(r"_ZN[0-9A-Za-z_$]+", lambda m: names.setdefault(m.group(0), f"SYM{len(names)}"), text)
    return re.sub(r'(\.size\s+"\.const\.missing Environment: SYM\d+"), \d+', r"\1", text)  # the names' lengths


# a cold compile of the EKF kernel in a fresh process (its cache folder and switches in the environment), printing the
# kernel's machine code: tests/test_typing_memo.py and tests/test_kernel_warm.py compare such dumps
EKF_KERNEL_ASM = textwrap.dedent(
    """
    import numpy as np
    from imutool.attitude import EkfParams
    from imutool.attitude.kernel import ekf_kernel
    from imutool.attitude.run import run_ekf
    t = np.arange(400) / 200.0
    g = np.zeros((400, 3)); a = np.zeros((400, 3)); a[:, 2] = -9.81; m = np.tile([20.0, 0.0, 45.0], (400, 1))
    run_ekf(t, g, a, m, EkfParams())
    for sig in ekf_kernel.signatures:
        print(ekf_kernel.inspect_asm(sig))
    """
)
