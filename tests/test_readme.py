"""Every command in the README's ```bash blocks runs, top to bottom, in a fresh copy of the repository.

The tracked files are copied to a temporary directory (a fresh clone without git), and each command line is run
there with ``bash -e`` in README order, with the installed ``imutool`` on PATH. Skipped: lines ending in
``# hardware`` (a real serial port or I2C bus), the test-suite command at the top (this test is part of it),
the ``pip install . &&`` prefix of the main job (the package is already installed) and ``pip install '.[extra]'``
lines (the test extras hold every extra). Comment lines are not run,
so "if you have the recordings" examples may be written as comments.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def readme_commands(text: str) -> list[str]:
    """Command lines of the ```bash blocks in order: continuation lines joined, comment-only lines dropped."""
    cmds: list[str] = []
    for block in re.findall(r"^```bash[ \t]*\n(.*?)^```", text, flags=re.S | re.M):
        pending = ""
        for raw in block.splitlines():
            line = raw.rstrip()
            if not pending and (not line.strip() or line.lstrip().startswith("#")):
                continue
            if line.endswith("\\"):
                pending += line[:-1] + " "
                continue
            cmds.append((pending + line).strip())
            pending = ""
        if pending:
            cmds.append(pending.strip())
    return cmds


def _is_hardware(cmd: str) -> bool:
    return bool(re.search(r"#\s*hardware\s*$", cmd))


def runnable(cmds: list[str]) -> list[str]:
    """What the test runs: the first two commands are the set-up (install + main job, install + test suite)."""
    assert len(cmds) >= 2, "README has fewer than two fenced commands"
    assert cmds[0].startswith("pip install . && "), cmds[0]
    assert "pytest" in cmds[1], cmds[1]
    return [cmds[0][len("pip install . && ") :]] + [c for c in cmds[2:] if not _is_hardware(c) and not _is_extra(c)]


def _is_extra(cmd: str) -> bool:
    """`pip install '.[extra]'` lines: the test extras already hold every extra the README uses, and installing
    the temporary copy would replace the package under test."""
    return cmd.startswith("pip install ")


def test_readme_parsing():
    text = "x\n```bash\n# c\na \\\n  --b\n\nc  # hardware\n```\n```python\nno\n```\n```bash\nd\n```\n"
    assert readme_commands(text) == ["a    --b", "c  # hardware", "d"]
    assert _is_hardware("imutool capture i2c 1 -o x.csv   # hardware")
    assert not _is_hardware("imutool simulate walk -o w.csv  # hardware-free")


def test_top_of_readme_is_the_whole_setup():
    cmds = readme_commands(README.read_text(encoding="utf-8"))
    assert cmds[0].startswith("pip install . && imutool ")
    assert cmds[1] == "pip install -e '.[test]' && python -m pytest"
    assert not any(c.startswith("pip ") for c in cmds[2:]), "more set-up than the two commands at the top"


def _fresh_copy(dst: Path) -> None:
    r = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z"], capture_output=True, timeout=60)
    if r.returncode != 0:
        pytest.skip("not a git checkout: cannot tell the tracked files (a fresh clone) apart")
    for rel in r.stdout.decode().split("\0"):
        if not rel:
            continue
        src = ROOT / rel
        if not src.is_file():  # deleted in the working tree
            continue
        (dst / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src, dst / rel)


def _imutool_on_path(bin_dir: Path) -> dict:
    """Environment whose PATH finds the installed imutool (the console script, not the copied sources)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)}
    exe = shutil.which("imutool") or str(Path(sys.executable).parent / "imutool")
    if not Path(exe).exists():
        pytest.skip("imutool is not installed (pip install -e '.[test]')")
    bin_dir.mkdir()
    (bin_dir / "imutool").symlink_to(exe)
    env["PATH"] = f"{bin_dir}{os.pathsep}{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["COLUMNS"] = "120"
    return env


@pytest.mark.slow
def test_every_readme_command_runs(tmp_path):
    cmds = runnable(readme_commands(README.read_text(encoding="utf-8")))
    clone = tmp_path / "clone"
    clone.mkdir()
    _fresh_copy(clone)
    env = _imutool_on_path(tmp_path / "bin")
    for i, cmd in enumerate(cmds, 1):
        r = subprocess.run(
            ["bash", "-e", "-c", cmd],
            cwd=clone,
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
            stdin=subprocess.DEVNULL,
        )
        assert r.returncode == 0, (
            f"README command {i}/{len(cmds)} failed (exit {r.returncode}):\n  {cmd}\n"
            f"stderr: {r.stderr[-3000:]}\nstdout: {r.stdout[-1500:]}"
        )
        assert "Traceback" not in r.stderr and "internal error" not in r.stderr, (cmd, r.stderr[-3000:])
