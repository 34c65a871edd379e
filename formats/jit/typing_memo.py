"""A memo for numba's typing of calls to built-in functions: a question asked once per function compiled.

Where a cold compile's time goes (docs/architecture.md, "Compile time"): numba types every call, operator and
subscript of a kernel by asking the function's type for a signature (``BaseFunction.get_call_type``), and answers
it by trying every registered template in turn; an ``@overload`` template hashes the whole compiler flag set at each
try. The EKF asks 13 500 times, for ~1 450 distinct questions (``float64 * float64`` thousands of times), and the
lowering stage asks again for each operator and subscript. That was ~30 % of the first ``filter``'s compile CPU.

:func:`install` wraps ``get_call_type`` with a dictionary keyed on exactly what the answer depends on: the function
type (numba interns types; a new ``@overload`` registration makes a new type, so a new key), the typing context,
the argument types (literal values included), the keyword arguments, and the compiler flag set in force
(``ConfigStack``; numba makes one for each function it compiles and keeps it while typing). Only answers of plain
templates are kept, those whose implementation key is the template's own ``key``: an ``@overload`` or
``@intrinsic`` template compiles an implementation for the flags in force and numba looks it up by argument types
only, so those are asked every time, as before. A kept answer's side effect (the implementation key numba records
for the lowering stage) is replayed on each hit. A question that raises is not kept. The compiled code is
unchanged: tests compare the machine code with and without the memo (a small mix of kernels, and the EKF kernel).

Because numba makes a new flag set for every function it compiles, an answer is reused within one function's
compile (an EKF section asks ``float64 * float64`` hundreds of times), not across functions: the EKF's cold compile
leaves ~1 400 entries. Keying on the flags' values instead would share answers across functions (430 entries) and
saved ~1 s of ~23 s CPU (EKF compile 21.5–22.9 s against 23.1–23.6 s, two runs each, 2026-11-28; within this
machine's wander), for a key that would have to name every flag a template may read: not done. The memo is
process-wide (numba's typing tables are) and capped at :data:`MAX_ENTRIES`, then emptied; it holds the flag sets
and contexts its keys name, so an id is never reused while it is in use. ``IMUTOOL_TYPING_MEMO=0`` switches it
off. It is installed only over the numba versions whose ``get_call_type`` it was checked against;
for any other, or if numba's internals moved, it stays off and numba works as shipped.
"""

from __future__ import annotations

import os
from typing import Any

import numba

MAX_ENTRIES = 50_000  # distinct (function, argument types, flags) questions kept before the memo is emptied
ENV = "IMUTOOL_TYPING_MEMO"
CHECKED_NUMBA = ((0, 58), (0, 68))  # numba (major, minor) range whose get_call_type was read: 0.58.1 and 0.68.1

_memo: dict[tuple, tuple[Any, Any, Any, Any]] = {}
_installed: list[Any] = []  # [the original get_call_type] once installed


def numba_version() -> tuple[int, int]:
    """This numba's (major, minor); (0, 0) where its version string is not numbers."""
    parts = numba.__version__.split(".")
    try:
        return int(parts[0]), int(parts[1])
    except (IndexError, ValueError):
        return (0, 0)


def supported() -> bool:
    """True when this numba's ``BaseFunction.get_call_type`` is the one the memo was checked against."""
    if not (CHECKED_NUMBA[0] <= numba_version() <= CHECKED_NUMBA[1]):
        return False
    try:
        from numba.core import targetconfig
        from numba.core.types.functions import BaseFunction
        from numba.core.typing.templates import FunctionTemplate
    except ImportError:
        return False
    code = getattr(BaseFunction.get_call_type, "__code__", None)
    return (
        code is not None
        and code.co_varnames[:4] == ("self", "context", "args", "kws")
        and hasattr(targetconfig.ConfigStack, "top_or_none")
        and "_impl_keys" in BaseFunction.__init__.__code__.co_names
        and hasattr(FunctionTemplate, "get_impl_key")
    )


_NONE = object()


def _plain_answer(function_type: Any, impl_key: Any, plain_key: Any) -> bool:
    """True when a plain template answered: one whose implementation key is its own ``key``, the same whatever
    the flags. An ``@overload`` or ``@intrinsic`` template's key is the implementation it compiled for the flags in
    force (numba keeps it in a table by argument types only, last writer wins), so its answers are never kept."""
    for template in getattr(function_type, "templates", ()):
        if getattr(template, "get_impl_key", None) is plain_key and getattr(template, "key", _NONE) is impl_key:
            return True
    return False


def install() -> bool:
    """Put the memo in front of numba's call typing (once per process); False when off or not supported."""
    if _installed:
        return True
    if os.environ.get(ENV, "1").strip() == "0" or not supported():
        return False
    from numba.core import targetconfig
    from numba.core.types.functions import BaseFunction
    from numba.core.typing.templates import FunctionTemplate

    original = BaseFunction.get_call_type
    top_flags = targetconfig.ConfigStack.top_or_none
    plain_key = FunctionTemplate.get_impl_key

    def get_call_type(self, context, args, kws):
        flags = top_flags()
        try:
            key = (self, id(context), tuple(args), tuple(kws.items()), id(flags))
            known = _memo.get(key)
        except TypeError:  # an unhashable argument type: ask numba
            return original(self, context, args, kws)
        if known is not None:
            sig, impl_key = known[0], known[1]
            self._impl_keys[sig.args] = impl_key  # the side effect of the first answer, replayed
            return sig
        sig = original(self, context, args, kws)
        impl_key = self._impl_keys.get(sig.args, _NONE) if sig is not None else _NONE
        if impl_key is not _NONE and _plain_answer(self, impl_key, plain_key):
            if len(_memo) >= MAX_ENTRIES:
                _memo.clear()
            _memo[key] = (sig, impl_key, context, flags)
        return sig

    get_call_type.__doc__ = original.__doc__
    get_call_type.__wrapped__ = original  # type: ignore[attr-defined]
    BaseFunction.get_call_type = get_call_type
    _installed.append(original)
    return True


def uninstall() -> None:
    """Give numba its own ``get_call_type`` back and forget every answer (tests)."""
    if _installed:
        from numba.core.types.functions import BaseFunction

        BaseFunction.get_call_type = _installed.pop()
    _memo.clear()


def is_installed() -> bool:
    return bool(_installed)
