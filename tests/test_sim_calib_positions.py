"""The six-position simulator scenario: poses held still, known accelerometer errors recovered by the calibration."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.inertial import calibrate_accel
from formats.errors import ImutoolError
from imutool import sim


def test_six_position_poses_point_each_axis_up_and_down():
    rec = sim.simulate("six-position", seed=3)
    assert rec.meta["poses"] == 6
    f = rec.get("ref_accel", "m/s^2")
    hold = rec.meta["hold_s"]
    period = hold + rec.meta["move_s"]
    means = np.array(
        [f[(rec.time > k * period + 1) & (rec.time < k * period + hold - 1)].mean(axis=0) for k in range(6)]
    )
    # every pose puts ±g on exactly one body axis, and the six cover all of ±x, ±y, ±z
    dominant = {(int(np.argmax(np.abs(m))), int(np.sign(m[np.argmax(np.abs(m))]))) for m in means}
    assert dominant == {(a, s) for a in range(3) for s in (-1, 1)}
    assert np.allclose(np.linalg.norm(means, axis=1), 9.80665, atol=1e-9)


def test_six_position_calibration_recovers_the_truth():
    rec = sim.simulate("six-position", seed=1)
    cal = calibrate_accel(rec.time, rec.get("accel", "m/s^2"), rec.get("gyro", "rad/s"))
    assert cal.kind == "diag" and cal.quality["poses"] == 6
    bias = np.array(rec.meta["accel_bias_m_s2"])
    scale = np.array(rec.meta["accel_scale"])
    # six poses cannot separate misalignment (±0.25°): bias within 10 mm/s², scale within 0.1 %
    assert np.max(np.abs(cal.bias - bias)) < 0.01
    assert np.max(np.abs(np.diag(cal.T) * (1 + scale) - 1)) < 1e-3


def test_twelve_positions_resolve_misalignment():
    rec = sim.simulate("six-position", seed=2, poses=12)
    cal = calibrate_accel(rec.time, rec.get("accel", "m/s^2"), rec.get("gyro", "rad/s"))
    assert cal.kind == "full" and cal.quality["poses"] == 12
    assert np.max(np.abs(cal.bias - np.array(rec.meta["accel_bias_m_s2"]))) < 2e-3
    m_true = np.eye(3) + np.diag(rec.meta["accel_scale"]) + np.array(rec.meta["accel_misalignment"])
    # T M maps true specific force to itself up to a rotation (unobservable from |g|): T M is orthogonal
    tm = cal.T @ m_true
    assert np.allclose(tm.T @ tm, np.eye(3), atol=5e-4)


def test_unknown_scenario_option_lists_the_valid_ones():
    with pytest.raises(ImutoolError, match=r"no option 'hss'.*valid: hs, tp"):
        sim.simulate("sea-state", duration=10, hss=2)
    with pytest.raises(ImutoolError, match="poses must be 6 or 12"):
        sim.simulate("six-position", poses=7)
