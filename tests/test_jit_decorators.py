"""formats.jit.decorators: numba's njit without the wrappers numba would build and never use."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

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
        out[i] = min(_twice(a[i]), 1e9)
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
    # numba's own overloads that a kernel called (np.empty_like, min) were built without their C entry too
    _calls_twice(np.arange(2.0))
    impls = [
        disp
        for cls in templates._OverloadFunctionTemplate.__subclasses__()
        if getattr(cls, "key", None) in (np.empty_like, min)
        for disp, _ in cls._impl_cache.values()
        if disp is not None
    ]
    assert impls and all(d.targetoptions.get("no_cfunc_wrapper") for d in impls), impls


def test_numba_disable_jit_gives_the_python_functions_back(tmp_path):
    """NUMBA_DISABLE_JIT=1 (numba's way to debug a kernel in Python): a function without a Python entry is plain
    Python too, so a kernel calling it runs."""
    code = (
        "from formats.jit.decorators import njit\n"
        "@njit(no_cpython_wrapper=True)\n"
        "def inner(x):\n    return x + 1\n"
        "@njit\n"
        "def outer(x):\n    return inner(x) * 2\n"
        "print(outer(1), type(inner).__name__)\n"
    )
    root = str(Path(__file__).resolve().parents[1])
    env = dict(os.environ, NUMBA_DISABLE_JIT="1", PYTHONPATH=root)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["4", "function"]


def test_the_ekf_sections_have_no_python_entry():
    """The kernel's sections and helpers (layout.INLINED / CALLED) are compiled only into kernels."""
    import importlib

    from imutool.filter_warm import EKF_SECTIONS, HEADING_SECTION

    for module, name, _ in (*EKF_SECTIONS, HEADING_SECTION):
        assert isinstance(getattr(importlib.import_module(module), name), CompiledOnlyDispatcher), name
