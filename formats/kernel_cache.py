"""Where the compiled numba kernels of ``imutool``, ``calibration`` and ``formats`` are cached: a per-user folder.

Every module with an ``@njit(cache=True)`` kernel imports this module first (``from formats import
kernel_cache``); importing it puts :class:`KernelCacheLocator` at the front of numba's cache locators. The
locator claims only functions whose source file lies in our three packages (other libraries' numba caches are
untouched) and caches them in

    <root>/kernels-<version>/<package>/<sub-package>/      e.g. ~/.cache/imutool/kernels-3f2a9c01d4e7/imutool/

never inside the installed package, so ``pip install``, upgrade and uninstall leave nothing behind and a read-only
install works. ``<root>`` is ``$NUMBA_CACHE_DIR/imutool`` when ``NUMBA_CACHE_DIR`` is set, else the platform's
per-user cache folder (:func:`user_cache_root`). If that cannot be written (a read-only home), a private folder
in the temporary directory is used, and failing that a folder that lives only as long as the process.

``<version>`` is a short hash of every library source file of the three packages (the CLI, which no kernel can
reach, excepted) and of the numba and Python versions. numba keys a kernel's cache on its own file only, so a
kernel that calls a helper in another file would keep the old helper after that file changed; with the version
in the path any source change starts a fresh cache. The newest :data:`KEEP_VERSIONS` version folders are kept,
older ones are removed when a new one is made.

A kernel that is not in the cache yet is announced once per kernel group on stderr before it compiles
("imutool: compiling the filter's kernels (first run only, ~N s)"), from numba's own ``numba:compile`` event,
which numba raises only after its cache had no entry. ``IMUTOOL_KERNEL_TIMES=1`` also prints each compiled
kernel's time.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import re
import shutil
import stat
import sys
import tempfile
import time
from pathlib import Path

import numba
from numba.core import caching, config, event

PACKAGES = ("imutool", "calibration", "formats")
KEEP_VERSIONS = 3  # version folders kept (the current one included)
_VERSION_DIR = re.compile(r"^kernels-[0-9a-f]{12}$")
_SITE = Path(__file__).resolve().parent.parent  # the folder holding the three packages (site-packages or a clone)
PACKAGES_FOLDER = str(_SITE)

# kernel groups: module-name prefix -> (what the user is told is compiling, about how long an empty cache takes to
# compile it on this project's 2-core machine without other load, s; twice that and more under load). A module of
# the three packages not listed here is announced by its own name. Kernels moved or re-timed: update this table.
# Measured 2026-11-27 (IMUTOOL_KERNEL_TIMES=1 imutool selfcheck, empty cache, load 1): the EKF 29 s (+ RTS 8 s and
# the zero-phase low-pass 1.4 s with --smooth), the gyro check 1.5 s, CSV 6 s, INS 7.5 s, heave 2.5 s, bags 5.6 s.
# The EKF's option-only sections compiled apart (branch compile): 10-16 % less CPU than main in paired runs, ~26 s.
KERNEL_GROUPS: tuple[tuple[str, str, float], ...] = (
    ("imutool.attitude", "the filter's kernels", 26.0),
    ("imutool.gyro_check", "the filter's kernels", 2.0),
    ("imutool.compass", "the compass filter's kernel", 2.0),
    ("imutool.heave", "the heave filter's kernels", 3.0),
    ("imutool.ins", "the INS kernels", 8.0),
    ("imutool.gyrofree", "the gyro-free kernel", 3.0),
    ("imutool.roll", "the roll statistics kernel", 2.0),
    ("imutool.capture", "the bridge-frame decoder", 3.0),
    ("calibration.magnetometer", "the magnetometer calibration kernel", 2.0),
    ("calibration.allan", "the Allan deviation kernel", 2.0),
    ("formats.csv_engine", "the CSV reader and writer", 6.0),
    ("formats.bags", "the ROS bag kernels", 6.0),
)


def user_cache_root() -> Path:
    """The per-user folder for imutool's caches: ``$NUMBA_CACHE_DIR/imutool`` when set, else the platform's place.

    Linux and other Unix: ``$XDG_CACHE_HOME/imutool`` or ``~/.cache/imutool``; macOS ``~/Library/Caches/imutool``;
    Windows ``%LOCALAPPDATA%\\imutool\\Cache``.
    """
    numba_dir = config.CACHE_DIR or os.environ.get("NUMBA_CACHE_DIR", "")
    if numba_dir:
        return Path(numba_dir).expanduser() / "imutool"
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA") or str(Path.home() / "AppData" / "Local")
        return Path(base) / "imutool" / "Cache"
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches" / "imutool"
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    return (Path(xdg) if os.path.isabs(xdg) else Path.home() / ".cache") / "imutool"


def _library_sources() -> list[Path]:
    """Every library .py file of the three packages, in a fixed order (imutool/cli excepted: no kernel reaches it)."""
    files: list[Path] = []
    for pkg in PACKAGES:
        top = _SITE / pkg
        for dirpath, dirnames, filenames in os.walk(top):
            here = Path(dirpath)
            dirnames[:] = sorted(
                d for d in dirnames if d != "__pycache__" and not (here == _SITE / "imutool" and d == "cli")
            )
            files.extend(here / f for f in sorted(filenames) if f.endswith(".py"))
    return files


def source_version() -> str:
    """12 hex digits that change with any library source file of the three packages, numba's and Python's version."""
    h = hashlib.blake2b(digest_size=16)
    h.update(f"numba {numba.__version__} python {sys.version_info[:3]} {sys.implementation.cache_tag}".encode())
    for path in _library_sources():
        h.update(path.relative_to(_SITE).as_posix().encode() + b"\0")
        try:
            h.update(path.read_bytes())
        except OSError:
            h.update(b"<unreadable>")
        h.update(b"\0")
    return h.hexdigest()[:12]


def _usable(folder: Path, private: bool = False) -> bool:
    """True if ``folder`` exists (made if needed) and a file can be written in it; ``private``: ours alone."""
    try:
        folder.mkdir(parents=True, exist_ok=True, mode=0o700 if private else 0o777)
        if private and hasattr(os, "getuid"):
            st = folder.lstat()  # in a shared temporary directory: a folder another user made is not ours to trust
            if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid() or st.st_mode & 0o022:
                return False
        tempfile.TemporaryFile(dir=folder).close()
        return True
    except OSError:
        return False


def _prune(root: Path, current: Path) -> None:
    """Remove version folders of ``root`` beyond the newest :data:`KEEP_VERSIONS` (never ``current``)."""
    try:
        found = [p for p in root.iterdir() if _VERSION_DIR.match(p.name) and p.is_dir() and p != current]
        found.sort(key=lambda p: p.stat().st_mtime, reverse=True)
    except OSError:
        return
    for old in found[KEEP_VERSIONS - 1 :]:
        shutil.rmtree(old, ignore_errors=True)


class _State:
    """The cache folder chosen for this process (found once, on the first kernel)."""

    folder: Path | None = None
    persistent = True  # False: a folder that lives only as long as this process
    version = ""


def cache_folder() -> Path | None:
    """This process's versioned kernel cache folder (made on first use), or None if no folder can be written."""
    if _State.folder is not None:
        return _State.folder
    _State.version = source_version()
    name = f"kernels-{_State.version}"
    uid = os.getuid() if hasattr(os, "getuid") else os.environ.get("USERNAME", "user")
    root = user_cache_root()
    candidates = [(root, False), (Path(tempfile.gettempdir()) / f"imutool-cache-{uid}", True)]
    for base, private in candidates:
        folder = base / name
        new = not folder.exists()
        if _usable(base, private) and _usable(folder):
            if new:
                _prune(base, folder)
            else:
                try:
                    os.utime(folder)  # newest-used first when pruning
                except OSError:
                    pass
            _State.folder = folder
            return folder
    try:  # nothing writable that lasts: compile into a folder of this process's own
        folder = Path(tempfile.mkdtemp(prefix="imutool-kernels-"))
    except OSError:
        return None
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    _State.folder, _State.persistent = folder, False
    return folder


def cache_is_persistent() -> bool:
    """False when no folder that outlives the process could be written: every run compiles again."""
    return _State.persistent


def _our_subfolder(py_file: str) -> str | None:
    """'imutool/capture' for a file of our packages, None for any other file."""
    for form in (os.path.abspath, os.path.realpath):
        try:
            rel = Path(form(py_file)).relative_to(form(str(_SITE)))
        except ValueError:
            continue
        if len(rel.parts) >= 2 and rel.parts[0] in PACKAGES:
            return rel.parent.as_posix()
    return None


_LocatorBase = getattr(caching, "_CacheLocator", object)  # numba's locator interface (abstract base)


class KernelCacheLocator(_LocatorBase):
    """numba cache locator for the kernels of imutool, calibration and formats: the per-user versioned folder."""

    def __init__(self, py_func, py_file: str, folder: Path):
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        self._cache_path = str(folder)

    @classmethod
    def from_function(cls, py_func, py_file):
        sub = _our_subfolder(py_file)
        if sub is None:
            return None  # another library's function: numba's own locators decide
        base = cache_folder()
        if base is None:
            return None
        self = cls(py_func, py_file, base / sub)
        try:
            self.ensure_cache_path()
        except OSError:
            return None
        return self

    def ensure_cache_path(self) -> None:
        os.makedirs(self._cache_path, exist_ok=True)  # writability was checked once for the version folder

    def get_cache_path(self) -> str:
        return self._cache_path

    def get_source_stamp(self) -> str:
        # the version hashes every source file of the packages: a changed file gives a new folder, not a new stamp
        return _State.version

    def get_disambiguator(self) -> str:
        return str(self._lineno)


def kernel_group(module: str) -> tuple[str, float] | None:
    """(what is compiling, about how many seconds) for a module of ours, None for another library's."""
    for prefix, what, seconds in KERNEL_GROUPS:
        if module == prefix or module.startswith(prefix + "."):
            return what, seconds
    if module.split(".", 1)[0] in PACKAGES:
        return f"the kernels of {module}", 0.0
    return None


class _CompileAnnouncer(event.Listener):
    """Says once per kernel group, before it compiles, that a kernel of ours missed the cache."""

    def __init__(self) -> None:
        self.announced: set[str] = set()
        self._starts: list[tuple[str, float] | None] = []
        self.times = os.environ.get("IMUTOOL_KERNEL_TIMES", "") not in ("", "0")
        self.silent = False  # True in formats.kernel_warm's second process

    def on_start(self, ev) -> None:
        disp = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
        func = getattr(disp, "py_func", None)
        module = getattr(func, "__module__", "") or ""
        group = kernel_group(module)
        cached = not isinstance(getattr(disp, "_cache", None), caching.NullCache)
        if group is None or not cached:
            self._starts.append(None)
            return
        what, seconds = group
        if what not in self.announced and not self.silent:
            self.announced.add(what)
            when = "first run only" if _State.persistent else "no writable cache folder: every run"
            about = f", ~{seconds:.0f} s" if seconds >= 1 else ""
            print(f"imutool: compiling {what} ({when}{about})", file=sys.stderr, flush=True)
        self._starts.append((f"{module}.{func.__qualname__}", time.perf_counter()))

    def on_end(self, ev) -> None:
        start = self._starts.pop() if self._starts else None
        if start is not None and self.times and not self.silent:
            print(f"imutool: compiled {start[0]} in {time.perf_counter() - start[1]:.1f} s", file=sys.stderr)


def _tolerant_save(numba_save):
    """numba's ``Cache.save_overload``, except that for our kernels a cache entry that cannot be written (a full
    disk, a file-size limit, a folder gone read-only) is skipped: the kernel is compiled and runs; the next run
    compiles it again. Another library's cache behaves as numba decides."""

    def save_overload(self, sig, data):
        try:
            numba_save(self, sig, data)
        except OSError:
            locator = getattr(getattr(self, "_impl", None), "locator", None)
            if not isinstance(locator, KernelCacheLocator):
                raise

    save_overload._imutool_tolerant = True  # type: ignore[attr-defined]
    return save_overload


def _install() -> None:
    cache_cls = getattr(caching, "Cache", None)
    save = getattr(cache_cls, "save_overload", None)
    if save is not None and not getattr(save, "_imutool_tolerant", False):
        cache_cls.save_overload = _tolerant_save(save)  # type: ignore[union-attr]
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    locators = getattr(impl, "_locator_classes", None)
    if isinstance(locators, list):
        if not any(getattr(c, "__name__", "") == KernelCacheLocator.__name__ for c in locators):
            locators.insert(0, KernelCacheLocator)
    else:  # numba's internals differ: at least keep every cache out of the package, in our versioned folder
        folder = cache_folder()
        if folder is not None and not config.CACHE_DIR:
            config.CACHE_DIR = str(folder)
    if not getattr(event, "_imutool_announcer", None):
        event._imutool_announcer = _CompileAnnouncer()
        event.register("numba:compile", event._imutool_announcer)


_install()
