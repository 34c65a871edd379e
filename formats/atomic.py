"""Atomic, safe output: one check for every writer, then a temporary name beside the target renamed at the end.

A crash or an error never leaves a partial file that looks complete, and an output never replaces:

- an input of the same command (same path after resolving links, or the same file through a hard link), nor a
  folder that holds an input, nor the current directory or one of its ancestors;
- an existing folder, unless it is a ROS2 bag folder imutool itself wrote (only ``metadata.yaml`` written by
  rosbags plus ``.db3``/``.mcap`` files) and the writer is writing a ROS2 bag folder;
- a device, FIFO or socket (``/dev/full``, ``/dev/null``...);
- an existing file, while a command's output check is active (:func:`output_guard`) and ``--force`` was not given.

Write failures (disk full, read-only folder, ``/proc``, ``/sys``) become one :class:`ImutoolError` line naming
the output; the temporary file is removed.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import os
import shutil
import stat
import tempfile
from collections.abc import Iterable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .errors import ImutoolError

FORCE_HINT = "add --force to replace it"


@dataclass
class _Guard:
    """What one command may write: its inputs (never replaced), --force, and outputs already checked."""

    inputs: list[tuple[str, str, tuple[int, int] | None]] = field(default_factory=list)  # (given, realpath, id)
    force: bool = False
    approved: set[str] = field(default_factory=set)  # realpaths of outputs that passed check_outputs


_GUARD: contextvars.ContextVar[_Guard | None] = contextvars.ContextVar("imutool_output_guard", default=None)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _real(path: str | os.PathLike) -> str:
    return os.path.realpath(os.path.abspath(os.fspath(path)))


def _file_id(path: str) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_dev, st.st_ino)


def _within(child: str, parent: str) -> bool:
    """True when realpath ``child`` is ``parent`` or lies below it."""
    return child == parent or child.startswith(parent.rstrip(os.sep) + os.sep)


def is_imutool_bag_folder(path: str | os.PathLike) -> bool:
    """True for a ROS2 bag folder written by imutool (rosbags): metadata.yaml + storage files, nothing else."""
    p = Path(path)
    try:
        entries = list(p.iterdir())
        meta = (p / "metadata.yaml").read_text(encoding="utf-8", errors="replace")[:100_000]
    except OSError:
        return False
    if "rosbag2_bagfile_information" not in meta or "ros_distro: rosbags" not in meta:
        return False
    return all(
        e.is_file() and not e.is_symlink() and (e.name == "metadata.yaml" or e.suffix in (".db3", ".mcap"))
        for e in entries
    )


def _as_input(path: str | os.PathLike) -> tuple[str, str, tuple[int, int] | None]:
    given = os.fspath(path)
    real = _real(given)
    return given, real, _file_id(real)


def check_output(
    path: str | os.PathLike,
    *,
    inputs: Iterable[str | os.PathLike] = (),
    force: bool = False,
    folder: bool = False,
    exists_ok: bool = False,
) -> None:
    """Refuse (ImutoolError naming ``path``) an output that would destroy something; see the module docstring.

    ``folder``: the writer writes a ROS2 bag folder (an imutool bag folder may then be replaced, with ``force``).
    ``exists_ok``: an existing file is expected (e.g. ``--append`` merges into it); it still must not be an input.
    """
    given = os.fspath(path)
    if not given.strip():
        raise ImutoolError("empty output name")
    real = _real(given)
    ins = [i if isinstance(i, tuple) else _as_input(i) for i in inputs]
    cwd = _real(os.getcwd())
    if _within(cwd, real):
        what = "the current folder" if real == cwd else "a folder holding the current folder"
        raise ImutoolError(f"output is {what}; name an output file", path=given)
    for in_given, in_real, in_id in ins:
        if real == in_real or (in_id is not None and in_id == _file_id(real)):
            raise ImutoolError(f"output is the input {in_given}; choose another output name", path=given)
        if _within(in_real, real):
            raise ImutoolError(
                f"output is a folder holding the input {in_given}; choose another output name", path=given
            )
        if os.path.isdir(in_real) and _within(real, in_real):
            raise ImutoolError(f"output is inside the input folder {in_given}; choose another output name", path=given)
    # the first existing ancestor must be a folder (a parent that is a file cannot hold the output)
    parent = Path(real).parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise ImutoolError(f"cannot write: {parent} is not a folder", path=given)
    try:
        st = os.stat(real)
    except FileNotFoundError:
        return
    except OSError as e:
        raise ImutoolError(f"cannot write: {e.strerror}", path=given) from None
    if stat.S_ISDIR(st.st_mode):
        if folder and is_imutool_bag_folder(real):
            if not force and not exists_ok:
                raise ImutoolError(f"an imutool ROS2 bag folder exists here; {FORCE_HINT}", path=given)
            return
        raise ImutoolError(
            "is an existing folder (not an imutool ROS2 bag); outputs never replace a folder: "
            "name a new file or folder",
            path=given,
        )
    if not stat.S_ISREG(st.st_mode):
        raise ImutoolError("is not a regular file (a device, FIFO or socket); outputs must be files", path=given)
    if not force and not exists_ok:
        raise ImutoolError(f"exists; {FORCE_HINT}", path=given)


def check_outputs(
    outputs: Iterable[str | os.PathLike | None],
    inputs: Iterable[str | os.PathLike] | None = None,
    *,
    force: bool | None = None,
    exists_ok: Iterable[str | os.PathLike] = (),
) -> None:
    """Check every output of a command against its inputs (see :func:`check_output`) before any work is done.

    Inside :func:`output_guard` the guard's inputs and ``force`` are used when not given here, the inputs given
    here are added to the guard, and the outputs are remembered so the writer (:func:`atomic_path`) accepts them.
    ``None`` outputs (options not given) are skipped; an output named twice is refused.
    """
    g = _GUARD.get()
    ins = [_as_input(i) for i in (inputs or ()) if i is not None and os.fspath(i) != ""]
    if g is not None:
        g.inputs.extend(ins)
        ins = g.inputs
        if force is None:
            force = g.force
    ok = {_real(p) for p in exists_ok if p}
    seen: dict[str, str] = {}
    for o in outputs:
        if o is None:
            continue
        o = os.fspath(o)
        real = _real(o) if o.strip() else ""
        if real and real in seen:
            raise ImutoolError(f"named twice as an output (also as {seen[real]})", path=o)
        seen[real] = o
        folder = _is_folder_output(o)
        check_output(o, inputs=ins, force=bool(force), folder=folder, exists_ok=real in ok)
        if g is not None:
            g.approved.add(real)


def _is_folder_output(path: str) -> bool:
    """A ROS2 bag folder output: no extension (or an existing folder), as ``formats.kind_of`` decides."""
    p = Path(path)
    return p.suffix == "" or p.is_dir()


@contextlib.contextmanager
def output_guard(inputs: Iterable[str | os.PathLike] = (), *, force: bool = False) -> Iterator[None]:
    """Scope of one command: every :func:`atomic_path` inside refuses the inputs and, without ``force``, any
    existing file not approved by :func:`check_outputs`."""
    g = _Guard(inputs=[_as_input(i) for i in inputs if i is not None and os.fspath(i) != ""], force=force)
    token = _GUARD.set(g)
    try:
        yield
    finally:
        _GUARD.reset(token)


def _check_target(target: Path, is_dir: bool) -> None:
    """The last line of defence, in the writer itself (works without a CLI output check too)."""
    g = _GUARD.get()
    real = _real(target)
    if g is not None:
        approved = real in g.approved
        check_output(target, inputs=g.inputs, force=g.force, folder=is_dir, exists_ok=approved)
        return
    # library use (no command scope): files may be replaced, folders only when they are imutool bag folders
    check_output(target, folder=is_dir, exists_ok=True)


def _os_error(e: OSError, target: Path) -> ImutoolError:
    reason = e.strerror or str(e)
    if e.errno in (errno.ENOSPC, errno.EDQUOT):
        reason = "no space left on the device"
    elif e.errno == errno.EROFS:
        reason = "read-only file system"
    return ImutoolError(f"cannot write: {reason}", path=os.fspath(target))


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike, *, is_dir: bool = False) -> Iterator[Path]:
    """Yield a temporary path next to ``target``; on success rename it onto ``target``.

    ``target`` is checked first (see the module docstring). On any exception the temporary file (or folder) is
    removed and ``target`` is untouched; an OSError (disk full, read-only...) becomes one ImutoolError line.
    """
    target = Path(target)
    _check_target(target, is_dir)
    parent = target.parent if str(target.parent) else Path(".")
    tmp: Path | None = None
    try:
        parent.mkdir(parents=True, exist_ok=True)
        if is_dir:
            tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=parent))
            shutil.rmtree(tmp)
        else:
            fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=parent)
            os.close(fd)
            tmp = Path(name)
            os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; outputs get the usual permissions
    except OSError as e:
        if tmp is not None:
            with contextlib.suppress(OSError):
                tmp.unlink()
        raise _os_error(e, target) from None
    try:
        yield tmp
        _check_target(target, is_dir)  # the world may have changed while the output was being computed
        if is_dir:
            if target.is_dir() and not target.is_symlink():
                shutil.rmtree(target)
            os.replace(tmp, target)
        else:
            os.replace(tmp, target)
    except BaseException as e:
        if tmp.is_dir() and not tmp.is_symlink():
            shutil.rmtree(tmp, ignore_errors=True)
        elif tmp.exists() or tmp.is_symlink():
            with contextlib.suppress(OSError):
                tmp.unlink()
        if isinstance(e, OSError):
            raise _os_error(e, target) from None
        raise


class AtomicChunkWriter:
    """Base of the streaming writers (CSV, Parquet): chunks written to a temporary file beside ``path``, renamed
    on :meth:`close`, dropped on :meth:`abort` or an exception inside ``with``.

    ``background=True``: a chunk is converted and written in one worker thread while the caller works on the
    next (one chunk in flight); its error (disk full, ...) is raised at the next :meth:`write` or at close.
    Subclasses implement ``_first(chunk)`` (header/schema, once, in the caller's thread), ``_check(chunk)``,
    ``_write_chunk(chunk)`` (may run in the worker), ``_finish()`` (flush and close the file) and ``_discard()``
    (close without raising). A write failure (OSError) surfaces as the one-line :class:`ImutoolError`.

    Metadata known only at the end of a stream (the warnings of a streamed run) are handed to
    :meth:`set_final_meta` before :meth:`close`; each format merges them over the first chunk's metadata.
    """

    def __init__(self, path: str | os.PathLike, background: bool = False, thread_name: str = "imutool-writer"):
        self.path = os.fspath(path)
        self._ctx = atomic_path(self.path)
        self._tmp = self._ctx.__enter__()
        self.rows = 0
        self._started = False
        self._pool = ThreadPoolExecutor(1, thread_name_prefix=thread_name) if background else None
        self._pending: Future | None = None
        self.final_meta: dict[str, Any] = {}

    def set_final_meta(self, meta: dict[str, Any]) -> None:
        """Metadata that replace the first chunk's keys of the same name when the file is closed. (A new dict each
        time: a chunk being written in the background reads one version of it.)"""
        self.final_meta = {**self.final_meta, **meta}

    def write(self, chunk: Any) -> None:
        if not self._started:
            self._first(chunk)
            self._started = True
        else:
            self._check(chunk)
        if len(chunk):
            if self._pool is None:
                self._write_chunk(chunk)
            else:
                self._wait()
                self._pending = self._pool.submit(self._write_chunk, chunk)
        self.rows += len(chunk)

    def _wait(self) -> None:
        """Finish the chunk in flight (its error is raised here)."""
        if self._pending is not None:
            pending, self._pending = self._pending, None
            pending.result()

    def close(self) -> None:
        try:
            self._wait()
            if self._pool is not None:
                self._pool.shutdown()
            self._finish()  # the last flush can fail too (disk full)
        except BaseException as e:
            self.abort(e)
            raise
        self._ctx.__exit__(None, None, None)

    def abort(self, exc: BaseException) -> None:
        """Drop the temporary file; a write failure (OSError) is raised as the one-line ImutoolError."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        self._discard()
        try:
            self._ctx.__exit__(type(exc), exc, exc.__traceback__)
        except ImutoolError as e:
            if isinstance(exc, OSError):
                raise e from None
        except BaseException:
            pass

    def __enter__(self) -> AtomicChunkWriter:
        return self

    def __exit__(self, et, ev, tb) -> None:
        if et is None:
            self.close()
        else:
            self.abort(ev)

    # ---- per format ----
    def _first(self, chunk: Any) -> None:
        raise NotImplementedError

    def _check(self, chunk: Any) -> None:
        """Refuse a chunk that does not fit the first one (default: accept)."""

    def _write_chunk(self, chunk: Any) -> None:
        raise NotImplementedError

    def _finish(self) -> None:
        raise NotImplementedError

    def _discard(self) -> None:
        raise NotImplementedError
