"""formats.jit.pipeline_memo: numba's pass-dependency analysis kept per pass list, the same answer."""

from __future__ import annotations

import numpy as np
import pytest
from numba.core.compiler import DefaultPassBuilder, Flags, StateDict
from numba.core.compiler_machinery import PassManager

import formats.jit.cache  # noqa: F401  (installs the memo)
from formats.jit import pipeline_memo
from formats.jit.decorators import njit


def _fresh_answer(pm: PassManager) -> dict:
    analyse = PassManager.dependency_analysis
    assert analyse._imutool_memo
    pipeline_memo._ANSWERS.pop(tuple(p for p, _ in pm.passes), None)
    return analyse(pm)


def test_the_memo_gives_numbas_own_answer_once_per_pass_list():
    if not pipeline_memo.install():
        pytest.skip("the memo is off here (IMUTOOL_PIPELINE_MEMO=0, or a numba it was not read against)")
    state = StateDict(func_ir=None, flags=Flags())
    pm = DefaultPassBuilder.define_nopython_pipeline(state)  # finalised: asked once already
    again = DefaultPassBuilder.define_nopython_pipeline(state)
    assert again._analysis is pm._analysis  # the second pipeline reused the first's answer
    fresh = _fresh_answer(pm)
    assert fresh == pm._analysis and fresh is not pm._analysis
    assert any(fresh.values())  # some pass depends on another: a real answer, not an empty one


def test_kernels_compile_and_run_with_the_memo():
    @njit
    def add(a):
        out = np.empty_like(a)
        for i in range(a.shape[0]):
            out[i] = a[i] + 1.0
        return out

    assert np.array_equal(add(np.arange(3.0)), [1.0, 2.0, 3.0])
