"""numba's ``njit`` as imutool's compiled functions take it: without the wrappers numba would build and never use.

numba builds two wrappers around every function it compiles, each its own LLVM function, optimised and turned
into machine code: a Python entry (unboxes the arguments, calls, boxes the result) and a C entry (numba's
``cfunc`` wrapper, for a compiled function passed as a first-class value to another). On a cold first ``filter``
(an empty cache, one process, ``py-spy`` sampled at 200 Hz, 2026-12-06) building them took 4 % (Python entry)
and 2.7 % (C entry) of the compile, and their LLVM passes and machine code about as much again.

- :func:`njit` leaves out the C entry by default (``no_cfunc_wrapper=True``): no kernel here passes a compiled
  function as a value (a library user who passes one of ours to their own numba code as a first-class function
  gets numba's "wrapper address ... got 0" error).
- numba's own ``@overload`` implementations that a kernel calls (``np.empty``, ``min``, ``int``...: ~25 small
  functions compiled on their own on a first ``filter``) are built without their C entry too (numba already
  leaves out their Python entry): :func:`install`, run when this module is imported.
- ``njit(..., no_cpython_wrapper=True)`` also leaves out the Python entry, for a function only compiled code
  calls (the EKF loop's sections and their helpers, :data:`imutool.attitude.layout.INLINED`). numba would then
  jump to a null address if Python called it; the dispatcher made here raises a ``TypeError`` that says so
  instead (call it from a compiled function; a test wraps it in one).

Every module of imutool, calibration and formats takes ``njit`` from here, not from ``numba`` (``tests/test_style.py``
checks), so a new kernel gets the same defaults; :func:`formats.jit.cache.kernel_sources` counts this module's
``njit`` as numba's decorator when it scans for the files a kernel can reach.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import numba
import numba.core.typing.templates
from numba.core.registry import CPUDispatcher

import formats.jit.cache  # noqa: F401  (a kernel decorated here is cached in imutool's folder)
from formats.jit.typing_memo import numba_version

CHECKED_NUMBA = ((0, 58), (0, 68))  # numba (major, minor) range whose overload templates were read


def install() -> None:
    """Build numba's ``@overload`` implementations without the C entry (``no_cfunc_wrapper``) in this process:
    they are only called by compiled code. Process-wide: a user's own ``@overload`` in the same process is built
    so too (an overload's implementation is never a first-class value). Once; only over the numba versions this
    was read against (:data:`CHECKED_NUMBA`); where numba's internals differ, nothing changes."""
    if not CHECKED_NUMBA[0] <= numba_version() <= CHECKED_NUMBA[1]:
        return
    template = getattr(numba.core.typing.templates, "_OverloadFunctionTemplate", None)
    get_jitter = getattr(template, "_get_jit_decorator", None)
    if get_jitter is None or getattr(get_jitter, "_imutool_no_cfunc", False):
        return

    def _get_jit_decorator(self):  # noqa: ANN001, ANN202 - numba's signature
        jitter = get_jitter(self)

        def no_c_entry(**options: Any) -> Any:
            options.setdefault("no_cfunc_wrapper", True)
            return jitter(**options)

        return no_c_entry

    _get_jit_decorator._imutool_no_cfunc = True  # type: ignore[attr-defined]
    template._get_jit_decorator = _get_jit_decorator


class CompiledOnlyDispatcher(CPUDispatcher):
    """A numba dispatcher of a function compiled without its Python entry (``no_cpython_wrapper``): compiled code
    calls it as any other; a call from Python raises a ``TypeError`` instead of jumping to a null address."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        name = f"{self.py_func.__module__}.{self.py_func.__qualname__}"
        raise TypeError(
            f"{name} is compiled without a Python entry (no_cpython_wrapper): call it from a compiled function"
        )


def njit(*args: Any, **options: Any) -> Any:
    """``numba.njit`` with ``no_cfunc_wrapper=True`` unless given; ``no_cpython_wrapper=True`` makes a
    :class:`CompiledOnlyDispatcher`. Used as ``@njit`` or ``@njit(cache=True, ...)``, as numba's."""
    options.setdefault("no_cfunc_wrapper", True)
    if not options.get("no_cpython_wrapper", False) or numba.config.DISABLE_JIT:
        return numba.njit(*args, **options)  # (NUMBA_DISABLE_JIT=1: numba gives the Python function back)
    cache = options.pop("cache", False)
    if "locals" in options or "pipeline_class" in options:
        raise TypeError("formats.jit.decorators.njit takes no locals or pipeline_class with no_cpython_wrapper")
    options["nopython"] = True

    def wrap(func: Callable) -> CompiledOnlyDispatcher:
        if not inspect.isfunction(func):
            raise TypeError(f"njit decorates a function, not {type(func).__name__}")
        dispatcher = CompiledOnlyDispatcher(py_func=func, locals={}, targetoptions=options)
        if cache:
            dispatcher.enable_caching()
        return dispatcher

    if args and callable(args[0]):
        return wrap(args[0])
    if args:
        raise TypeError("formats.jit.decorators.njit takes no signatures with no_cpython_wrapper")
    return wrap


install()
