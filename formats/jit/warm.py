"""A cold first run on two cores: a second process compiles part of what a command needs into the same cache.

numba compiles in one thread (a process-wide lock), and most of a first run's time is numba's own Python passes
(type inference, lowering; LLVM a third), so a cold cache cannot be compiled much faster in one process. It can be
split across processes: while a command compiles its parser and its main kernel, a second process compiles the
main kernel's parts from the last one backwards (the EKF's sections, :mod:`imutool.filter_warm`) and the kernels
the command calls later (the CSV writer's before the sections, the gyro check's and the smoother's after them),
into the same cache. The command
loads each part it reaches that the second process has finished, and compiles the others itself; the two meet in
the middle, each function compiled once: while they share the work, a process claims a function before compiling
it and the other waits for a claimed one instead of compiling it too (:mod:`formats.jit.claims`). numba links a
part loaded from the cache as LLVM bitcode, so the kernel is the same machine code as when it compiles everything
itself (`tests/test_kernel_warm.py` compares them).

A part compiled on its own must be the code its caller would have compiled: numba takes ``fastmath``,
``error_model``, ``_nrt`` and ``forceinline`` from the caller for a function that does not set them, and its cache
does not key on flags. So every part listed, and every helper it calls, states all four (and ``cache=True``).

:func:`warm_in_background` is called by a command's library route before its work starts. When the command's main
kernel is not in the cache yet, it starts the second process, which compiles the listed entries in order with the
argument types the command calls them with. The command never depends on the second process (a command that
waits for a kernel, :func:`wait_for`, compiles it itself when the process ends or takes too long); that process
stays silent (an entry it cannot compile is left to the command), is killed if still running when the command
ends (a command killed by a signal: on POSIX the second process stops before its next entry, as its parent is
gone), and is never started from inside itself (``IMUTOOL_KERNEL_WARM=0``).

An entry is ``(module, function, argument types)`` in numba's signature syntax (``"float64[:, ::1], int64,
boolean"``), kept beside the command's kernels; a test records a real cold compile and checks that every kernel and
part it compiled is listed with the types it was called with.
"""

from __future__ import annotations

import atexit
import importlib
import multiprocessing
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from numba.core import sigutils, types

from formats.jit import cache as kernel_cache
from formats.jit import claims
from formats.jit.threads import thread_budget

ENV_SWITCH = "IMUTOOL_KERNEL_WARM"  # "0": never start a warming process (set inside one); "1": even on a busy machine

Entry = tuple[str, str, str]  # (module, function name, argument types)

# the CSV writer's kernel, as every command that writes a CSV calls it
CSV_WRITER: Entry = (
    "formats.csv_engine",
    "format_block",
    "float64[:, ::1], uint64[:, ::1], int64, int64, int64, uint8[::1], int64[:, ::1], int64[::1]",
)
# the CSV reader's kernel, as every command that reads a CSV calls it
CSV_READER: Entry = (
    "formats.csv_engine",
    "parse_block",
    "uint8[::1], int64, int64, int64, int64, int64, float64[:, ::1], int64, boolean, int64[:, ::1], int64[:, ::1], "
    "uint64[::1], uint64[::1]",
)


def type_text(t: types.Type) -> str:
    """A numba type in signature syntax: ``float64[:, ::1]`` for a 2-D C array, ``boolean``, ``int64``."""
    if isinstance(t, types.Array):
        if not t.mutable or not t.aligned:
            raise ValueError(f"no signature syntax for {t!r}")
        dims = [":"] * t.ndim
        if t.layout == "C":
            dims[-1] = "::1"
        elif t.layout == "F":
            dims[0] = "::1"
        return f"{type_text(t.dtype)}[{', '.join(dims)}]"
    if isinstance(t, types.Boolean):
        return "boolean"
    return str(t)


def argument_types(text: str) -> tuple[types.Type, ...]:
    """The argument types of ``"float64[::1], int64"`` (numba's signature syntax, no return type)."""
    args, _ = sigutils.normalize_signature(f"({text},)" if text else "()")
    return tuple(args)


def _index_file(dispatcher) -> Path | None:
    """The cache index file of ``dispatcher`` (numba's internals; None where they differ)."""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    path = getattr(cache_file, "_index_path", None)
    return Path(path) if path else None


def is_cached(dispatcher) -> bool:
    """True if ``dispatcher`` has an entry in the kernel cache (any signature), or its cache cannot be located.
    ``dispatcher`` may also be an :data:`Entry` (its module not imported: the index file is looked for by name)."""
    if isinstance(dispatcher, tuple):
        folder = kernel_cache.cache_folder()
        module, name = dispatcher[0], dispatcher[1]
        if folder is None or module.split(".")[0] not in kernel_cache.PACKAGES:
            return True
        package, _, base = module.rpartition(".")
        return any((folder / package.replace(".", "/")).glob(f"{base}.{name}-*.nbi"))
    index = _index_file(dispatcher)
    return index is None or index.exists()


def _probe_key(probe) -> str:
    if isinstance(probe, tuple):
        return f"{probe[0]}.{probe[1]}"
    return f"{getattr(probe, '__module__', '')}.{getattr(probe, '__qualname__', probe)}"


def warm_in_background(
    probe, entries: Sequence[Entry], splits_probe: bool = False, meanwhile: Sequence[Entry] = ()
) -> subprocess.Popen | None:
    """Start the warming process for ``entries`` (in order) if ``probe`` (the command's main kernel) is not cached.

    ``splits_probe``: the entries hold the probe's own parts, from its last (the EKF's sections), so the command
    compiles only about half of the probe's group and announces that share of its time; and ``meanwhile`` (what
    the command compiles while it waits for the other process) waits until the probe is cached.

    Returns the process (not waited for; killed if still running when this one ends), or None: cached already,
    a thread budget of one (one core, or a batch worker's share, :func:`formats.jit.threads.thread_budget`), a
    machine busy already (load average above the usable cores: the second process would only take the command's
    share; below that it costs only its start-up, ~1.5 s CPU, as the two compile different parts), switched off,
    a cache that lasts only as long as this process, or the process could not be started.
    """
    budget = thread_budget()
    if os.environ.get(ENV_SWITCH, "") == "0" or budget < 2 or not entries or not sys.executable:
        return None
    if getattr(sys, "frozen", False) or multiprocessing.parent_process() is not None:
        return None  # a frozen program has no `python -c`; a pool worker (batch) never runs atexit
    key = _probe_key(probe)
    if key in _STARTED:
        return None  # once per process: a cache that cannot be written stays cold, and is not compiled twice
    if os.environ.get(ENV_SWITCH, "") != "1" and _busy_cores() > budget:
        return None  # every core busy: a second process would only take the command's share
    env = dict(os.environ, **{ENV_SWITCH: "0"})
    if not kernel_cache.new_source_tree():
        folder = kernel_cache.cache_folder()
        if folder is None or not kernel_cache.cache_is_persistent() or is_cached(probe):
            return None
        env[kernel_cache.FOLDER_ENV] = str(folder.resolve())
    # else a first run of these files: cold, and the second process starts now, not after this one's source scan
    # (~0.4 s, formats.jit.cache.source_version); it finds the same folder itself
    _STARTED.add(key)
    path = kernel_cache.PACKAGES_FOLDER
    # the command's pid in the start line: a command killed while the second process imports numba is noticed
    start = f"import sys; sys.path.insert(0, {path!r}); from formats.jit.warm import _main; _main({os.getpid()})"
    lines = "\n".join("\t".join(e) for e in entries)
    try:
        proc = subprocess.Popen(
            [sys.executable, "-c", start],  # our packages first on the path, not a user's `formats`
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
            close_fds=True,
        )
        assert proc.stdin is not None
        proc.stdin.write(lines.encode())
        proc.stdin.close()
    except (OSError, ValueError):
        return None
    atexit.register(_stop, proc)  # a command that ends first leaves no process behind
    claims.share_with(proc.pid, lambda: proc.poll() is None)  # each function compiled once (formats.jit.claims)
    if meanwhile:
        claims.while_waiting(_one_at_a_time(meanwhile, after=probe if splits_probe else None))
    if splits_probe:
        kernel_cache.compiling_in_two_processes(probe[0] if isinstance(probe, tuple) else probe.__module__)
    return proc


_STARTED: set[str] = set()  # the probes this process has started a warming process for


def _one_at_a_time(entries: Sequence[Entry], after=None):
    """For :func:`formats.jit.claims.while_waiting`: each call compiles the next of ``entries`` that is neither
    cached nor claimed by the other process; False once none is left. With ``after`` (the probe, whose parts the
    two processes share): nothing (None) until it is cached — where the command meets the second process among
    the probe's parts, the part it waits for is nearly done, and a kernel compiled there would put its time
    before the probe's own on the command's path."""
    left = list(entries)

    def work() -> bool | None:
        if after is not None and not is_cached(after):
            return None
        while left:
            if compile_entries([left.pop(0)]):
                return True
        return False

    return work


def _busy_cores(loadavg: str = "/proc/loadavg") -> float:
    """The machine's load: runnable processes, the 1-minute mean (0 where the platform has none) — or, where it is
    lower, the count running at this instant, this process left out (Linux ``/proc/loadavg``). The mean lags a
    minute behind: right after one cold command its two processes held it near 2 on this 2-core machine, and the
    next command, on an idle machine, compiled alone (18–20 s instead of ~10, 2026-12-06)."""
    try:
        mean = os.getloadavg()[0]
    except (AttributeError, OSError):
        return 0.0
    try:
        with open(loadavg, encoding="ascii") as f:
            now = int(f.read().split()[3].split("/")[0]) - 1
    except (OSError, ValueError, IndexError):
        return mean
    return min(mean, float(max(now, 0)))


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def compile_entries(entries: Sequence[Entry], parent: int | None = None) -> int:
    """Compile each entry in order (from the cache where it is there already); the number compiled or loaded.
    With ``parent`` (a process id), stop before the next entry once that process has ended: a command killed by a
    signal runs no exit handler, and its second process then finishes at most the entry it is compiling."""
    done = 0
    for module, name, text in entries:
        if parent is not None and os.getppid() != parent:
            break
        before = claims.held()  # (the command's, when it compiles an entry while it waits: its kernel's claim)
        try:
            fn = getattr(importlib.import_module(module), name)
            args = argument_types(text)
            index = _index_file(fn)
            if claims.sharing() and index is not None and claims.claimed_by_other(claims.claim_path(str(index), args)):
                continue  # the other process is compiling it (where the two meet): the next one
            fn.compile(args)
        except Exception:  # noqa: BLE001 - a kernel this process cannot compile is left to the command
            claims.release_all(keep=before)  # what it had claimed for it: the other process may compile that
            continue
        done += 1
    return done


WAIT_FACTOR = 6.0  # wait at most this many times the kernel group's compile estimate (kernel_cache.KERNEL_GROUPS)
WAIT_FLOOR_S = 60.0  # and at least this long: a loaded machine compiles several times slower than the estimate


def wait_for(
    dispatcher, proc: subprocess.Popen | None, meanwhile: Sequence[Entry] = (), timeout_s: float | None = None
) -> bool:
    """For a command whose main kernel the second process ``proc`` compiles (its first entry): compile
    ``meanwhile`` here first (what the command needs after that kernel), then wait until ``dispatcher`` is in the
    cache, ``proc`` has ended or ``timeout_s`` s have passed (default: :data:`WAIT_FACTOR` times the group's
    estimate, at least :data:`WAIT_FLOOR_S`). True when it is cached; on False the command compiles it itself when
    it calls it. Without a second process (``proc`` None) nothing is compiled or waited for.

    "Cached" is any signature of ``dispatcher`` (numba's index file exists): meant for a kernel that is always
    called with the types listed in its entry."""
    if proc is None:
        return False
    compile_entries(meanwhile)
    module = getattr(dispatcher, "__module__", "")
    if not is_cached(dispatcher):
        kernel_cache.announce_compile(module)
    if timeout_s is None:
        group = kernel_cache.kernel_group(module)
        timeout_s = max(WAIT_FLOOR_S, WAIT_FACTOR * (group[1] if group else 0.0))
    deadline = time.monotonic() + timeout_s
    while not is_cached(dispatcher):
        if proc.poll() is not None or time.monotonic() > deadline:
            _stop(proc)  # too slow: the command compiles the kernel itself, not both of them at once
            return is_cached(dispatcher)
        time.sleep(0.05)
    return True


def _main(parent: int | None = None) -> None:
    """The second process: compile the entries on stdin, while ``parent`` (the command's pid) is its parent."""
    announcer = getattr(kernel_cache.event, "_imutool_announcer", None)
    if announcer is not None:
        announcer.silent = True  # the command says what compiles; this process has no one to tell
    entries = [tuple(line.split("\t")) for line in sys.stdin.read().splitlines() if line.count("\t") == 2]
    if parent is not None:
        claims.share_with(parent, lambda: os.getppid() == parent)
    compile_entries(entries, parent)  # type: ignore[arg-type]


if __name__ == "__main__":  # python -m formats.jit.warm (the command starts it with -c, see above)
    _main()
