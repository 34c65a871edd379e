"""numba's start-up without importing scipy.linalg (formats/jit/blas_probe.py): kernels run as before, and a kernel
that uses np.linalg still gets scipy's BLAS/LAPACK, compiled or loaded from the cache.

Each case runs in a fresh process (the probe acts at numba's first context load, once per process).
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from formats.jit import blas_probe

ROOT = Path(__file__).resolve().parents[1]

KERNELS = textwrap.dedent(
    """
    import numpy as np
    import formats.jit.cache  # noqa: F401  (installs the probe unless switched off)
    from numba import njit

    @njit(cache=True)
    def plain(a):
        return a.sum() * 2.0

    @njit(cache=True)
    def algebra(a, b):
        return np.dot(a, b), np.linalg.solve(a, b), np.linalg.norm(a)
    """
)

RUN = textwrap.dedent(
    """
    import sys
    sys.path.insert(0, sys.argv[1])
    sys.path.insert(0, sys.argv[2])
    import numpy as np
    import kernels_for_probe as k
    a = np.array([[2.0, 1.0], [1.0, 3.0]])
    b = np.array([[1.0, 0.5], [0.0, 1.0]])
    assert k.plain(a) == 14.0
    print("after a plain kernel, scipy.linalg imported:", "scipy.linalg" in sys.modules)
    d, s, n = k.algebra(a, b)
    assert np.allclose(d, a @ b) and np.allclose(s, np.linalg.solve(a, b)) and np.isclose(n, np.linalg.norm(a))
    print("np.linalg in a kernel: right")
    """
)


def _run(tmp_path: Path, probe: str) -> str:
    (tmp_path / "kernels_for_probe.py").write_text(KERNELS)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update({blas_probe.ENV: probe, "NUMBA_CACHE_DIR": str(tmp_path / f"cache{probe}")})
    r = subprocess.run(
        [sys.executable, "-c", RUN, str(ROOT), str(tmp_path)], capture_output=True, text=True, env=env, timeout=600
    )
    assert r.returncode == 0, r.stderr
    return r.stdout


@pytest.mark.skipif(not blas_probe.cython_blas_found(), reason="scipy without cython_blas")
def test_kernels_start_without_scipy_linalg_and_linalg_still_works(tmp_path):
    compiled = _run(tmp_path, "1")  # compiled in this process
    assert "scipy.linalg imported: False" in compiled
    assert "np.linalg in a kernel: right" in compiled
    cached = _run(tmp_path, "1")  # loaded from the cache: numba's wrappers import scipy's BLAS at their first call
    assert "scipy.linalg imported: False" in cached
    assert "np.linalg in a kernel: right" in cached
    # switched off: numba as shipped, which imports scipy.linalg when its first kernel runs
    shipped = _run(tmp_path, "0")
    assert "scipy.linalg imported: True" in shipped
    assert "np.linalg in a kernel: right" in shipped


def test_blas_found_where_scipy_has_it():
    import scipy.linalg.cython_blas as cb

    assert blas_probe.cython_blas_found() == Path(cb.__file__).is_file()
