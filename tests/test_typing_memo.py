"""numba's call typing asked once per distinct question (formats/jit/typing_memo.py): the same machine code, sooner.

The memo is only sound if what numba compiles is unchanged. The tests compile the same functions in two fresh
processes, with and without it, and compare the machine code, symbol names aside (numba mangles a hash of the
flags into them, which differs from process to process). The functions mix what the memo keeps (arithmetic,
comparisons, ``math``) with what it must not keep (``max``/``min`` and ``np.empty`` are ``@overload``-ed: numba
compiles them once per flag set and looks the implementation up by argument types only), under two flag sets.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import EKF_KERNEL_ASM, normalized_asm

from formats.jit import typing_memo

ROOT = Path(__file__).resolve().parents[1]

KERNELS = textwrap.dedent(
    """
    import math
    import numpy as np
    from numba import njit

    @njit(cache=False)
    def clamp(x, lo, hi):
        return min(max(x, lo), hi)

    @njit(cache=False, fastmath=True, error_model="numpy")
    def fast(a, k):
        out = np.empty(a.shape[0])
        s = 0.0
        for i in range(a.shape[0]):
            v = a[i] * 2.0 + 1.0
            v = v * v - a[i] / 3.0
            s += clamp(v, -1.0, 1.0) + math.sqrt(abs(v)) + max(v, 0.5)
            out[i] = s * k + i
        return out

    @njit(cache=False)
    def plain(a, k):
        out = np.empty(a.shape[0])
        s = 0.0
        for i in range(a.shape[0]):
            v = a[i] * 2.0 + 1.0
            v = v * v - a[i] / 3.0
            s += clamp(v, -1.0, 1.0) + math.sqrt(abs(v)) + min(v, 0.5)
            out[i] = s * k + (i % 3)
        return out
    """
)

DUMP = textwrap.dedent(
    """
    import sys
    sys.path.insert(0, sys.argv[1])
    import numpy as np
    import formats.jit.cache  # installs the memo unless switched off
    from formats.jit import typing_memo
    import kernels_for_memo as k
    a = np.linspace(-2.0, 2.0, 7)
    k.fast(a, 3); k.plain(a, 3)
    print("memo", typing_memo.is_installed(), len(typing_memo._memo))
    for f in (k.fast, k.plain, k.clamp):
        for sig in f.signatures:
            print(f.inspect_asm(sig))
    """
)


def _dump(tmp_path: Path, memo: str) -> tuple[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update({typing_memo.ENV: memo, "NUMBA_CACHE_DIR": str(tmp_path / f"cache{memo}")})
    r = subprocess.run(
        [sys.executable, "-c", DUMP, str(tmp_path)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 0, r.stderr
    first, _, rest = r.stdout.partition("\n")
    return first, normalized_asm(rest)


def test_the_same_machine_code_with_and_without_the_memo(tmp_path):
    if not typing_memo.supported():
        pytest.skip(f"the memo is off on numba {typing_memo.numba.__version__}")
    (tmp_path / "kernels_for_memo.py").write_text(KERNELS)
    on_head, on = _dump(tmp_path, "1")
    off_head, off = _dump(tmp_path, "0")
    assert on_head.startswith("memo True") and int(on_head.split()[2]) > 20, on_head  # it kept answers
    assert off_head == "memo False 0", off_head
    assert on.count("SYM") > 10 and len(on) > 5000  # real code was compared
    assert on == off


def test_off_by_the_switch_and_on_an_unchecked_numba(monkeypatch):
    assert typing_memo.install() is typing_memo.is_installed()
    monkeypatch.setattr(typing_memo, "numba_version", lambda: (0, 99))
    assert not typing_memo.supported()
    monkeypatch.setattr(typing_memo, "numba_version", lambda: (0, 57))
    assert not typing_memo.supported()
    env = dict(os.environ, **{typing_memo.ENV: "0"})
    check = (
        "import formats.jit.cache; from formats.jit import typing_memo as m; "
        "from numba.core.types.functions import BaseFunction as B; "
        "print(m.is_installed(), hasattr(B.get_call_type, '__wrapped__'))"
    )
    r = subprocess.run([sys.executable, "-c", check], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.split() == ["False", "False"], (r.stdout, r.stderr)


def test_uninstall_gives_numba_its_own_typing_back():
    if not typing_memo.supported():
        pytest.skip("the memo is off on this numba")
    from numba.core.types.functions import BaseFunction

    was = typing_memo.is_installed()
    typing_memo.install()
    ours = BaseFunction.get_call_type
    assert ours.__wrapped__ is not ours
    typing_memo.uninstall()
    try:
        assert BaseFunction.get_call_type is ours.__wrapped__ and not typing_memo.is_installed()
    finally:
        if was:
            typing_memo.install()


@pytest.mark.slow
def test_the_ekf_kernel_is_the_same_machine_code_with_and_without_the_memo(tmp_path):
    """~40 s: two cold compiles of the EKF kernel, at once."""
    if not typing_memo.supported():
        pytest.skip("the memo is off on this numba")
    procs = []
    for memo in ("1", "0"):
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        env.update({typing_memo.ENV: memo, "NUMBA_CACHE_DIR": str(tmp_path / memo), "IMUTOOL_KERNEL_WARM": "0"})
        procs.append(
            subprocess.Popen(
                [sys.executable, "-c", EKF_KERNEL_ASM],
                cwd=ROOT,
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
        )
    outs = [p.communicate(timeout=900) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1][-2000:] for o in outs]
    on, off = (normalized_asm(o[0]) for o in outs)
    assert len(on) > 100_000
    assert on == off
