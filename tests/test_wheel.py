"""The built wheel carries every module and data file the packages read (schemas, presets, layouts).

A wheel that lacks a data file works in the editable install the other tests use and fails for every user
who runs ``pip install``; this test builds the wheel from a copy of the source packages and compares.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("imutool", "calibration", "formats")
# files read at run time through importlib.resources or relative to a module's __file__
_RESOURCE_PATTERNS = (
    re.compile(r"""resources\.files\(\s*["']([\w.]+)["']\s*\)((?:\s*\.joinpath\(\s*["'][^"']+["']\s*\))+)"""),
    re.compile(r"""resources\.files\(\s*["']([\w.]+)["']\s*\)((?:\s*/\s*["'][^"']+["'])+)"""),
)
_FILE_PATTERN = re.compile(r"""Path\(__file__\)(?:\.resolve\(\))?\.parent((?:\s*/\s*["'][^"']+["'])+)""")


def _source_files() -> tuple[set[str], set[str]]:
    """(python modules, data files) of the packages, as wheel paths."""
    mods: set[str] = set()
    data: set[str] = set()
    for pkg in PACKAGES:
        for p in (ROOT / pkg).rglob("*"):
            if not p.is_file() or "__pycache__" in p.parts or p.suffix in (".pyc", ".pyo") or p.name.startswith("."):
                continue
            rel = p.relative_to(ROOT).as_posix()
            (mods if p.suffix == ".py" else data).add(rel)
    return mods, data


def _referenced_resources() -> set[str]:
    """Data files the code opens via importlib.resources or Path(__file__).parent / 'name'."""
    out: set[str] = set()
    for pkg in PACKAGES:
        for py in (ROOT / pkg).rglob("*.py"):
            text = py.read_text(encoding="utf-8")
            for pat in _RESOURCE_PATTERNS:
                for m in pat.finditer(text):
                    parts = re.findall(r"""["']([^"']+)["']""", m.group(2))
                    out.add("/".join([m.group(1).replace(".", "/"), *parts]))
            for m in _FILE_PATTERN.finditer(text):
                parts = re.findall(r"""["']([^"']+)["']""", m.group(1))
                out.add("/".join([py.parent.relative_to(ROOT).as_posix(), *parts]))
    return out


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    src = tmp_path_factory.mktemp("src")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    for pkg in PACKAGES:
        shutil.copytree(ROOT / pkg, src / pkg, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info"))
    dist = tmp_path_factory.mktemp("dist")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--quiet",
            "--no-deps",
            "--disable-pip-version-check",
            "-w",
            str(dist),
            str(src),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    wheels = list(dist.glob("imutool-*.whl"))
    assert len(wheels) == 1, wheels
    return wheels[0]


@pytest.fixture(scope="module")
def wheel_names(wheel) -> set[str]:
    with zipfile.ZipFile(wheel) as z:
        return set(z.namelist())


def test_wheel_has_every_module(wheel_names):
    mods, _ = _source_files()
    assert mods, "no package modules found"
    missing = sorted(mods - wheel_names)
    assert not missing, f"modules missing from the wheel: {missing}"


def test_wheel_has_every_data_file(wheel_names):
    _, data = _source_files()
    missing = sorted(data - wheel_names)
    assert not missing, f"data files in the source packages but not in the wheel (package-data?): {missing}"


def test_every_resource_the_code_reads_is_in_the_wheel(wheel_names):
    refs = _referenced_resources()
    # the evidence schema is read through importlib.resources: the scan must find at least that one
    assert "imutool/report/schema/evidence.schema.json" in refs
    missing = sorted(r for r in refs if r not in wheel_names and not any(n.startswith(r + "/") for n in wheel_names))
    assert not missing, f"files the code reads but the wheel lacks: {missing}"


def test_console_script_declared(wheel, wheel_names):
    ep = [n for n in wheel_names if n.endswith(".dist-info/entry_points.txt")]
    assert len(ep) == 1, "no entry_points.txt in the wheel"
    with zipfile.ZipFile(wheel) as z:
        text = z.read(ep[0]).decode()
    assert re.search(r"^imutool\s*=\s*imutool\.cli:main\s*$", text, flags=re.M), text
