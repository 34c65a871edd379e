"""The `walk` scenario: deterministic, self-consistent truth (position/velocity/attitude/rates), paper geometry."""

from __future__ import annotations

import numpy as np
import pytest

from formats.errors import ImutoolError
from formats.frames import quat_conjugate, quat_multiply
from imutool.sim import simulate
from imutool.sim.walk import walk


@pytest.fixture(scope="module")
def rec():
    return walk(seed=4, n_steps=6, turn_deg=20.0)


def test_deterministic_for_a_seed(rec):
    again = walk(seed=4, n_steps=6, turn_deg=20.0)
    for name in rec.channels:
        np.testing.assert_array_equal(rec[name], again[name])
    other = walk(seed=5, n_steps=6, turn_deg=20.0)
    assert not np.array_equal(rec["gyro"], other["gyro"])


def test_registered_and_columns():
    r = simulate("walk", seed=0, n_steps=2)
    assert r.columns["ref_pos"] == ["ref_pos_n", "ref_pos_e", "ref_pos_d"]
    assert r.columns["ref_vel"] == ["ref_vel_n", "ref_vel_e", "ref_vel_d"]
    for name in ("gyro", "accel", "ref_q", "ref_zvi"):
        assert name in r.channels


def test_velocity_integrates_to_position(rec):
    t, p, v = rec.time, rec["ref_pos"], rec["ref_vel"]
    p_int = np.vstack([np.zeros(3), np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t)[:, None], axis=0)])
    assert np.max(np.abs(p_int - p)) < 1e-3


def test_zero_velocity_and_floor_in_stance(rec):
    z = rec["ref_zvi"] > 0.5
    assert 0.3 < z.mean() < 0.8
    assert np.max(np.abs(rec["ref_vel"][z])) < 1e-6
    assert np.max(np.abs(rec["ref_pos"][z, 2])) < 1e-9
    assert np.max(np.linalg.norm(rec["ref_vel"][~z], axis=1)) > 1.0


def test_rates_consistent_with_attitude(rec):
    # integrate the true body rate and compare with ref_q
    q = rec["ref_q"]
    w = rec["ref_gyro"]
    dt = np.diff(rec.time)
    wm = 0.5 * (w[1:] + w[:-1])
    ang = np.linalg.norm(wm, axis=1) * dt
    axis = wm / np.maximum(np.linalg.norm(wm, axis=1), 1e-300)[:, None]
    dq = np.column_stack([np.cos(ang / 2), axis * np.sin(ang / 2)[:, None]])
    pred = quat_multiply(q[:-1], dq)
    err = quat_multiply(quat_conjugate(pred), q[1:])
    assert np.max(2 * np.abs(err[:, 1:])) < 1e-4  # rad per step


def test_specific_force_at_rest_is_gravity(rec):
    z = rec["ref_zvi"] > 0.5
    f = rec["ref_accel"][z]
    np.testing.assert_allclose(np.linalg.norm(f, axis=1), 9.80665, atol=1e-6)


def test_paper_geometry():
    r = walk(geometry="paper", seed=1)
    assert r.rate_hz == pytest.approx(100.0)
    assert r.meta["n_steps"] == 3
    np.testing.assert_allclose(r["ref_pos"][-1], [2.0, 0.0, 0.0], atol=1e-9)


def test_turning_loop_closes():
    r = walk(seed=0, n_steps=12, turn_deg=30.0, step_length=1.0)
    assert np.linalg.norm(r["ref_pos"][-1]) < 1e-9
    assert r.meta["distance_m"] == pytest.approx(12.0)


def test_duration_sets_steps():
    r = walk(duration=10.0, seed=0)
    assert r.duration == pytest.approx(10.0, abs=0.01)
    assert r.meta["n_steps"] == int((10.0 - 3.0 + 0.5) // 1.1)


def test_bad_options():
    with pytest.raises(ImutoolError, match="geometry"):
        walk(geometry="moon")
    with pytest.raises(ImutoolError, match="tilt"):
        walk(tilt_deg="1,2,3")
