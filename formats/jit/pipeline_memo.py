"""A memo for numba's pass-dependency analysis: worked out once per pass list, not once per function compiled.

Every function numba compiles builds its pipeline of compiler passes and works out, for each pass, every analysis
it depends on transitively (``PassManager.dependency_analysis``, from each pass's declared requirements). The
answer depends only on the list of passes, which is the same for every function of a kind (numba's nopython
pipeline, its untyped pipeline for inlining), yet it was 1.8 % of a cold first ``filter``'s samples (py-spy, one
process, 2026-12-06): ~60 functions and their inlining pipelines each asked again.

:func:`install` keeps the answer per tuple of pass classes. numba only hands the answer to each pass (in numba 0.68
nothing changes it, and only one pass reads it, for show), so one dict serves every pipeline of the same passes.
Installed only over the numba versions whose ``PassManager`` it was checked against; for any other it stays off and
numba works as shipped. ``IMUTOOL_PIPELINE_MEMO=0`` switches it off.
"""

from __future__ import annotations

import os
from typing import Any

import numba

ENV = "IMUTOOL_PIPELINE_MEMO"
CHECKED_NUMBA = ((0, 58), (0, 68))  # numba (major, minor) range whose PassManager.dependency_analysis was read

_ANSWERS: dict[tuple, dict] = {}


def _numba_checked() -> bool:
    try:
        version = tuple(int(p) for p in numba.__version__.split(".")[:2])
    except ValueError:
        return False
    return CHECKED_NUMBA[0] <= version <= CHECKED_NUMBA[1]


def install() -> bool:
    """Wrap ``PassManager.dependency_analysis`` with the memo (once). False where it is not installed."""
    if os.environ.get(ENV, "") == "0" or not _numba_checked():
        return False
    try:
        from numba.core.compiler_machinery import PassManager
    except ImportError:
        return False
    analyse = getattr(PassManager, "dependency_analysis", None)
    if analyse is None or getattr(analyse, "_imutool_memo", False):
        return analyse is not None

    def dependency_analysis(self) -> Any:
        try:
            key = tuple(p for p, _ in self.passes)
            hash(key)
        except (TypeError, ValueError):
            return analyse(self)
        answer = _ANSWERS.get(key)
        if answer is None:
            answer = _ANSWERS[key] = analyse(self)
        return answer

    dependency_analysis._imutool_memo = True  # type: ignore[attr-defined]
    PassManager.dependency_analysis = dependency_analysis
    return True
