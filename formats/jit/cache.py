"""Where the compiled numba kernels of ``imutool``, ``calibration`` and ``formats`` are cached: a per-user folder.

Every module with an ``@njit(cache=True)`` kernel imports this module first (``import
formats.jit.cache``); importing it puts :class:`KernelCacheLocator` at the front of numba's cache locators. The
locator claims only functions whose source file lies in our three packages (other libraries' numba caches are
untouched) and caches them in

    <root>/kernels-<version>/<package>/<sub-package>/      e.g. ~/.cache/imutool/kernels-3f2a9c01d4e7/imutool/

never inside the installed package, so ``pip install``, upgrade and uninstall leave nothing behind and a read-only
install works. ``<root>`` is ``$NUMBA_CACHE_DIR/imutool`` when ``NUMBA_CACHE_DIR`` is set, else the platform's
per-user cache folder (:func:`user_cache_root`). If that cannot be written (a read-only home), a private folder
in the temporary directory is used, and failing that a folder that lives only as long as the process.

``<version>`` is a short hash of the library files whose content can reach a compiled kernel, and of the numba and
Python versions. numba keys a kernel's cache on its own file only, so a kernel that calls a helper in another file, or
freezes a constant imported from one, would keep the old value after that file changed; with the version in the path
such a change starts a fresh cache. The files are found by a static scan (:func:`kernel_sources`, ``ast`` only, nothing
imported): the kernel files (a function decorated, or a statement wrapped, with one of numba's decorators imported from
``numba`` or :mod:`formats.jit.decorators`: ``njit``, ``jit``, ``vectorize``...) and every file that a name a kernel
mentions leads to, followed through the module-level statements that define it and through ``import``/``from ...
import`` of the three packages, transitively. A file no kernel name leads to (a route, a report, the CLI) can be edited
without recompiling anything. The scan takes ~0.4 s; its answer is kept per hash of every library file in
``<root>/kernel-sources.json``, so a process whose sources did not change pays only for reading and hashing them (~10
ms). Not seen by the scan: a kernel that reads a non-Python file at import, or a module that takes numba's decorators
from another of our modules than ``formats.jit.decorators`` (none does). The newest :data:`KEEP_VERSIONS` version
folders are kept, older ones are removed when a new one is made.

A kernel that is not in the cache yet is announced once per kernel group on stderr before it compiles
("imutool: compiling the filter's kernels (first run only, ~N s)"), from numba's own ``numba:compile`` event,
which numba raises only after its cache had no entry. ``IMUTOOL_KERNEL_TIMES=1`` also prints each compiled
kernel's time.
"""

from __future__ import annotations

import ast
import atexit
import hashlib
import json
import os
import re
import shutil
import stat
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numba
from numba.core import caching, config, event

from formats.jit import blas_probe, claims, typing_memo

typing_memo.install()  # numba's call typing asked once per distinct question (formats/jit/typing_memo.py)
blas_probe.install()  # numba's start-up without importing scipy.linalg (formats/jit/blas_probe.py)

PACKAGES = ("imutool", "calibration", "formats")
KEEP_VERSIONS = 3  # version folders kept (the current one included)
_VERSION_DIR = re.compile(r"^kernels-[0-9a-f]{12}$")
_SITE = Path(__file__).resolve().parents[2]  # the folder holding the three packages (site-packages or a clone)
PACKAGES_FOLDER = str(_SITE)
FOLDER_ENV = "IMUTOOL_KERNEL_FOLDER"  # set by formats.jit.warm for its second process: the parent's folder

# kernel groups: module-name prefix -> (what the user is told is compiling, about how long an empty cache takes to
# compile it on this project's 2-core machine without other load, s; twice that and more under load). A module of
# the three packages not listed here is announced by its own name. Kernels moved or re-timed: update this table.
# Measured 2026-11-27 (IMUTOOL_KERNEL_TIMES=1 imutool selfcheck, empty cache, load 1): the EKF 29 s (+ RTS 8 s and
# the zero-phase low-pass 1.4 s with --smooth), the gyro check 1.5 s, CSV 6 s, INS 7.5 s, heave 2.5 s, bags 5.6 s.
# 2026-11-28, with numba's call typing memoised (formats/jit/typing_memo.py): the EKF 18-23 s CPU alone, CSV reader
# 2.5-3.5 s + writer 2.1-3.4 s, INS 5.2-5.4 s, heave 1.7 s; the others not re-timed (~25 % less).
# 2026-12-06, without numba's unused wrappers (formats/jit/decorators.py), one process: the EKF 11-14 s, the CSV
# reader 1.6-2.9 s and writer 1.6-1.9 s.
KERNEL_GROUPS: tuple[tuple[str, str, float], ...] = (
    ("imutool.attitude", "the filter's kernels", 14.0),
    ("imutool.gyro_check", "the filter's kernels", 2.0),
    ("imutool.compass", "the compass filter's kernel", 2.0),
    ("imutool.heave", "the heave filter's kernels", 2.0),
    ("imutool.ins", "the INS kernels", 5.0),
    ("imutool.gyrofree", "the gyro-free kernel", 3.0),
    ("imutool.roll", "the roll statistics kernel", 2.0),
    ("imutool.roll_period", "the roll statistics kernel", 2.0),
    ("imutool.capture", "the bridge-frame decoder", 3.0),
    ("calibration.magnetometer", "the magnetometer calibration kernel", 2.0),
    ("calibration.allan", "the Allan deviation kernel", 2.0),
    ("formats.csv_engine", "the CSV reader and writer", 4.0),
    ("formats.bags", "the ROS bag kernels", 6.0),
)
# the share of a group's time a command waits when formats.jit.warm's second process compiles the other half of
# that group's kernel (the first filter's EKF sections, from the other end: 10 s against 20 s alone, 2026-11-28);
# a group the command compiles alone, or waits for whole, is announced at its full time
SHARED_SHARE = 0.5


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


def _library_sources(site: Path | None = None) -> list[Path]:
    """Every library .py file of the three packages, in a fixed order (imutool/cli excepted: no kernel reaches it)."""
    site = _SITE if site is None else site
    files: list[Path] = []
    for pkg in PACKAGES:
        top = site / pkg
        for dirpath, dirnames, filenames in os.walk(top):
            here = Path(dirpath)
            dirnames[:] = sorted(
                d for d in dirnames if d != "__pycache__" and not (here == site / "imutool" and d == "cli")
            )
            files.extend(here / f for f in sorted(filenames) if f.endswith(".py"))
    return files


_NUMBA_DECORATORS = frozenset(
    {
        "njit",
        "jit",
        "generated_jit",
        "vectorize",
        "guvectorize",
        "cfunc",
        "stencil",
        "jitclass",
        "overload",
        "overload_method",
        "overload_attribute",
        "register_jitable",
        "intrinsic",
    }
)
DECORATORS_MODULE = "formats.jit.decorators"  # numba's njit with imutool's defaults: counted as numba's own
_ALL = ("*",)  # a reference to a whole module (``import m`` used as ``m``, ``from m import *``)


class _Scan:
    """What one source file binds at module level and what each binding refers to (names, dotted references)."""

    def __init__(self, module: str, is_package: bool, text: bytes):
        self.package = module if is_package else module.rpartition(".")[0]
        self.defs: dict[str, set[tuple[str, ...]]] = {}  # module-level name -> references its statements make
        self.imports: dict[str, list[tuple[str, str | None]]] = {}  # name -> (module, attribute or None: the module)
        self.star: list[str] = []  # modules of ``from m import *``
        self.roots: set[str] = set()  # names whose statement uses a numba decorator: the kernels
        self._numba: set[str] = set()  # local names of numba's decorators
        self._numba_modules: set[str] = set()  # local names of numba itself (``import numba as nb``)
        try:
            tree = ast.parse(text)
        except (SyntaxError, ValueError):  # cannot be imported either; kept in the version if it mentions numba
            self.roots.add("")
            return
        self._bind_imports(tree.body)
        self._statements(tree.body, set())

    def _bind_imports(self, body: list[ast.stmt]) -> None:
        """Imports anywhere (a factory function may import what its kernel uses): statements are walked, not
        expressions (a tenth of the nodes; the scan's time halved)."""
        for stmt in body:
            if isinstance(stmt, (ast.Import, ast.ImportFrom)):
                self._bind(stmt)
                continue
            for field in ("body", "orelse", "finalbody", "handlers", "cases"):
                inner = getattr(stmt, field, None)
                if isinstance(inner, list):
                    for part in inner:  # an except handler or a match case holds a body of its own
                        if isinstance(part, ast.stmt):
                            self._bind_imports([part])
                        else:
                            self._bind_imports(getattr(part, "body", []))

    def _bind(self, node: ast.Import | ast.ImportFrom) -> None:
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "numba":
                    self._numba_modules.add(a.asname or "numba")
                elif a.asname:
                    self.imports.setdefault(a.asname, []).append((a.name, None))
                else:
                    top = a.name.split(".")[0]
                    self.imports.setdefault(top, []).append((top, None))
            return
        if node.level:
            base = self.package.split(".")[: max(0, len(self.package.split(".")) - node.level + 1)]
            module = ".".join([*base, node.module] if node.module else base)
        else:
            module = node.module or ""
        for a in node.names:
            if module == DECORATORS_MODULE and a.name in _NUMBA_DECORATORS:  # a decorator, and a file that counts
                self._numba.add(a.asname or a.name)
                self.imports.setdefault(a.asname or a.name, []).append((module, a.name))
            elif module.split(".")[0] == "numba":
                if a.name in _NUMBA_DECORATORS:
                    self._numba.add(a.asname or a.name)
            elif f"{module}.{a.name}" == DECORATORS_MODULE:  # ``from formats.jit import decorators``: its njit
                self._numba_modules.add(a.asname or a.name)
                self.imports.setdefault(a.asname or a.name, []).append((DECORATORS_MODULE, None))
            elif a.name == "*":
                self.star.append(module)
            else:
                self.imports.setdefault(a.asname or a.name, []).append((module, a.name))

    def _refs(self, node: ast.AST) -> tuple[set[tuple[str, ...]], bool]:
        """The names and dotted references (``qn.qmul``) in ``node``; True if one is a numba decorator."""
        refs: set[tuple[str, ...]] = set()
        numba_used = False
        stack = [node]
        while stack:
            n = stack.pop()
            if isinstance(n, ast.Attribute):
                chain = [n.attr]
                base = n.value
                while isinstance(base, ast.Attribute):
                    chain.append(base.attr)
                    base = base.value
                if isinstance(base, ast.Name):
                    refs.add((base.id, *reversed(chain)))
                    if base.id in self._numba_modules and n.attr in _NUMBA_DECORATORS:
                        numba_used = True
                    continue
                stack.append(base)
            elif isinstance(n, ast.Name):
                refs.add((n.id,))
                numba_used = numba_used or n.id in self._numba
            else:  # ast.iter_child_nodes, without its generator (the scan's most frequent step)
                for field in n._fields:
                    child = getattr(n, field, None)
                    if isinstance(child, ast.AST):
                        stack.append(child)
                    elif isinstance(child, list):
                        stack.extend(c for c in child if isinstance(c, ast.AST))
        return refs, numba_used

    def _statements(self, body: list[ast.stmt], outer: set[tuple[str, ...]]) -> None:
        for stmt in body:
            if isinstance(stmt, (ast.Import, ast.ImportFrom)):
                continue
            nested = [getattr(stmt, f, None) for f in ("body", "orelse", "finalbody")]
            if isinstance(stmt, (ast.If, ast.For, ast.AsyncFor, ast.While, ast.With, ast.AsyncWith, ast.Try)):
                head = [getattr(stmt, f) for f in ("test", "iter", "target") if hasattr(stmt, f)]
                head += [item for item in getattr(stmt, "items", [])]
                refs = set(outer)
                for h in head:
                    refs |= self._refs(h)[0]
                for block in nested:
                    if block:
                        self._statements(block, refs)
                for handler in getattr(stmt, "handlers", []):
                    self._statements(handler.body, refs)
                continue
            refs, is_kernel = self._refs(stmt)
            if isinstance(stmt, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                names = {stmt.name}
            else:
                names = {t[0] for t in self._targets(stmt)}
            if not names:  # a bare statement (``TABLE.update(...)``): it may change every name it mentions
                names = {r[0] for r in refs}
            for name in names:
                self.defs.setdefault(name, set()).update(refs | outer)
                if is_kernel:
                    self.roots.add(name)

    @staticmethod
    def _targets(stmt: ast.stmt) -> set[tuple[str, ...]]:
        targets: list[ast.AST] = []
        if isinstance(stmt, ast.Assign):
            targets = list(stmt.targets)
        elif isinstance(stmt, (ast.AnnAssign, ast.AugAssign)):
            targets = [stmt.target]
        found: set[tuple[str, ...]] = set()
        for t in targets:
            for n in ast.walk(t):
                if isinstance(n, ast.Name):
                    found.add((n.id,))
        return found


def _module_file(site: Path, module: str) -> Path | None:
    """The source file of a module of our packages (``a.b`` -> a/b.py or a/b/__init__.py), None for any other."""
    parts = module.split(".")
    if not parts[0] or parts[0] not in PACKAGES or (parts[:2] == ["imutool", "cli"]):
        return None
    path = site.joinpath(*parts)
    if path.with_suffix(".py").is_file():
        return path.with_suffix(".py")
    if (path / "__init__.py").is_file():
        return path / "__init__.py"
    return None


def kernel_sources(site: Path | None = None, texts: dict[Path, bytes] | None = None) -> list[Path]:
    """The library files whose content can reach a compiled kernel, found by a static scan (sorted).

    A kernel file uses one of numba's decorators (from ``numba`` or ``formats.jit.decorators``); from each kernel, every
    name it mentions is followed: to the module-level statement that defines it in its file (a constant, a helper, a
    table built at import), or through an ``import``/``from ... import`` into another module of the three packages, and
    on from there. A file is in the set as soon as one followed name lies in it.
    """
    site = _SITE if site is None else site
    texts = {} if texts is None else texts
    scans: dict[Path, _Scan] = {}

    def scan(path: Path) -> _Scan:
        if path not in scans:
            rel = path.relative_to(site).with_suffix("")
            is_package = rel.name == "__init__"
            module = ".".join(rel.parent.parts if is_package else rel.parts)
            text = texts[path] if path in texts else path.read_bytes()
            scans[path] = _Scan(module, is_package, text)
        return scans[path]

    work: list[tuple[Path, tuple[str, ...]]] = []
    for path in _library_sources(site):
        text = texts.get(path)
        if text is None:
            text = texts[path] = path.read_bytes()
        if b"numba" in text or b"decorators" in text:  # (relative imports of formats.jit.decorators too)
            work.extend((path, (name,)) for name in scan(path).roots)
    seen: set[tuple[Path, tuple[str, ...]]] = set()
    reached: set[Path] = set()

    def module_ref(module: str, rest: tuple[str, ...]) -> None:
        if rest and rest != _ALL and _module_file(site, f"{module}.{rest[0]}") is not None:
            module_ref(f"{module}.{rest[0]}", rest[1:])  # a sub-module reached as an attribute
            return
        path = _module_file(site, module)
        if path is not None:
            work.append((path, rest or _ALL))

    while work:
        path, ref = work.pop()
        if (path, ref) in seen:
            continue
        seen.add((path, ref))
        reached.add(path)
        s = scan(path)
        names = list(s.defs) + list(s.imports) if ref == _ALL else [ref[0]]
        if ref == _ALL:
            for module in s.star:
                module_ref(module, _ALL)
        rest = () if ref == _ALL else ref[1:]
        for name in names:
            found = False
            for inner in s.defs.get(name, ()):
                found = True
                work.append((path, inner))
            for module, attr in s.imports.get(name, ()):
                found = True
                if attr is None:
                    module_ref(module, rest)
                elif _module_file(site, f"{module}.{attr}") is not None:
                    module_ref(f"{module}.{attr}", rest)
                else:
                    module_ref(module, (attr, *rest))
            if not found:  # not bound here: perhaps by a ``from m import *``
                for module in s.star:
                    module_ref(module, (name, *rest))
    return sorted(reached)


MEMO_NAME = "kernel-sources.json"  # in the cache root: the scan's answer for the last few source trees
_MEMO_KEEP = 8


def _read_memo(memo: Path | None, tree: str) -> list[str] | None:
    try:
        found = json.loads(memo.read_text(encoding="utf-8")).get(tree) if memo is not None else None
    except (OSError, ValueError, AttributeError):
        return None
    if isinstance(found, list) and all(isinstance(f, str) for f in found):
        return found
    return None


def _write_memo(memo: Path | None, tree: str, files: list[str]) -> None:
    if memo is None:
        return
    try:
        entries = json.loads(memo.read_text(encoding="utf-8"))
        entries = entries if isinstance(entries, dict) else {}
    except (OSError, ValueError):
        entries = {}
    entries.pop(tree, None)
    entries[tree] = files
    entries = dict(list(entries.items())[-_MEMO_KEEP:])
    tmp = ""
    try:
        memo.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=memo.parent, prefix=".kernel-sources-", suffix=".tmp")
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(entries, f)
        os.replace(tmp, memo)  # whole or not at all: processes starting together may each write it
    except OSError:
        if tmp:
            try:
                os.unlink(tmp)
            except OSError:
                pass


def _source_tree() -> tuple[bytes, dict[Path, bytes], Any]:
    """(numba's, Python's versions; every library file's text; their hash)."""
    head = f"numba {numba.__version__} python {sys.version_info[:3]} {sys.implementation.cache_tag}".encode()
    texts: dict[Path, bytes] = {}
    tree = hashlib.blake2b(head, digest_size=16)
    for path in _library_sources():
        try:
            texts[path] = path.read_bytes()
        except OSError:
            texts[path] = b"<unreadable>"
        tree.update(path.relative_to(_SITE).as_posix().encode() + b"\0" + texts[path] + b"\0")
    return head, texts, tree


def new_source_tree() -> bool:
    """True when no process has used these library files with this cache yet (the source scan's memo has no
    answer for them, :func:`source_version`): a first run, whose kernels are not cached (~15 ms, no scan)."""
    if _State.folder is not None:
        return False
    _State.tree = _source_tree()  # kept for this process's source_version, read next
    return _read_memo(user_cache_root() / MEMO_NAME, _State.tree[2].hexdigest()) is None


def source_version(memo: Path | None = None) -> str:
    """12 hex digits that change with the files that can reach a compiled kernel and numba's and Python's version.

    The set of files is :func:`kernel_sources`; ``memo`` (a JSON file) keeps that answer per hash of every library
    file, so only the first process after a change of any file pays for the scan (~0.3 s; reading and hashing the
    files ~15 ms).
    """
    head, texts, tree = _State.tree or _source_tree()
    _State.tree = None
    files = _read_memo(memo, tree.hexdigest())
    if files is None:
        files = [p.relative_to(_SITE).as_posix() for p in kernel_sources(_SITE, texts)]
        _write_memo(memo, tree.hexdigest(), files)
    h = hashlib.blake2b(head, digest_size=16)
    for rel in files:
        text = texts.get(_SITE / rel, b"<gone>")
        h.update(rel.encode() + b"\0" + text + b"\0")
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
    shared: set[str] = set()  # the groups whose kernel a second process compiles half of (formats.jit.warm)
    tree = None  # (versions, library files' texts, their hash) read by new_source_tree for source_version


def compiling_in_two_processes(module: str) -> None:
    """Announce a shorter wait for the group of ``module``: a second process compiles half of its kernel's parts
    from the other end (formats.jit.warm). Other groups keep their full time."""
    group = kernel_group(module)
    if group is not None:
        _State.shared.add(group[0])


def cache_folder() -> Path | None:
    """This process's versioned kernel cache folder (made on first use), or None if no folder can be written."""
    if _State.folder is not None:
        return _State.folder
    _State.version = source_version(memo=user_cache_root() / MEMO_NAME)
    name = f"kernels-{_State.version}"
    given = os.environ.get(FOLDER_ENV, "")  # formats.jit.warm's second process: its parent's folder
    if given and Path(given).name == name and Path(given).is_absolute() and _usable(Path(given)):
        _State.folder = Path(given)
        return _State.folder
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
        self.silent = False  # True in formats.jit.warm's second process

    def on_start(self, ev) -> None:
        disp = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
        func = getattr(disp, "py_func", None)
        module = getattr(func, "__module__", "") or ""
        group = kernel_group(module)
        cached = not isinstance(getattr(disp, "_cache", None), caching.NullCache)
        if group is None or not cached:
            self._starts.append(None)
            return
        self.announce(group)
        self._starts.append((f"{module}.{func.__qualname__}", time.perf_counter()))

    def announce(self, group: tuple[str, float]) -> None:
        what, seconds = group
        if what not in self.announced and not self.silent:
            self.announced.add(what)
            when = "first run only" if _State.persistent else "no writable cache folder: every run"
            seconds *= SHARED_SHARE if what in _State.shared else 1.0
            about = f", ~{seconds:.0f} s" if seconds >= 1 else ""
            print(f"imutool: compiling {what} ({when}{about})", file=sys.stderr, flush=True)

    def on_end(self, ev) -> None:
        start = self._starts.pop() if self._starts else None
        if start is not None and self.times and not self.silent:
            print(f"imutool: compiled {start[0]} in {time.perf_counter() - start[1]:.1f} s", file=sys.stderr)


def announce_compile(module: str) -> None:
    """Say that the kernels of ``module`` are being compiled (once per group), for a command that waits while
    another process compiles them (formats.jit.warm.wait_for): numba's own event never fires in this one."""
    announcer = getattr(event, "_imutool_announcer", None)
    group = kernel_group(module)
    if announcer is not None and group is not None:
        announcer.announce(group)


TYPE_ANNOTATION_NOT_KEPT = "(numba's type annotation is not kept in imutool's kernel cache)"


def _tolerant_save(numba_save):
    """numba's ``Cache.save_overload``, except that for our kernels a cache entry that cannot be written (a full
    disk, a file-size limit, a folder gone read-only) is skipped: the kernel is compiled and runs; the next run
    compiles it again; and the entry keeps no type annotation. Another library's cache behaves as numba decides."""

    def save_overload(self, sig, data):
        locator = getattr(getattr(self, "_impl", None), "locator", None)
        ours = isinstance(locator, KernelCacheLocator)
        if ours and hasattr(data, "_replace") and hasattr(data, "type_annotation"):
            # numba saves the annotated source (its inspect_types text) with every entry: building that text was ~1 %
            # of a cold first filter; our entries keep a note instead (the in-memory result keeps its annotation)
            data = data._replace(type_annotation=TYPE_ANNOTATION_NOT_KEPT)
        try:
            numba_save(self, sig, data)
        except OSError:
            if not ours:
                raise
        finally:
            if claims.sharing():
                path = _claim_file(self, sig)
                if path is not None:
                    claims.release(path)  # saved (or not savable): a process waiting for it loads or compiles it

    save_overload._imutool_tolerant = True  # type: ignore[attr-defined]
    return save_overload


def _claim_file(cache, sig) -> Path | None:
    """The claim file of ``sig`` of one of our cached functions (formats.jit.claims), None for another library's."""
    if not isinstance(getattr(getattr(cache, "_impl", None), "locator", None), KernelCacheLocator):
        return None
    index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    return claims.claim_path(index, sig) if index else None


def _shared_load(numba_load):
    """numba's ``Cache.load_overload``, except that while two processes share a cold compile
    (formats.jit.claims), a miss of one of our functions claims it, or waits for the other process's copy."""

    def load_overload(self, sig, target_context):
        data = numba_load(self, sig, target_context)
        if data is not None or not claims.sharing():
            return data
        path = _claim_file(self, sig)
        if path is None:
            return data
        return claims.claim_or_wait(path, lambda: numba_load(self, sig, target_context))

    load_overload._imutool_shared = True  # type: ignore[attr-defined]
    return load_overload


def _install() -> None:
    cache_cls = getattr(caching, "Cache", None)
    save = getattr(cache_cls, "save_overload", None)
    if save is not None and not getattr(save, "_imutool_tolerant", False):
        cache_cls.save_overload = _tolerant_save(save)  # type: ignore[union-attr]
    load = getattr(cache_cls, "load_overload", None)
    if load is not None and not getattr(load, "_imutool_shared", False):
        cache_cls.load_overload = _shared_load(load)  # type: ignore[union-attr]
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
