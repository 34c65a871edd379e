"""ZVI detectors: accuracy against simulated stance phases, interval tables, threshold picking, CLI, real data."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

import formats
from formats.errors import ImutoolError
from imutool.cli import cli
from imutool.sim.walk import walk
from imutool.zvi import (
    DETECTORS,
    detect,
    detect_zvi,
    drop_short,
    flag_scores,
    interval_indices,
    pick_threshold,
)


@pytest.fixture(scope="module")
def sim():
    return walk(seed=11, n_steps=10, turn_deg=15.0)


@pytest.mark.parametrize("detector", DETECTORS)
def test_f1_against_truth_stance(sim, detector):
    res = detect(sim, detector)
    s = flag_scores(res.flags, sim["ref_zvi"])
    assert s["f1"] >= 0.95, (detector, s)
    assert len(res.intervals) == 11  # initial rest + 10 stances (the last one is the final rest)


def test_paper_geometry_100hz():
    r = walk(geometry="paper", seed=3)
    for det in ("paper", "shoe"):
        assert flag_scores(detect(r, det).flags, r["ref_zvi"])["f1"] >= 0.95


def test_threshold_matters(sim):
    # a threshold far too high flags the swings as stationary: recall stays, precision collapses
    s = flag_scores(detect(sim, "shoe", gamma=1e12).flags, sim["ref_zvi"])
    assert s["recall"] == 1.0 and s["precision"] < 0.7
    s = flag_scores(detect(sim, "paper", b_g=1e-4).flags, sim["ref_zvi"])
    assert s["recall"] == 0.0


def test_interval_indices_and_drop_short():
    f = np.array([0, 1, 1, 0, 0, 1, 0, 1, 1, 1], bool)
    np.testing.assert_array_equal(interval_indices(f), [[1, 3], [5, 6], [7, 10]])
    t = np.arange(10) * 0.1
    np.testing.assert_array_equal(drop_short(t, f, 0.15), [0, 0, 0, 0, 0, 0, 0, 1, 1, 1])
    assert interval_indices(np.zeros(4, bool)).shape == (0, 2)


def test_shoe_statistic_matches_definition():
    rng = np.random.default_rng(0)
    n, w = 50, 5
    t = np.arange(n) / 100.0
    a = rng.normal(0, 0.05, (n, 3)) + [0, 0, -9.80665]
    g = rng.normal(0, 0.01, (n, 3))
    res = detect_zvi(t, g, a, "shoe", window_s=w / 100.0, min_duration_s=0.0)
    m = 20
    ya = a[m - 2 : m + 3]
    yg = g[m - 2 : m + 3]
    mean = ya.mean(axis=0)
    ref = np.mean(
        np.sum((ya - 9.80665 * mean / np.linalg.norm(mean)) ** 2, axis=1) / 0.01**2
        + np.sum(yg**2, axis=1) / np.radians(0.1) ** 2
    )
    assert res.statistic[m] == pytest.approx(ref, rel=1e-9)


def test_pick_threshold_improves_f1(sim):
    base = flag_scores(detect(sim, "shoe", gamma=1e3).flags, sim["ref_zvi"])["f1"]
    best = pick_threshold(sim.time, sim["gyro"], sim["accel"], sim["ref_zvi"], "shoe", gamma=1e3)
    assert best["param"] == "gamma"
    assert best["f1"] >= base and best["f1"] >= 0.97
    assert best["f1"] == pytest.approx(np.max(best["f1_grid"]))


def test_bad_input():
    t = np.arange(10) * 0.01
    g = np.zeros((10, 3))
    with pytest.raises(ImutoolError, match="unknown ZVI detector"):
        detect_zvi(t, g, g, "magic")
    with pytest.raises(ImutoolError, match="no parameter"):
        detect_zvi(t, g, g, "shoe", b_g=1.0)
    bad = g.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ImutoolError, match="NaN"):
        detect_zvi(t, bad, g, "shoe")


def test_cli_writes_interval_table_and_plot(tmp_path):
    src = tmp_path / "walk.csv"
    formats.write(walk(seed=11, n_steps=4), src)
    out = tmp_path / "iv.csv"
    png = tmp_path / "zvi.png"
    r = CliRunner().invoke(cli, ["zvi", str(src), "-o", str(out), "--detector", "paper", "--plot", str(png), "--json"])
    assert r.exit_code == 0, r.output
    summary = json.loads(r.stdout)
    assert summary["score_vs_ref_zvi"]["f1"] >= 0.95
    lines = out.read_text().splitlines()
    assert lines[0] == "start_s,end_s,duration_s"
    rows = np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]])
    np.testing.assert_allclose(rows[:, 2], rows[:, 1] - rows[:, 0], atol=1e-5)
    assert len(rows) == summary["intervals"]
    assert png.stat().st_size > 10_000


def test_cli_rejects_option_of_other_detector(tmp_path, sim):
    src = tmp_path / "walk.csv"
    formats.write(sim.select(slice(0, 1000)), src)
    from imutool.cli import main

    with pytest.raises(SystemExit) as e:
        main(["zvi", str(src), "-o", str(tmp_path / "x.csv"), "--detector", "shoe", "--b-g", "3"])
    assert e.value.code == 2
    assert not (tmp_path / "x.csv").exists()


def test_real_foot_walk_stances(shared):
    rec, _ = formats.read(shared("xio_gait_tracking", "short_walk.csv")).validated()
    res = detect(rec, "shoe")
    # ~25 m in ~1.4 m strides: about 17-20 stances plus the rests at both ends
    assert 17 <= len(res.intervals) <= 26
    assert res.flags[:4000].all()  # standing still for the first 10 s
