"""The built wheel carries every module and data file the packages read (schemas, presets, layouts).

A wheel that lacks a data file works in the editable install the other tests use and fails for every user
who runs ``pip install``; this test builds the wheel from a copy of the source packages and compares.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

# building the wheel takes ~7 s: out of the quick loop; CI runs these (and installs the package as a user does)
pytestmark = pytest.mark.slow

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
    # `run`: `main`, then the process ends without the module teardown (imutool/cli/__init__.py)
    assert re.search(r"^imutool\s*=\s*imutool\.cli:run\s*$", text, flags=re.M), text


def test_uninstall_leaves_nothing_behind_after_kernels_compiled(wheel, tmp_path):
    """A user's lifecycle in a fresh venv: install the wheel, run a compiled kernel (cold per-user cache, no
    NUMBA_CACHE_DIR), uninstall — nothing of imutool is left in site-packages (numba once cached kernels in the
    installed package's __pycache__, which pip does not own: a folder without __init__.py stayed behind and was
    imported as a namespace package by the next install)."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    py = venv / ("Scripts/python.exe" if os.name == "nt" else "bin/python")
    site = Path(
        subprocess.run(
            [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            capture_output=True,
            text=True,
            check=True,
            timeout=60,
        ).stdout.strip()
    )
    # the dependencies (numpy, numba ...) are read from this environment; imutool comes from the wheel alone
    here = sysconfig.get_paths()
    (site / "_deps_of_the_test.pth").write_text("\n".join(dict.fromkeys([here["purelib"], here["platlib"]])) + "\n")
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "--python", str(py)]
    r = subprocess.run(
        [*pip, "install", "--quiet", "--no-deps", "--no-index", str(wheel)], capture_output=True, text=True, timeout=300
    )
    if r.returncode != 0 and "no such option: --python" in r.stderr:
        pytest.skip("pip < 22.3 has no --python option")
    assert r.returncode == 0, r.stderr[-2000:]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NUMBA_CACHE_DIR")}
    cache = str(tmp_path / "cache")  # a cold per-user cache (the platform's default place, no NUMBA_CACHE_DIR)
    env.update(HOME=str(tmp_path / "home"), XDG_CACHE_HOME=cache, LOCALAPPDATA=cache)
    code = (
        "import numpy as np, imutool\n"
        "from calibration.allan import allan_deviation\n"
        "allan_deviation(np.random.default_rng(0).normal(size=2000), 100.0)\n"
        "print(imutool.__file__)\n"
    )
    r = subprocess.run([str(py), "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert Path(r.stdout.strip()).is_relative_to(site), f"imutool imported from {r.stdout.strip()}, not the wheel"
    assert "imutool: compiling the Allan deviation kernel" in r.stderr, "the run compiled nothing: a warm cache?"
    assert list((tmp_path / "cache").rglob("allan._adev_axis-*.nbi")), "the kernel was not cached in the user's folder"
    in_package = [p for pkg in PACKAGES for p in (site / pkg).rglob("*.nb[ic]")]
    assert not in_package, f"kernels cached inside the installed package: {in_package[:3]}"
    r = subprocess.run([*pip, "uninstall", "--quiet", "-y", "imutool"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    left = [p.name for p in site.iterdir() if p.name.split("-")[0] in (*PACKAGES, "imutool")]
    assert not left, f"left in site-packages after pip uninstall: {left}"
