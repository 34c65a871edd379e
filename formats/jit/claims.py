"""Two processes compiling into one cache, each function once: a claim file per function and signature.

A cold first run compiles in two processes (:mod:`formats.jit.warm`): the command from its first kernel on, the
second process from the other end of the list. Where they meet, both used to compile the same function at once
(an EKF section, ~1.7 s of CPU each). Now, while two processes share the work (:func:`share_with`), a process
that misses the cache for one of our functions creates ``<index>.<signature hash>.claim`` (holding its pid)
before it compiles; a process that misses the cache for a function the other one has claimed waits until that
one is in the cache and loads it (a few ms), instead of compiling it again. A claim is removed when the
function is saved, when its compile failed, and when its process ends; a claim whose owner has ended, or that
has not been honoured within :data:`WAIT_S` s, is ignored (the waiter compiles the function itself). A waiter
waits only for a function the other process is compiling, and that process never waits for a function it is
compiling itself, so two processes cannot wait for each other: numba compiles a function's callees inside it,
and a circle of claims would need a circle of calls.

The compiled code does not depend on which process compiled a function: every function the kernels reach
states its own flags (:mod:`formats.jit.warm`), and ``tests/test_kernel_warm.py`` compares the machine code.
"""

from __future__ import annotations

import atexit
import contextlib
import hashlib
import os
import time
from collections.abc import Callable
from pathlib import Path

WAIT_S = 60.0  # at most this long for one claimed function (a loaded machine compiles several times slower)
POLL_S = 0.02


class _Sharing:
    peer: int | None = None  # the other process's pid while two processes share the compile
    alive: Callable[[], bool] = staticmethod(lambda: False)  # is the other process still running
    mine: set[Path] = set()  # the claims this process holds
    # compiles one more thing this process needs later: True done, None nothing yet (asked again), False none left
    meanwhile: Callable[[], bool | None] | None = None
    busy = False  # in meanwhile (a wait inside it waits)


def while_waiting(work: Callable[[], bool | None] | None) -> None:
    """What this process does instead of idling while it waits for the other's function: ``work()`` compiles one
    function it will need later (claimed, so the other skips it) and returns True, None when it has nothing to do
    yet (asked again at the next wait) or False when there is none left."""
    _Sharing.meanwhile = work


def share_with(peer: int, alive: Callable[[], bool]) -> None:
    """From now on, claim each of our functions before compiling it and wait for those ``peer`` has claimed
    while ``alive()`` (the other process has not ended)."""
    if _Sharing.peer is None:
        atexit.register(release_all)  # a command that fails or ends first leaves no claim behind
    _Sharing.peer, _Sharing.alive = peer, alive


def sharing() -> bool:
    return _Sharing.peer is not None


def stop_sharing() -> None:
    """Forget the other process and give up every claim of this one (at exit, or when the other has ended)."""
    _Sharing.peer = None
    _Sharing.meanwhile = None
    release_all()


def claim_path(index_path: str, sig) -> Path:
    """The claim file of one signature of a cached function (beside its numba index file)."""
    digest = hashlib.blake2b(str(sig).encode(), digest_size=6).hexdigest()
    return Path(f"{index_path}.{digest}.claim")


def _owner(path: Path) -> int | None:
    try:
        return int(path.read_text(encoding="ascii") or "0")
    except (OSError, ValueError):
        return None


def _running(pid: int) -> bool:
    if pid == _Sharing.peer:
        return _Sharing.alive()
    try:
        os.kill(pid, 0)
    except OSError:
        return False
    try:  # a zombie (ended, not yet reaped) is not compiling anything
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except (OSError, IndexError):
        return True


def claimed_by_other(path: Path) -> bool:
    """True if another process that is still running holds the claim ``path``."""
    owner = _owner(path)
    return owner is not None and owner != os.getpid() and _running(owner)


def _claim(path: Path) -> bool:
    try:
        fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError:
        return False
    except OSError:
        return True  # a folder we cannot claim in: compile as without sharing
    with os.fdopen(fd, "w", encoding="ascii") as f:
        f.write(str(os.getpid()))
    _Sharing.mine.add(path)
    return True


def release(path: Path) -> None:
    if path in _Sharing.mine:
        _Sharing.mine.discard(path)
        try:
            path.unlink()
        except OSError:
            pass


def release_all(keep: frozenset[Path] | set[Path] = frozenset()) -> None:
    """Give up this process's claims, except ``keep``."""
    for path in list(_Sharing.mine - set(keep)):
        release(path)


def held() -> frozenset[Path]:
    """The claims this process holds now."""
    return frozenset(_Sharing.mine)


@contextlib.contextmanager
def _outside_any_compile():
    """The wait happens inside numba's compile of a caller, and numba gives a function that does not state
    ``fastmath``, ``error_model``, ``_nrt`` or ``forceinline`` those of the compile it happens in (its thread's flag
    stack): a kernel compiled while waiting sees an empty stack, as when the command calls it."""
    from numba.core.utils import ThreadLocalStack

    tls, attr = ThreadLocalStack._tls, "stack_flags"
    outer = getattr(tls, attr, None)
    setattr(tls, attr, [])
    try:
        yield
    finally:
        if outer is None:
            delattr(tls, attr)
        else:
            setattr(tls, attr, outer)


def claim_or_wait(path: Path, load: Callable[[], object]) -> object:
    """After a cache miss: claim the function (returns None: compile it) or, when the other process holds the
    claim, wait until ``load()`` finds it in the cache and return that. None also when the claim's owner ended
    or :data:`WAIT_S` passed: the caller compiles the function itself."""
    deadline = time.monotonic() + WAIT_S
    while True:
        if _claim(path):
            data = load()  # saved by the other process between our miss and our claim
            if data is not None:
                release(path)
            return data
        owner = _owner(path)
        if owner == os.getpid():
            return None
        if owner is not None and not _running(owner):
            try:  # an ended process's claim: taken over
                path.unlink()
            except OSError:
                pass
            continue
        data = load()
        if data is not None:
            return data
        if time.monotonic() > deadline:
            return None
        if _Sharing.meanwhile is not None and not _Sharing.busy:
            _Sharing.busy = True
            try:
                with _outside_any_compile():
                    more = _Sharing.meanwhile()
            finally:
                _Sharing.busy = False
            if more:
                deadline = time.monotonic() + WAIT_S  # the wait starts again after that compile
                continue
            if more is False:
                _Sharing.meanwhile = None
        time.sleep(POLL_S)
