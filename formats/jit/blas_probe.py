"""numba's start-up without importing scipy.linalg: its BLAS probe answered by finding the module, not importing it.

The first time a process calls (or loads from the cache) any numba kernel, numba's CPU target loads its
implementations, and one of them, ``numba.np.arraymath``, asks at import whether a BLAS is there for ``np.dot`` & co
(``_check_blas`` → ``numba.np.linalg.ensure_blas``) by importing ``scipy.linalg.cython_blas``: all of
``scipy.linalg``, and through scipy's array-API layer ``numpy.f2py`` and ``numpy.testing``. That was ~0.15 s CPU of
every command's start on the project's 2-core machine (``python -X importtime``: 150 of the ~800 ms a 2 000-row
``filter`` takes), for an answer no kernel of the default paths uses.

:func:`install` (from :mod:`formats.jit.cache`, before any kernel runs) wraps numba's CPU context's first
``load_additional_registries`` so that, just before numba imports ``numba.np.arraymath``, ``ensure_blas`` becomes
:func:`_ensure_blas_found`: the same question answered by finding ``scipy/linalg/cython_blas`` among scipy's
files — where it is not found there (no scipy, or a scipy that an import hook supplies) numba's own import decides,
its ``ImportError`` included — followed by numba's own check that scipy's BLAS integer width is the one numba was
built for. (A ``cython_blas`` file that is there but cannot load is found by the first kernel that calls BLAS, not at
start-up.) Nothing else changes: a kernel that uses ``np.linalg`` is compiled as before
(numba's LAPACK probe still imports), and numba's compiled BLAS/LAPACK wrappers import ``scipy.linalg.cython_blas``
themselves at their first call, so ``scipy.linalg`` is imported when a kernel needs it and not before.
Where ``scipy.linalg`` is already imported the probe imports as numba's does (it costs nothing then).

Installed only over the numba versions whose probe was read (:data:`CHECKED_NUMBA`), and only while
``numba.np.arraymath`` is not imported yet; ``IMUTOOL_BLAS_PROBE=0`` switches it off (numba as shipped).
"""

from __future__ import annotations

import importlib.machinery
import os
import sys
from pathlib import Path

from formats.jit.typing_memo import numba_version

ENV = "IMUTOOL_BLAS_PROBE"
CHECKED_NUMBA = ((0, 58), (0, 68))  # numba (major, minor) whose arraymath._check_blas / linalg.ensure_blas were read
_installed: list[bool] = []


def cython_blas_found() -> bool:
    """True when ``scipy.linalg.cython_blas`` is among scipy's files (an extension module), found without
    importing ``scipy.linalg``."""
    spec = importlib.machinery.PathFinder.find_spec("scipy")
    if spec is None or not spec.submodule_search_locations:
        return False
    for folder in spec.submodule_search_locations:
        linalg = Path(folder) / "linalg"
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            if (linalg / f"cython_blas{suffix}").is_file():
                return True
    return False


def _ensure_blas_found() -> None:
    """numba's ``ensure_blas`` without the import: ImportError without scipy's BLAS, numba's width check after."""
    from numba.np import linalg

    if "scipy.linalg" in sys.modules:
        import scipy.linalg.cython_blas  # noqa: F401  (imported already: free)
    elif not cython_blas_found():  # not among scipy's files (none, or a scipy another finder supplies): numba's probe
        try:
            import scipy.linalg.cython_blas  # noqa: F401
        except ImportError:
            raise ImportError("scipy 0.16+ is required for linear algebra") from None
    width_check = getattr(linalg, "_check_lapack_int_width", None)
    if width_check is not None:
        width_check()


def install() -> bool:
    """Answer numba's BLAS probe without importing scipy.linalg (once per process); False when off, not supported,
    or too late (``numba.np.arraymath`` imported already)."""
    if _installed:
        return True
    if os.environ.get(ENV, "1").strip() == "0" or not (CHECKED_NUMBA[0] <= numba_version() <= CHECKED_NUMBA[1]):
        return False
    if "numba.np.arraymath" in sys.modules:
        return False
    try:
        from numba.core.cpu import CPUContext
    except ImportError:
        return False
    original = CPUContext.load_additional_registries

    def load_additional_registries(self):
        CPUContext.load_additional_registries = original  # the first call only
        if "numba.np.arraymath" not in sys.modules:
            from numba.np import linalg

            if callable(getattr(linalg, "ensure_blas", None)):
                linalg.ensure_blas = _ensure_blas_found
        return original(self)

    CPUContext.load_additional_registries = load_additional_registries
    _installed.append(True)
    return True
