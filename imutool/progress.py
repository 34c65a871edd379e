"""Progress reporting: one small mechanism for the library and the command line.

Library side: a function that can run long takes ``progress: Progress | None = None`` — a callable
``progress(done, total)`` with absolute counts in the function's own unit (samples, rows, chunks, steps) — and
calls it between chunks of work (:func:`report`, :func:`chunk_ranges`). Nothing is printed by the library.

CLI side: :func:`bar` gives a :class:`Bar` — a tqdm bar on stderr with done/total, rate and ETA, shown only when
stderr is a terminal and ``--quiet`` was not given (otherwise every call is a no-op, so output piped to a file or
another program stays clean). A ``Bar`` is itself a ``Progress`` callable, and also counts stages
(:meth:`Bar.stage`) or wraps an iterable (:meth:`Bar.iterate`)::

    with bar("filtering", total=len(rec), unit="samples", quiet=quiet) as b:
        out = estimate(rec, progress=b)          # the library calls b(done, total)

    with bar("ins", total=3, unit="steps", quiet=quiet) as b:
        b.stage("reading"); rec = read(...)
        b.stage("INS"); out = ins(rec)
        b.stage("writing"); write(out)
"""

from __future__ import annotations

import os
import sys
import weakref
from collections.abc import Callable, Iterable, Iterator
from typing import Any, TypeVar

T = TypeVar("T")

Progress = Callable[[int, "int | None"], None]
"""``progress(done, total)``: absolute amount done so far and the total (None when unknown)."""

_OPEN: weakref.WeakSet = weakref.WeakSet()  # bars drawn and not yet closed (closed before an error line)


def report(progress: Progress | None, done: int, total: int | None) -> None:
    """Call ``progress(done, total)`` if a callback was given."""
    if progress is not None:
        progress(done, total)


def chunk_ranges(n: int, chunk: int, progress: Progress | None = None) -> Iterator[tuple[int, int]]:
    """``(start, stop)`` index ranges covering ``range(n)`` in steps of ``chunk``; reports after each range."""
    chunk = max(1, int(chunk))
    for a in range(0, n, chunk):
        b = min(n, a + chunk)
        yield a, b
        report(progress, b, n)


def interactive(quiet: bool = False, stream: Any = None) -> bool:
    """True when a bar should be drawn: not ``quiet`` and the stream (stderr) is a terminal."""
    s = sys.stderr if stream is None else stream
    if quiet:
        return False
    try:
        return bool(s.isatty())
    except (AttributeError, ValueError):
        return False


def estimate_rows(path: str | os.PathLike, sample_bytes: int = 1 << 20) -> int | None:
    """Rough number of lines of a text file (size / mean line length of its first MiB); None if unreadable."""
    try:
        size = os.path.getsize(path)
        with open(path, "rb") as f:
            head = f.read(sample_bytes)
    except OSError:
        return None
    lines = head.count(b"\n")
    if not head or lines == 0:
        return None
    return max(1, round(size * lines / len(head)))


def _columns(stream: Any) -> int | None:
    """None when the terminal reports its size (tqdm follows it), else 80 (a pty without a size: tqdm would draw
    nothing, taking the bar for one below the last row)."""
    try:
        if os.get_terminal_size(stream.fileno()).columns > 0:
            return None
    except (AttributeError, OSError, ValueError):
        pass
    return 80


class Bar:
    """A progress bar on stderr (tqdm), or a silent stand-in when not interactive. Use as a context manager."""

    def __init__(
        self, label: str, total: int | None = None, unit: str = "it", quiet: bool = False, stream: Any = None
    ) -> None:
        self.label = label
        self.total = total
        self.unit = unit
        self.done = 0
        self._stage: str | None = None
        self._tq: Any = None
        if interactive(quiet, stream):
            from tqdm import tqdm

            out = sys.stderr if stream is None else stream
            cols = _columns(out)
            self._tq = tqdm(
                total=total,
                desc=label,
                unit=unit,
                file=out,
                leave=False,
                ncols=cols,
                nrows=None if cols is None else 24,
                dynamic_ncols=cols is None,
                unit_scale=total is None or total >= 100_000,
                mininterval=0.2,
                smoothing=0.1,
            )
            _OPEN.add(self)

    @property
    def shown(self) -> bool:
        """Whether a bar is actually drawn."""
        return self._tq is not None

    def __call__(self, done: int, total: int | None = None) -> None:
        """Absolute update (the :data:`Progress` protocol)."""
        if total is not None and total != self.total:
            self.total = total
            if self._tq is not None:
                self._tq.total = total
        self.advance(int(done) - self.done)

    def advance(self, n: int = 1) -> None:
        """``n`` more units done."""
        if n <= 0:
            return
        self.done += n
        if self._tq is not None:
            self._tq.update(n)

    def stage(self, label: str) -> None:
        """Start the next stage: the previous one (if any) counts as one step done; the label shows ``label``."""
        if self._stage is not None:
            self.advance(1)
        self._stage = label
        if self._tq is not None:
            self._tq.set_description_str(f"{self.label}: {label}", refresh=True)

    def iterate(self, items: Iterable[T], weight: Callable[[T], int] | None = None) -> Iterator[T]:
        """Yield ``items``, advancing by 1 (or ``weight(item)``, e.g. rows of a chunk) after each."""
        for item in items:
            yield item
            self.advance(1 if weight is None else int(weight(item)))

    def close(self) -> None:
        if self._stage is not None:
            self._stage = None
            self.advance(1)
        if self._tq is not None:
            self._tq.close()
            self._tq = None
            _OPEN.discard(self)

    def __enter__(self) -> Bar:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def close_all() -> None:
    """Close every open bar (the CLI calls this before printing an error, so the error gets a clean line)."""
    for b in list(_OPEN):
        b.close()


def bar(label: str, total: int | None = None, unit: str = "it", quiet: bool = False) -> Bar:
    """A :class:`Bar` on stderr: drawn only when stderr is a terminal and not ``quiet``."""
    return Bar(label, total=total, unit=unit, quiet=quiet)


def stages(label: str, names: Iterable[str], quiet: bool = False) -> Bar:
    """A bar counting named stages (call :meth:`Bar.stage` with each); total = number of stages."""
    return Bar(label, total=len(list(names)), unit="step", quiet=quiet)
