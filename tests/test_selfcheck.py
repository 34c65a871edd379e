"""`imutool selfcheck`: every step passes on a correct install and names the cache folder; a failing step is one
line on stderr with exit status 1."""

from __future__ import annotations

import json
from pathlib import Path

from conftest import run_main

import imutool.selfcheck as sc


def test_selfcheck_passes_and_names_the_cache_folder(capsys):
    code, out, err = run_main(["selfcheck", "--json"], capsys)
    assert code == 0, err
    summary = json.loads(out)
    assert summary["ok"] is True
    assert [s["name"] for s in summary["steps"]] == [name for name, _ in sc.STEPS]
    ekf = next(s for s in summary["steps"] if s["name"].startswith("attitude EKF"))
    roll = float(ekf["detail"].split("roll RMSE ")[1].split("°")[0])
    assert 0.0 < roll <= sc.ROLL_RMSE_MAX_DEG
    folder = Path(summary["cache_folder"])
    assert folder.name.startswith("kernels-") and folder.is_dir()
    assert list(folder.rglob("*.nbi")), "no compiled kernel in the cache folder"


def test_selfcheck_failure_is_one_line_exit_1(capsys, monkeypatch):
    def broken(self):
        raise ValueError("the Allan deviation came out negative")

    monkeypatch.setattr(sc, "STEPS", (("bridge frames (capture)", "bridge"), ("Allan deviation (allan)", "allan")))
    monkeypatch.setattr(sc._Run, "allan", broken)
    code, out, err = run_main(["selfcheck"], capsys)
    assert code == 1
    assert out.startswith("ok  bridge frames (capture)")
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith("imutool: compiling")]
    assert len(lines) == 1, err
    assert lines[0].startswith("imutool selfcheck: FAILED: ") and "Allan deviation (allan)" in lines[0], lines
    assert "came out negative" in lines[0]
