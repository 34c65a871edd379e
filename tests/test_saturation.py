"""A clipped accelerometer or gyro is found, flagged per sample, not used, and said (issue 35, item 4)."""

from __future__ import annotations

import numpy as np

from formats.saturation import MIN_RUN, clipped
from formats.units import STANDARD_GRAVITY
from imutool.filtering import run_filter
from imutool.sim import simulate

TWO_G = 2.0 * STANDARD_GRAVITY


def shaken(seconds: float = 60.0):
    """A foot-mounted IMU walking: heel strikes beyond 2 g."""
    return simulate("walk", duration=seconds, seed=2)


def test_flat_tops_at_a_range_limit_are_found_and_peaks_are_not():
    rec = shaken()
    acc = rec.in_unit("accel", "m/s^2")
    assert np.abs(acc).max() > TWO_G  # the walk's own peaks: not clipped
    assert clipped(acc, "accel").count == 0
    cut = np.clip(acc, -TWO_G, TWO_G)
    clip = clipped(cut, "accel")
    assert clip.count == int(np.count_nonzero(np.any(np.abs(cut) >= TWO_G, axis=1)))
    assert any(TWO_G in axis or -TWO_G in axis for axis in clip.limits)
    # a still sensor repeats its values too, within ±1 g: not a range limit
    still = np.tile([0.0, 0.0, -STANDARD_GRAVITY], (500, 1))
    assert clipped(still, "accel").count == 0
    # fewer than MIN_RUN samples in a row at the extreme: a peak
    one = np.zeros((100, 3))
    one[50 : 50 + MIN_RUN - 1, 0] = 30.0
    assert clipped(one, "accel").count == 0


def test_the_filter_does_not_use_a_clipped_accelerometer_and_says_so(tmp_path):
    rec = shaken()
    acc = rec.in_unit("accel", "m/s^2")
    cut = rec.copy()
    cut.channels["accel"] = np.clip(acc, -TWO_G, TWO_G)
    cut.units["accel"] = "m/s^2"
    rows = np.any(np.abs(cut["accel"]) >= TWO_G, axis=1)
    assert rows.sum() >= 10
    res = run_filter(cut)
    s = res.summary
    assert s["accel_clipped_samples"] == int(rows.sum())
    assert any("accel clipped at" in w and "range limit" in w for w in s["warnings"]), s["warnings"]
    assert np.all(res.recording["accel_rejected"][rows] == 1)
    clean = run_filter(rec).summary
    assert "accel_clipped_samples" not in clean
    assert not any("clipped" in w for w in clean.get("warnings", []))
    # streamed: the same count and the same warning
    from formats import write

    src = tmp_path / "clipped.csv"
    write(cut, src)
    streamed = run_filter(src, tmp_path / "est.csv", stream_mb=0.0, chunk_rows=2000).summary
    assert streamed["accel_clipped_samples"] == int(rows.sum())


def test_a_clipped_gyro_is_said():
    rec = shaken()
    gyro = rec.in_unit("gyro", "rad/s")
    limit = 0.6 * np.abs(gyro).max()
    assert limit > 1.0  # beyond the floor: a range limit a real gyro could have
    cut = rec.copy()
    cut.channels["gyro"] = np.clip(gyro, -limit, limit)
    cut.units["gyro"] = "rad/s"
    s = run_filter(cut).summary
    assert s["gyro_clipped_samples"] > 0
    assert any(w.startswith("gyro clipped at") for w in s["warnings"]), s["warnings"]
