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


def test_a_magnetic_disturbance_distrusts_the_heading_not_the_attitude():
    """issue 35, item 5: a magnetometer trusted to 0.2° and disturbed for a minute (the field turned by ±40° every
    half second, as by a motor nearby) fails the heading's check, in its own column and warning; roll and pitch
    stay trusted (mag_mode heading never moves them), where before one 'inconsistent' flag condemned the whole
    attitude."""
    import numpy as np

    from imutool.attitude import EkfParams
    from imutool.filtering import run_filter
    from imutool.sim import simulate

    rec = simulate("ship-roll", duration=240.0, seed=2)
    t = rec.time - rec.time[0]
    mag = rec["mag"].copy()
    bad = (t > 100) & (t < 160)
    ang = np.radians(np.random.default_rng(0).uniform(-40, 40, 1000))[(t * 2).astype(int) % 1000][bad]
    mx, my = mag[bad, 0].copy(), mag[bad, 1].copy()
    mag[bad, 0], mag[bad, 1] = np.cos(ang) * mx - np.sin(ang) * my, np.sin(ang) * mx + np.cos(ang) * my
    rec.channels["mag"] = mag
    res = run_filter(rec, params=EkfParams(mag_noise_deg=0.2, mag_disturbance_hold=0.0))
    est, summ = res.recording, res.summary
    assert est["heading_inconsistent"][bad].mean() > 0.3
    assert est["inconsistent"].sum() == 0
    assert any(w.startswith("the heading's self-check failed") for w in summ["warnings"]), summ["warnings"]
    assert not any(w.startswith("the attitude filter's self-check failed") for w in summ["warnings"])
    err = np.abs(est["roll"] - rec["ref_roll"])[t > 60]
    assert err.max() < 1.0
