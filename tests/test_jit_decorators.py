"""formats.jit.decorators: numba's njit without the wrappers numba would build and never use."""

from __future__ import annotations

import numpy as np
import pytest
from numba.core.typing import templates

from formats.jit.decorators import CompiledOnlyDispatcher, njit


@njit(no_cpython_wrapper=True)
def _twice(x):
    return 2.0 * x


@njit
def _calls_twice(a):
    out = np.empty_like(a)
    for i in range(a.shape[0]):
        out[i] = _twice(a[i])
    return out


def test_a_function_without_python_entry_runs_from_compiled_code_and_refuses_python():
    assert isinstance(_twice, CompiledOnlyDispatcher)
    assert np.array_equal(_calls_twice(np.arange(3.0)), [0.0, 2.0, 4.0])
    with pytest.raises(TypeError, match="without a Python entry"):
        _twice(1.0)  # numba's own dispatcher would jump to a null address here (a segmentation fault)
    assert _twice.py_func(1.5) == 3.0


def test_no_c_entry_by_default_and_a_given_option_wins():
    assert _calls_twice.targetoptions["no_cfunc_wrapper"] is True

    @njit(no_cfunc_wrapper=False)
    def with_c_entry(x):
        return x + 1.0

    assert with_c_entry.targetoptions["no_cfunc_wrapper"] is False
    assert with_c_entry(1.0) == 2.0
    assert templates._OverloadFunctionTemplate._get_jit_decorator._imutool_no_cfunc  # numba's overloads too


def test_the_ekf_sections_have_no_python_entry():
    """The kernel's sections and helpers (layout.INLINED / CALLED) are compiled only into kernels."""
    import importlib

    from imutool.filter_warm import EKF_SECTIONS, HEADING_SECTION

    for module, name, _ in (*EKF_SECTIONS, HEADING_SECTION):
        assert isinstance(getattr(importlib.import_module(module), name), CompiledOnlyDispatcher), name
