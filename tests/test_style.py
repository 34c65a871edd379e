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
