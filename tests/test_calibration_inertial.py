"""Gyro bias/temperature slope/scale, accelerometer many-position calibration, rest detection, normal gravity."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.inertial import calibrate_accel, calibrate_gyro, detect_rest, normal_gravity
from formats.errors import ImutoolError
from formats.frames import euler_to_quat
from imutool.sim.sensor import MPU6050_ACCEL, MPU6050_GYRO, SensorErrors, imu_recording

POSES = [
    (0, 0),
    (180, 0),
    (90, 0),
    (-90, 0),
    (0, 89.9),
    (0, -89.9),
    (45, 30),
    (-60, -20),
    (120, 40),
    (30, -60),
    (-135, 10),
    (70, 70),
]


def poses_recording(poses=POSES, hold=6.0, move=3.0, rate=100.0, seed=0, temp_slope=None, quats=None):
    """Static poses (roll, pitch deg, or quaternions) held ``hold`` s, joined by smooth ``move`` s rotations about
    a fixed axis (nlerp); known sensor errors."""
    rng = np.random.default_rng(seed)
    if quats is not None:
        poses = list(range(len(quats)))
    t = np.arange(0, len(poses) * (hold + move), 1 / rate)
    k = np.minimum((t // (hold + move)).astype(int), len(poses) - 1)
    nxt = np.minimum(k + 1, len(poses) - 1)
    s = np.clip((t - k * (hold + move) - hold) / move, 0, 1)
    s = s * s * (3 - 2 * s)
    if quats is None:
        r = np.radians([p[0] for p in poses])
        p = np.radians([p[1] for p in poses])
        quats = euler_to_quat(r, p, np.zeros_like(r))
    quats = np.asarray(quats)
    q0, q1 = quats[k], quats[nxt]
    q1 = np.where(np.sum(q0 * q1, axis=1)[:, None] < 0, -q1, q1)
    q = (1 - s)[:, None] * q0 + s[:, None] * q1
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    ae = SensorErrors(**{**MPU6050_ACCEL.__dict__})
    ae.bias = np.array([0.15, -0.1, 0.2])
    ae.scale = np.array([0.02, -0.015, 0.01])
    ae.misalignment = np.array([[0, 0.004, -0.003], [0.002, 0, 0.005], [-0.004, 0.001, 0]])
    ae.full_range = np.inf
    ge = SensorErrors(**{**MPU6050_GYRO.__dict__})
    ge.bias = np.radians([1.0, -2.0, 0.5])
    ge.bias_rw = 0.0
    ge.full_range = np.inf
    rec = imu_recording(t, q, np.zeros((len(t), 3)), rng, gyro_errors=ge, accel_errors=ae, mag_errors=None)
    temp = 20.0 + 10.0 * t / t[-1]
    rec.add("temp", temp)
    if temp_slope is not None:
        rec.add("gyro", rec["gyro"] + (temp - 25.0)[:, None] * np.asarray(temp_slope))
    return rec, ae, ge


def test_normal_gravity_wgs84():
    assert normal_gravity(0.0) == pytest.approx(9.7803253359, abs=1e-9)
    assert normal_gravity(90.0) == pytest.approx(9.8321849378, abs=1e-8)
    assert normal_gravity(45.0) == pytest.approx(9.80619920, abs=5e-6)  # GRS80 value; WGS-84 differs by 1.4e-6
    assert normal_gravity(45.0, 1000.0) == pytest.approx(normal_gravity(45.0) - 3.086e-3, abs=1e-9)


def test_rest_detection_finds_every_pose():
    rec, _, _ = poses_recording()
    rests = detect_rest(rec.time, rec["gyro"], rec["accel"])
    assert len(rests) == len(POSES)
    for a, b in rests[:-1]:  # every rest lies inside a hold period (the last pose is held to the end)
        ph = rec.time[a:b] % 9.0
        assert np.all(ph <= 6.0 + 1e-9)


def test_accel_many_position_bias_scale_misalignment():
    rec, ae, _ = poses_recording()
    cal = calibrate_accel(rec.time, rec["accel"], rec["gyro"])
    assert cal.kind == "full" and cal.quality["poses"] == len(POSES)
    assert np.all(np.abs(cal.bias - ae.bias) < 0.005)
    m_inv = np.linalg.inv(np.eye(3) + np.diag(ae.scale) + ae.misalignment)
    # |g| only fixes TᵀT (the rotation part of T is unobservable): compare the metric
    assert np.abs(cal.T.T @ cal.T - m_inv.T @ m_inv).max() < 1e-3
    assert cal.residual_rms < 0.005
    corrected = np.linalg.norm(cal.apply(cal.poses), axis=1)
    assert np.allclose(corrected, 9.80665, atol=0.01)


def test_accel_six_position_gives_bias_and_scale():
    rec, ae, _ = poses_recording(POSES[:6])
    cal = calibrate_accel(rec.time, rec["accel"], rec["gyro"])
    assert cal.kind == "diag"
    assert np.all(np.abs(cal.bias - ae.bias) < 0.01)
    assert np.allclose(np.diag(cal.T), 1 / (1 + ae.scale), atol=2e-3)


def test_accel_too_few_poses_refused():
    rec, _, _ = poses_recording(POSES[:3])
    with pytest.raises(ImutoolError, match="3 distinct static poses"):
        calibrate_accel(rec.time, rec["accel"], rec["gyro"])


def test_gyro_bias_and_temperature_slope():
    slope = np.radians([0.02, -0.01, 0.005])  # rad/s/°C
    rec, _, ge = poses_recording(temp_slope=slope)
    cal = calibrate_gyro(rec.time, rec["gyro"], rec["accel"], rec["temp"])
    assert cal.temp_slope is not None
    assert np.allclose(cal.temp_slope, slope, atol=np.radians(0.002))
    at_ref = ge.bias + (cal.temp_ref - 25.0) * slope
    assert np.allclose(cal.bias, at_ref, atol=np.radians(0.01))


def test_gyro_bias_without_temperature_and_no_rest_refused():
    rec, _, ge = poses_recording()
    cal = calibrate_gyro(rec.time, rec["gyro"], rec["accel"], None)
    assert np.allclose(cal.bias, ge.bias, atol=np.radians(0.01))
    with pytest.raises(ImutoolError, match="no rest interval"):
        calibrate_gyro(rec.time, rec["gyro"], rec["accel"], gyro_std=1e-6)


def test_gyro_scale_from_known_turns():
    from formats.frames import quat_multiply

    h = np.sqrt(0.5)
    turns = [np.array([h, h, 0, 0]), np.array([h, 0, h, 0]), np.array([h, 0, 0, h]), np.array([h, -h, 0, 0])]
    quats = [np.array([1.0, 0, 0, 0])]
    for d in turns:  # 90° about body x, y, z, then −x
        quats.append(quat_multiply(quats[-1], d))
    rec, _, ge = poses_recording(hold=5.0, move=3.0, quats=np.array(quats))
    s_true = np.array([[1.03, 0.004, 0.0], [0.0, 0.98, -0.003], [0.002, 0.0, 1.01]])  # S: ω = S (ω_meas − b)
    rec.add("gyro", (rec["gyro"] - ge.bias) @ np.linalg.inv(s_true).T + ge.bias)
    cal = calibrate_gyro(rec.time, rec["gyro"], rec["accel"], turns_deg=90.0)
    assert cal.quality["turns"] == 4
    assert np.abs(cal.scale - s_true).max() < 3e-3
    part = rec.slice_time(None, 17.5)  # only the turn about x
    with pytest.raises(ImutoolError, match="all three axes"):
        calibrate_gyro(part.time, part["gyro"], part["accel"], turns_deg=90.0)
