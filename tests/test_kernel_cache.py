"""Compiled kernels are cached per user and per source version, never inside the installed package.

The cold-cache test runs a command whose one kernel compiles in seconds (``allan`` on a Parquet file: no CSV
kernels) twice with an empty ``NUMBA_CACHE_DIR``: the first run says it compiles, the second does not, and the
kernel's cache files are in the user's folder.
"""

from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

import formats.jit.cache as kc

ROOT = Path(__file__).resolve().parents[1]
KERNEL_PACKAGES = ("imutool", "calibration", "formats")


def _cli(args: list[str], cwd: Path, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", "from imutool.cli import main; main()", *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        stdin=subprocess.DEVNULL,
    )


@pytest.mark.slow
def test_cold_cache_says_it_compiles_once_and_caches_in_the_user_folder(tmp_path):
    pytest.importorskip("pyarrow")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "IMUTOOL_KERNEL_TIMES")}
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "numba")
    r = _cli(["simulate", "static", "--duration", "30", "-o", "s.parquet"], tmp_path, env)
    assert r.returncode == 0, r.stderr
    first = _cli(["allan", "s.parquet", "-o", "a.yaml"], tmp_path, env)
    assert first.returncode == 0, first.stderr
    said = [line for line in first.stderr.splitlines() if line.startswith("imutool: compiling")]
    assert len(said) == 1, first.stderr  # once, for the one kernel group the command compiles
    assert said[0].startswith("imutool: compiling the Allan deviation kernel (first run only"), said
    second = _cli(["allan", "s.parquet", "-o", "b.yaml"], tmp_path, env)
    assert second.returncode == 0, second.stderr
    assert "compiling" not in second.stderr, second.stderr
    index = list((tmp_path / "numba" / "imutool").glob("kernels-*/calibration/allan._adev_axis-*.nbi"))
    assert len(index) == 1, sorted(p.as_posix() for p in (tmp_path / "numba").rglob("*"))


def test_every_kernel_module_imports_the_cache_before_its_first_kernel():
    """A module whose kernels were decorated before formats.jit.cache was imported would cache in the package."""
    missing = []
    for pkg in KERNEL_PACKAGES:
        for py in sorted((ROOT / pkg).rglob("*.py")):
            text = py.read_text(encoding="utf-8")
            cached = ("cache=True", "**INLINED", "**CALLED")  # the last two: imutool/attitude/layout.py's flag sets
            if not any(c in text for c in cached) or py.as_posix().endswith("formats/jit/cache.py"):
                continue
            tree = ast.parse(text)
            first_kernel = min(
                (n.lineno for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and n.decorator_list),
                default=10**9,
            )
            imports = [
                n.lineno
                for n in ast.walk(tree)
                if (isinstance(n, ast.Import) and any(a.name == "formats.jit.cache" for a in n.names))
                or (
                    isinstance(n, ast.ImportFrom)
                    and any(a.name == "cache" for a in n.names)
                    and (n.module == "formats.jit" or (n.level >= 1 and n.module == "jit" and pkg == "formats"))
                )
            ]
            if not imports or min(imports) > first_kernel:
                missing.append(py.relative_to(ROOT).as_posix())
    assert not missing, f"modules with cache=True kernels that do not import formats.jit.cache first: {missing}"


def test_locator_claims_our_files_only():
    assert kc._our_subfolder(str(ROOT / "imutool" / "attitude.py")) == "imutool"
    assert kc._our_subfolder(str(ROOT / "imutool" / "capture" / "bridge.py")) == "imutool/capture"
    assert kc._our_subfolder(str(ROOT / "formats" / "csv_engine.py")) == "formats"
    import numba

    assert kc._our_subfolder(numba.__file__) is None
    assert kc._our_subfolder(str(ROOT / "tests" / "test_kernel_cache.py")) is None
    # the running kernels of this process are cached in the versioned user folder, not next to their source
    from formats import csv_engine

    kernels = [obj for obj in vars(csv_engine).values() if hasattr(obj, "stats")]
    paths = {k.stats.cache_path for k in kernels if k.stats.cache_path}  # the cached ones (helpers are compiled in)
    assert paths and all(Path(p).parent.name.startswith("kernels-") for p in paths), paths
    assert all(not Path(p).is_relative_to(ROOT / "formats") for p in paths), paths
    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    assert impl._locator_classes[0] is kc.KernelCacheLocator


def test_user_cache_root_per_platform(monkeypatch, tmp_path):
    monkeypatch.setattr(kc.config, "CACHE_DIR", "")
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setattr(kc.Path, "home", classmethod(lambda cls: tmp_path / "home"))
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert kc.user_cache_root() == tmp_path / "xdg" / "imutool"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/ignored")
    assert kc.user_cache_root() == tmp_path / "home" / ".cache" / "imutool"
    monkeypatch.setattr(sys, "platform", "darwin")
    assert kc.user_cache_root() == tmp_path / "home" / "Library" / "Caches" / "imutool"
    monkeypatch.setattr(sys, "platform", "win32")
    monkeypatch.setenv("LOCALAPPDATA", str(tmp_path / "local"))
    assert kc.user_cache_root() == tmp_path / "local" / "imutool" / "Cache"
    monkeypatch.setattr(kc.config, "CACHE_DIR", str(tmp_path / "nc"))  # NUMBA_CACHE_DIR wins as the root
    assert kc.user_cache_root() == tmp_path / "nc" / "imutool"


def _tree(site: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        (site / rel).parent.mkdir(parents=True, exist_ok=True)
        (site / rel).write_text(text)


# a small tree with every way a kernel reaches another file, and files no kernel reaches
SMALL = {
    "imutool/__init__.py": "from imutool.plain import route  # re-exported: no kernel reaches it\n",
    "imutool/kern.py": (
        "import numba as nb\n"
        "from numba import njit\n"
        "from formats import units\n"
        "from imutool import sub\n"
        "from imutool.plain import route\n"
        "from .consts import BASE\n"
        "SCALE = BASE * 2\n"
        "@njit(cache=True)\n"
        "def k(x):\n"
        "    return x * SCALE + units.G + sub.helpers.h(x)\n"
        "@nb.vectorize\n"
        "def v(x):\n"
        "    return x\n"
        "def run():\n"
        "    return route(k(1.0))\n"
    ),
    "imutool/consts.py": "from formats.deep import DEEP\nBASE = DEEP + 1\n",
    "imutool/plain.py": "from formats.errors import E\ndef route(x):\n    return x\n",
    "imutool/sub/__init__.py": "",
    "imutool/sub/helpers.py": "from numba import njit\n@njit\ndef h(x):\n    return x\n",
    "imutool/wrapped.py": "import numba\ndef _f(x):\n    return x\nf = numba.njit(_f)\n",
    "imutool/uses_numba_only.py": "import numba\nnumba.set_num_threads(1)\n",
    "imutool/cli/__init__.py": "",
    "calibration/__init__.py": "",
    "formats/__init__.py": "",
    "formats/units.py": "G = 9.8\n",
    "formats/deep.py": "DEEP = 1\n",
    "formats/errors.py": "class E(Exception):\n    pass\n",
}


def test_the_scan_finds_the_kernel_files_and_what_their_kernels_reach(tmp_path):
    _tree(tmp_path, SMALL)
    found = [p.relative_to(tmp_path).as_posix() for p in kc.kernel_sources(tmp_path)]
    assert found == [
        "formats/deep.py",  # a constant that a constant of a kernel's file is made from
        "formats/units.py",  # a module's attribute
        "imutool/consts.py",  # a relative import
        "imutool/kern.py",
        "imutool/sub/helpers.py",  # a kernel called through a sub-package's module
        "imutool/wrapped.py",  # numba.njit called, not written as a decorator
    ]


def test_the_scan_counts_formats_jit_decorators_as_numbas_decorator_in_every_spelling(tmp_path):
    """A kernel decorated with formats.jit.decorators' njit is a kernel file however the module is imported (a
    file that never writes "numba" was skipped by the first version of the text filter), and the decorators'
    own file is in the version (its defaults decide which wrappers a cached entry holds)."""
    tree = {k: v for k, v in SMALL.items() if not k.startswith("imutool/")}
    tree.update(
        {
            "imutool/__init__.py": "",
            "formats/jit/__init__.py": "",
            "formats/jit/decorators.py": "import numba\ndef njit(*a, **k):\n    return numba.njit(*a, **k)\n",
            "formats/rel.py": "from .jit.decorators import njit\nfrom .deep import DEEP\n@njit\ndef r():\n"
            "    return DEEP\n",
            "imutool/absolute.py": "from formats.jit.decorators import njit\n@njit(cache=True)\ndef a():\n"
            "    return 1\n",
            "imutool/module.py": "from formats.jit import decorators\nfrom formats.units import G\n"
            "@decorators.njit\ndef m():\n    return G\n",
            "imutool/plain2.py": "from formats.jit import decorators  # no kernel\nX = 1\n",
        }
    )
    _tree(tmp_path, tree)
    found = [p.relative_to(tmp_path).as_posix() for p in kc.kernel_sources(tmp_path)]
    assert found == [
        "formats/deep.py",
        "formats/jit/decorators.py",
        "formats/rel.py",
        "formats/units.py",
        "imutool/absolute.py",
        "imutool/module.py",
    ]


def test_version_follows_only_what_a_kernel_can_reach(monkeypatch, tmp_path):
    _tree(tmp_path, SMALL)
    monkeypatch.setattr(kc, "_SITE", tmp_path)
    v0 = kc.source_version()
    assert len(v0) == 12 and int(v0, 16) >= 0
    os.utime(tmp_path / "formats" / "deep.py", (time.time() + 100, time.time() + 100))
    assert kc.source_version() == v0, "a touched file with the same content is the same version"
    for rel in ("imutool/plain.py", "imutool/__init__.py", "formats/errors.py", "imutool/cli/__init__.py"):
        (tmp_path / rel).write_text((tmp_path / rel).read_text() + "# edited: no kernel reaches it\n")
        assert kc.source_version() == v0, rel
    (tmp_path / "calibration" / "new.py").write_text("X = 1\n")
    assert kc.source_version() == v0
    (tmp_path / "formats" / "deep.py").write_text("DEEP = 2\n")  # frozen into a kernel through two files
    v1 = kc.source_version()
    assert v1 != v0
    (tmp_path / "calibration" / "new.py").write_text("from numba import njit\n@njit\ndef n():\n    return 1\n")
    assert kc.source_version() not in (v0, v1), "a new kernel file"


def _copy_of_the_packages(site: Path) -> None:
    for pkg in KERNEL_PACKAGES:
        shutil.copytree(ROOT / pkg, site / pkg, ignore=shutil.ignore_patterns("__pycache__", "cli"))


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text(encoding="utf-8")
    assert text.count(old) == 1, (path, old)
    path.write_text(text.replace(old, new), encoding="utf-8")


def test_version_of_the_real_packages_ignores_routes_and_follows_kernels_and_their_constants(monkeypatch, tmp_path):
    """Editing a route does not throw the compiled kernels away; editing a kernel or a constant it freezes does."""
    _copy_of_the_packages(tmp_path)
    monkeypatch.setattr(kc, "_SITE", tmp_path)
    memo = tmp_path / "cache" / kc.MEMO_NAME
    v0 = kc.source_version(memo)
    assert memo.is_file() and kc.source_version(memo) == v0
    _edit(tmp_path / "imutool" / "routes" / "__init__.py", "def read_source(", "# a developer's edit\ndef read_source(")
    report = tmp_path / "imutool" / "report" / "route.py"
    report.write_text(report.read_text(encoding="utf-8") + "# a developer's edit\n", encoding="utf-8")
    assert kc.source_version(memo) == v0
    _edit(tmp_path / "imutool" / "attitude" / "layout.py", "LP_MEAN_MAX = 0.25", "LP_MEAN_MAX = 0.3")
    v1 = kc.source_version(memo)
    assert v1 != v0
    _edit(
        tmp_path / "imutool" / "heave.py", "def _complementary_kernel(", "# a kernel's file\ndef _complementary_kernel("
    )
    assert kc.source_version(memo) not in (v0, v1)


def test_a_memo_of_another_tree_or_a_broken_one_is_not_trusted(monkeypatch, tmp_path):
    _tree(tmp_path, SMALL)
    monkeypatch.setattr(kc, "_SITE", tmp_path)
    memo = tmp_path / "memo.json"
    v0 = kc.source_version(memo)
    memo.write_text("{not json")
    assert kc.source_version(memo) == v0
    entries = json.loads(memo.read_text())
    assert list(entries.values()) == [[p.relative_to(tmp_path).as_posix() for p in kc.kernel_sources(tmp_path)]]
    (tmp_path / "imutool" / "kern.py").write_text(SMALL["imutool/kern.py"] + "# edited\n")
    assert kc.source_version(memo) != v0 and len(json.loads(memo.read_text())) == 2


def test_old_versions_are_pruned(tmp_path):
    now = time.time()
    names = [f"kernels-{i:012x}" for i in range(6)]
    for age, name in enumerate(names):
        (tmp_path / name).mkdir()
        os.utime(tmp_path / name, (now - 100 * age, now - 100 * age))
    (tmp_path / "not-ours").mkdir()
    current = tmp_path / names[5]  # the oldest by date, but the one in use
    kc._prune(tmp_path, current)
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == sorted([*names[: kc.KEEP_VERSIONS - 1], names[5], "not-ours"])


def test_unwritable_root_falls_back_without_a_crash(monkeypatch, tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setattr(kc, "user_cache_root", lambda: blocker / "imutool")  # cannot be made, even by root
    monkeypatch.setattr(kc.tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    monkeypatch.setattr(kc._State, "folder", None)
    monkeypatch.setattr(kc._State, "persistent", True)
    folder = kc.cache_folder()
    assert folder is not None and folder.parent.parent == tmp_path / "tmp" and kc._State.persistent
    assert folder.parent.name.startswith("imutool-cache-") and folder.name.startswith("kernels-")
    if hasattr(os, "getuid"):
        assert (folder.parent.stat().st_mode & 0o077) == 0, "the shared temporary folder is private"
    # the temporary directory's folder is not usable either (another user's, or a file): a folder for this run
    for p in sorted(folder.parent.rglob("*"), reverse=True):
        p.rmdir()
    folder.parent.rmdir()
    folder.parent.write_text("squatted")
    monkeypatch.setattr(kc._State, "folder", None)
    folder = kc.cache_folder()
    assert folder is not None and folder.is_dir() and not kc._State.persistent
    assert folder.parent == tmp_path / "tmp" and folder.name.startswith("imutool-kernels-")


def test_only_the_group_split_between_two_processes_is_announced_at_its_share(monkeypatch, capsys):
    """The filter's EKF sections are compiled from both ends, so its wait is about half; the CSV kernels (the command
    compiles the parser itself) and the INS kernel (the command waits for all of it) keep their full estimates."""
    announcer = kc._CompileAnnouncer()
    monkeypatch.setattr(kc._State, "shared", set())
    monkeypatch.setattr(kc._State, "persistent", True)
    kc.compiling_in_two_processes("imutool.attitude.kernel")
    for module in ("imutool.attitude.accel", "formats.csv_engine", "imutool.ins", "imutool.attitude.rest"):
        group = kc.kernel_group(module)
        assert group is not None
        announcer.announce(group)
    filter_s, csv_s, ins_s = (kc.kernel_group(m)[1] for m in ("imutool.attitude", "formats.csv_engine", "imutool.ins"))
    assert filter_s * kc.SHARED_SHARE >= 1 and csv_s >= 1 and ins_s >= 1
    said = capsys.readouterr().err.splitlines()
    assert said == [
        f"imutool: compiling the filter's kernels (first run only, ~{filter_s * kc.SHARED_SHARE:.0f} s)",
        f"imutool: compiling the CSV reader and writer (first run only, ~{csv_s:.0f} s)",
        f"imutool: compiling the INS kernels (first run only, ~{ins_s:.0f} s)",
    ]  # once per group
