"""The gyro-scale self-check: a gyro whose rates are k× wrong (wrong full-scale range or unit) is said, with the
factor, in memory and streamed; intact recordings (simulated ships, all 16 BROAD trials) are not."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

import formats
from imutool.attitude import ekf_recording
from imutool.gyro_check import GyroScaleCheck
from imutool.sim import simulate


def _scaled(rec, k):
    out = rec.copy()
    out.channels["gyro"] = rec["gyro"] * k
    return out


@pytest.fixture(scope="module")
def ship():
    return simulate("ship-roll", duration=120, seed=7)


@pytest.mark.parametrize("k", [1.0, 2.0, 0.5, 1.5])
def test_a_gyro_in_the_wrong_range_is_said_with_its_factor(ship, k):
    """Before this check a gyro ×2 cost 13° of inclination RMS with no word from either self-check (the filter's
    own low-pass turns with the same gyro). ŝ is the factor the rates would need: 1/k."""
    est, summary = ekf_recording(_scaled(ship, k))
    c = summary["gyro_scale_check"]
    warned = [w for w in summary.get("warnings", []) if "gyro scale check:" in w]
    if k == 1.0:
        assert 0.9 <= c["scale"] <= 1.15 and not c.get("flagged") and not warned, c
        assert "warnings" not in est.meta or not any("gyro scale" in w for w in est.meta["warnings"])
    else:
        assert c["scale"] == pytest.approx(1 / k, rel=0.12) and c["flagged"], c
        assert len(warned) == 1 and f"scaling them by {c['scale']:.3g} " in warned[0], warned
        assert c["discrepancy_deg"] > 3.0, c
        assert any("gyro scale check:" in w for w in est.meta["warnings"])


def test_the_check_is_the_same_streamed_and_in_memory(ship, tmp_path):
    """`imutool filter` on a file that streams (chunks of 5000 rows: pairs do not cross a chunk) says the same as
    an in-memory run: stderr, the JSON summary and the output's metadata."""
    from imutool.cli import cli

    src = tmp_path / "x2.csv"
    formats.write(_scaled(ship, 2.0), src)
    found = {}
    for name, extra in (("memory", []), ("stream", ["--stream-mb", "0", "--chunk-rows", "5000"])):
        out = tmp_path / f"{name}.csv"
        run = CliRunner().invoke(cli, ["filter", str(src), "-o", str(out), "--json", *extra])
        assert run.exit_code == 0, run.output
        s = json.loads(run.stdout)
        found[name] = s["gyro_scale_check"]
        assert found[name]["flagged"] and "gyro scale check:" in run.stderr, name
        assert any("gyro scale check:" in w for w in formats.read(out).meta["warnings"]), name
    assert found["stream"]["scale"] == pytest.approx(found["memory"]["scale"], abs=0.03)
    assert found["stream"]["pairs"] >= 0.85 * found["memory"]["pairs"]


def test_a_recording_that_hardly_turns_gives_no_verdict():
    """A still sensor: every candidate scale explains the data equally well — no rotation, no evidence."""
    n = 4000
    t = np.arange(n) / 100.0
    rng = np.random.default_rng(1)
    gyro = rng.normal(0, 1e-3, (n, 3))
    force = np.array([0.0, 0.0, -9.80665]) + rng.normal(0, 0.05, (n, 3))
    chk = GyroScaleCheck()
    chk.add(t, gyro * 2.0, np.zeros((n, 3)), force)
    entry, warnings = chk.report()
    assert entry["gyro_scale_check"]["pairs"] > 10 and not warnings
    assert entry["gyro_scale_check"]["discrepancy_deg"] < 0.5


def test_broad_intact_trials_are_not_flagged_and_a_doubled_gyro_is(shared):
    """All 16 shared BROAD trials, intact: no warning, and ŝ within 4 % of 1 on every trial that turns (E ≥ 0.2°;
    the slow-translation trial 10 hardly turns: its J is flat, ŝ 0.71 with 0.7° to explain, no verdict). Four
    trials of each kind with the gyro ×2: warned, ŝ = 0.50 ± 0.03."""
    folder = shared("broad")
    for f in sorted(folder.glob("*.csv")):
        rec = formats.read(f)
        _, s = ekf_recording(rec)
        c = s["gyro_scale_check"]
        assert not c.get("flagged") and not any("gyro scale" in w for w in s.get("warnings", [])), (f.name, c)
        if f.name[:2] != "10":
            assert abs(c["scale"] - 1.0) <= 0.04, (f.name, c)
        if f.name[:2] in ("02", "07", "16", "28"):
            _, s2 = ekf_recording(_scaled(rec, 2.0))
            c2 = s2["gyro_scale_check"]
            assert c2["flagged"] and c2["scale"] == pytest.approx(0.5, abs=0.03), (f.name, c2)


def test_the_checked_share_is_per_run_whatever_the_chunk_size():
    """The cost is bounded per run (the first 100 000 samples whole, then 10 %): a stream in 10 000-row chunks
    integrates no more than one call over the whole run (per-chunk budgets made a 24 h file cost 3× the filter)."""
    n = 400_000
    t = np.arange(n) / 100.0
    gyro = np.zeros((n, 3))
    gyro[:, 0] = 0.3 * np.sin(t)
    force = np.tile([0.0, 0.0, -9.80665], (n, 1))
    used = []
    for chunk in (n, 10_000):
        chk = GyroScaleCheck()
        for i in range(0, n, chunk):
            chk.add(t[i:i + chunk], gyro[i:i + chunk], np.zeros((min(chunk, n - i), 3)), force[i:i + chunk])
        used.append(chk.checked)
        assert chk.report()[0]["gyro_scale_check"]["pairs"] > 20
    assert max(used) <= max(100_000, 0.1 * n) + 400, used  # + one pair of 2-s windows at 100 Hz
