"""House rules that are cheap to check: ruff clean, layering (imports only go downward), no copied data."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _ruff(*args: str) -> subprocess.CompletedProcess:
    if (
        shutil.which("ruff") is None
        and subprocess.run([sys.executable, "-m", "ruff", "--version"], capture_output=True).returncode != 0
    ):
        pytest.skip("ruff not installed (it is in the [test] extra)")
    return subprocess.run(
        [sys.executable, "-m", "ruff", *args, "--no-cache", str(ROOT)], capture_output=True, text=True
    )


def test_ruff_clean():
    r = _ruff("check")
    assert r.returncode == 0, r.stdout[-3000:]


def test_ruff_formatted():
    """`ruff format` was applied once to the whole tree; this keeps it so (run `ruff format .` to mend)."""
    r = _ruff("format", "--check")
    assert r.returncode == 0, r.stdout[-3000:]


def _imports(pkg: str) -> list[tuple[Path, str]]:
    out = []
    for f in (ROOT / pkg).rglob("*.py"):
        tree = ast.parse(f.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                out += [(f, a.name) for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                out.append((f, node.module))
    return out


@pytest.mark.parametrize(
    "pkg,forbidden", [("formats", ("imutool", "calibration", "click")), ("calibration", ("imutool", "click"))]
)
def test_imports_only_go_downward(pkg, forbidden):
    bad = [f"{f.relative_to(ROOT)} imports {m}" for f, m in _imports(pkg) if m.split(".")[0] in forbidden]
    assert not bad, bad


def test_kernels_take_njit_from_formats_jit_decorators():
    """A kernel takes ``njit`` as ``from formats.jit.decorators import njit`` (no wrappers numba would build and
    never use; the cache's source scan looks for that module's name), not from numba under any name."""
    bad = []
    for pkg in ("imutool", "calibration", "formats"):
        for f in (ROOT / pkg).rglob("*.py"):
            if f == ROOT / "formats" / "jit" / "decorators.py":
                continue
            tree = ast.parse(f.read_text(encoding="utf-8"))
            numba_names = {"numba"}  # local names of numba itself (``import numba as nb``)
            for node in ast.walk(tree):
                if isinstance(node, ast.Import):
                    numba_names |= {a.asname or a.name for a in node.names if a.name == "numba"}
            for node in ast.walk(tree):
                where = f"{f.relative_to(ROOT)}:{getattr(node, 'lineno', 0)}"
                if isinstance(node, ast.ImportFrom):
                    names = {a.name for a in node.names}
                    if (node.module or "").split(".")[0] == "numba" and names & {"njit", "jit"}:
                        bad.append(f"{where}: from {node.module} import njit/jit")
                    elif "decorators" in (node.module or "") or "decorators" in names:
                        if node.level or node.module != "formats.jit.decorators":
                            bad.append(f"{where}: take it as `from formats.jit.decorators import njit`")
                elif isinstance(node, ast.Attribute) and node.attr in ("njit", "jit"):
                    if isinstance(node.value, ast.Name) and node.value.id in numba_names:
                        bad.append(f"{where}: {node.value.id}.{node.attr}")
    assert not bad, bad


def test_no_shared_data_copied_into_repo():
    shared = ROOT.parent / "shared" / "data"
    if not shared.exists():
        pytest.skip("../shared/data absent")
    names = {
        p.name
        for p in shared.rglob("*")
        if p.is_file() and p.suffix in (".csv", ".bag", ".db3", ".mcap", ".log", ".mat", ".hdf5")
    }
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True).stdout.split()
    copies = [t for t in tracked if Path(t).name in names]
    assert not copies, copies


def _module_graph() -> dict[str, set[str]]:
    """Every library module → the library modules it imports (function-level imports included)."""
    files = {}
    for pkg in ("imutool", "calibration", "formats"):
        for f in (ROOT / pkg).rglob("*.py"):
            parts = list(f.relative_to(ROOT).with_suffix("").parts)
            files[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    graph: dict[str, set[str]] = {m: set() for m in files}
    for mod, f in files.items():
        package = mod.split(".") if f.name == "__init__.py" else mod.split(".")[:-1]
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(package[: len(package) - node.level + 1] + ([base] if base else []))
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in files else base for a in node.names]
            else:
                continue
            for t in targets:
                while t and t not in files:
                    t = t.rpartition(".")[0]
                if t and t != mod:
                    graph[mod].add(t)
    return graph


def test_no_import_cycle():
    """No library module imports itself round a cycle (an import inside a function counts too: it hides one)."""
    graph = _module_graph()
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(m: str, path: list[str]) -> list[str] | None:
        state[m] = 1
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                return path + [m, n]
            if n not in state and (cycle := visit(n, path + [m])):
                return cycle
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state:
            cycle = visit(m, [])
            assert cycle is None, " → ".join(cycle[cycle.index(cycle[-1]) :])
    assert "imutool.attitude.kernel" in graph and "imutool.quaternion" in graph["imutool.gyro_check"]


MAX_MODULE_LINES, MAX_KERNEL_LINES = 600, 120


def _is_njit(dec: ast.expr) -> bool:
    f = dec.func if isinstance(dec, ast.Call) else dec
    return (f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")) in ("njit", "jit")


def test_attitude_modules_and_kernels_are_small():
    """The attitude filter stays a package of small parts (issue 36): no module in imutool/attitude/ over 600 lines,
    no numba function over 120 (from its decorator to the end of its body) — the EKF's loop is a short sequence of
    one section per sensor (kernel.py), each section a function of its own."""
    big = []
    for f in sorted((ROOT / "imutool" / "attitude").glob("*.py")):
        text = f.read_text(encoding="utf-8")
        if (n := len(text.splitlines())) > MAX_MODULE_LINES:
            big.append(f"{f.name}: {n} lines (at most {MAX_MODULE_LINES})")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef) and any(_is_njit(d) for d in node.decorator_list):
                n = node.end_lineno - min(d.lineno for d in node.decorator_list) + 1
                if n > MAX_KERNEL_LINES:
                    big.append(f"{f.name}:{node.name}: {n} lines (at most {MAX_KERNEL_LINES})")
    assert not big, big
