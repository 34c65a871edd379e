"""Ship scenarios: truth consistency, the documented noise interpretation, GNSS channels, static cost."""

import numpy as np

from imutool.sim import simulate


def test_ship_roll_truth_and_noise():
    r = simulate("ship-roll", duration=30, seed=3, lever_z_m=0.0)
    assert abs(np.nanmax(r["ref_roll"]) - 15.0) < 0.1
    f = r["accel"]
    roll_acc = np.degrees(np.arctan2(-f[:, 1], -f[:, 2]))
    # "white noise σ = 1.5°": accelerometer-only roll scatters with σ ≈ 1.5° (no lever arm here)
    assert abs(np.std(roll_acc - r["ref_roll"]) - 1.5) < 0.1
    # gyro = truth + bias + noise
    resid = r["gyro"] - r["ref_gyro"] - r["ref_gyro_bias"]
    assert np.all(np.abs(resid.mean(axis=0)) < 1e-3)
    q = r["ref_q"]
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0)


def test_ship_roll_lever_arm_fools_accelerometer():
    r = simulate("ship-roll", duration=20, seed=1, lever_z_m=-5.0)
    f = r["ref_accel"]  # error-free specific force: only the lever-arm acceleration remains
    err = np.degrees(np.arctan2(-f[:, 1], -f[:, 2])) - r["ref_roll"]
    assert np.abs(err).max() > 2.0


def test_turn_has_centripetal_and_gnss():
    r = simulate("turn", duration=60, seed=2, straight_s=10, ramp_s=5)
    assert {"sog", "cog", "ref_cog"} <= set(r.channels)
    assert np.allclose(np.nanmedian(r["sog"]), 10.0, atol=0.1)
    late = r.time > 30
    f = r["ref_accel"][late]
    err = np.degrees(np.arctan2(-f[:, 1], -f[:, 2])) - r["ref_roll"][late]
    assert abs(err.mean()) > 2.5  # 10 m/s × 3 °/s ≈ 0.52 m/s² ≈ 3° of false tilt
    hd = np.unwrap(np.radians(r["ref_heading"]))
    assert abs(np.degrees(hd[-1] - hd[late][0]) / (r.time[-1] - r.time[late][0]) - 3.0) < 0.05


def test_static_long_is_cheap_and_still():
    r = simulate("static", duration=1800, rate_hz=100, seed=0, gyro_bias_instability_deg_s=0.01)
    assert len(r) == 180001
    assert np.allclose(r["ref_gyro"], 0.0)
    g = r["gyro"] - r["ref_gyro_bias"]
    assert abs(np.std(g[:, 0]) - np.radians(0.005) * 10) < 1e-4  # white noise σ = N·√fs
