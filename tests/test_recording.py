"""Recording: validation (duplicates, gaps, NaN, backwards), slicing, multi-clock merge, mounting transform."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formats import Recording, merge, parse_mounting
from formats.errors import ImutoolError
from formats.frames import euler_to_quat, quat_normalize, quat_rotate


def _rec(t, **ch) -> Recording:
    r = Recording(np.asarray(t, dtype=float))
    for k, v in ch.items():
        r.add(k, np.asarray(v, dtype=float))
    return r


# -- validation -------------------------------------------------------------------------------------------------
def test_duplicates_drop_mean_error():
    t = [0.0, 0.1, 0.1, 0.2, 0.3, 0.3, 0.3, 0.4]
    g = np.arange(8.0)
    r = _rec(t, temp=g)
    clean, rep = r.validated(duplicates="drop")
    assert rep.duplicates == 3 and rep.duplicates_conflicting == 3
    assert clean.time.tolist() == [0.0, 0.1, 0.2, 0.3, 0.4]
    assert clean["temp"].tolist() == [0.0, 1.0, 3.0, 4.0, 7.0]  # first row of each timestamp kept
    mean, rep = r.validated(duplicates="mean")
    assert mean["temp"].tolist() == [0.0, 1.5, 3.0, 5.0, 7.0]
    assert any("averaged 3" in a for a in rep.actions)
    with pytest.raises(ImutoolError, match=r"3 duplicate timestamps \(first at row 3, t = 0.100000 s\)"):
        r.validated(duplicates="error")


def test_identical_duplicates_not_counted_as_conflicting():
    r = _rec([0, 1, 1, 2], gyro=np.ones((4, 3)))
    _, rep = r.validated()
    assert rep.duplicates == 1 and rep.duplicates_conflicting == 0


def test_gaps_reported_not_filled():
    t = np.concatenate([np.arange(0, 1, 0.01), np.arange(1.5, 2, 0.01)])
    r = _rec(t, temp=np.zeros(t.size))
    clean, rep = r.validated()
    assert len(clean) == t.size
    assert len(rep.gaps) == 1
    start, length = rep.gaps[0]
    assert start == pytest.approx(0.99) and length == pytest.approx(0.51)
    assert rep.median_dt == pytest.approx(0.01)
    assert clean.meta["validation"]["gaps"][0]["length_s"] == pytest.approx(0.51)


def test_nan_rows_counted_per_channel_and_kept():
    g = np.zeros((6, 3))
    g[1, 0] = np.nan
    g[4] = np.nan
    m = np.zeros((6, 3))
    m[4, 2] = np.nan
    m[5, 1] = np.nan
    r = _rec(np.arange(6.0), gyro=g, mag=m)
    clean, rep = r.validated()
    assert rep.nan_rows == 3 and rep.nan_by_channel == {"gyro": 2, "mag": 2}
    assert len(clean) == 6


def test_backwards_policies():
    t = [0.0, 0.1, 0.2, 0.15, 0.3]
    r = _rec(t, temp=[0, 1, 2, 3, 4])
    with pytest.raises(ImutoolError, match=r"time goes backwards at row 4 \(0.200000 s → 0.150000 s\)"):
        r.validated()
    s, rep = r.validated(backwards="sort")
    assert s.time.tolist() == [0.0, 0.1, 0.15, 0.2, 0.3] and s["temp"].tolist() == [0, 1, 3, 2, 4]
    assert rep.backwards == 1
    d, _ = r.validated(backwards="drop")
    assert d.time.tolist() == [0.0, 0.1, 0.2, 0.3] and d["temp"].tolist() == [0, 1, 2, 4]
    with pytest.raises(ImutoolError, match="not finite"):
        _rec([0.0, np.nan], temp=[1, 2]).validated()


def test_real_short_walk_duplicates(shared):
    from formats.csv import read_csv

    rec = read_csv(str(shared("xio_gait_tracking", "short_walk.csv")))
    d = np.diff(rec.time)
    expected = int(np.count_nonzero(d == 0))
    clean, rep = rec.validated(duplicates="drop")
    assert expected > 0 and rep.duplicates == expected
    assert rep.duplicates_conflicting == 0  # the logger repeated whole rows
    assert len(clean) == len(rec) - expected
    assert np.all(np.diff(clean.time) > 0)
    assert 380 < clean.rate_hz < 420


# -- slicing -------------------------------------------------------------------------------------------------
def test_slice_time_half_open_and_select():
    r = _rec(np.arange(10) * 0.5, temp=np.arange(10.0))
    s = r.slice_time(1.0, 3.0)
    assert s.time.tolist() == [1.0, 1.5, 2.0, 2.5]
    assert s["temp"].tolist() == [2, 3, 4, 5]
    assert len(r.slice_time(None, 0.0)) == 0 and len(r.slice_time(4.5)) == 1
    s["temp"][0] = 99  # a copy, not a view into the original
    assert r["temp"][2] == 2
    assert r.duration == 4.5 and r.rate_hz == pytest.approx(2.0)


# -- merging two clocks ----------------------------------------------------------------------------------------
def test_merge_77hz_mag_onto_99hz_imu_interpolation_bound():
    f = 0.7  # Hz
    w = 2 * math.pi * f
    t_imu = np.arange(0, 20, 1 / 99.0)
    t_mag = 0.0031 + np.arange(0, 20, 1 / 77.0)
    imu = _rec(t_imu, gyro=np.stack([np.sin(w * t_imu)] * 3, axis=1))
    amp = 40.0
    mag = _rec(
        t_mag, mag=np.stack([amp * np.sin(w * t_mag), amp * np.cos(w * t_mag), np.full(t_mag.size, -30.0)], axis=1)
    )
    m = merge([imu, mag], clock=imu)
    assert set(m.channels) == {"gyro", "mag"}
    assert np.all(m.time >= t_mag[0]) and np.all(m.time <= t_mag[-1])
    assert np.array_equal(m.time, t_imu[(t_imu >= t_mag[0]) & (t_imu <= t_mag[-1])])
    err = m["mag"][:, 0] - amp * np.sin(w * m.time)
    h = 1 / 77.0
    bound = amp * w**2 * h**2 / 8  # linear interpolation error bound: max|f''| h²/8
    assert np.max(np.abs(err)) <= bound * 1.0001
    assert np.max(np.abs(err)) > bound * 0.3  # and the bound is not vacuous
    assert np.allclose(m["mag"][:, 2], -30.0)
    assert m.units["mag"] == "uT"


def test_merge_rate_clock_name_clash_and_quaternions():
    t1 = np.linspace(0, 1, 11)
    t2 = np.linspace(0, 1, 7)
    q = quat_normalize(euler_to_quat(np.linspace(0, 1, 7), np.zeros(7), np.zeros(7)))
    a = _rec(t1, temp=t1)
    b = _rec(t2, temp=2 * t2, q=q)
    m = merge([a, b], clock=20.0, prefixes=["", "b_"])
    assert len(m) == 21 and np.allclose(np.diff(m.time), 0.05)
    assert "b_temp" in m.channels and np.allclose(m["b_temp"], 2 * m.time)
    assert np.allclose(np.linalg.norm(m["q"], axis=1), 1.0)
    with pytest.raises(ImutoolError, match="do not overlap"):
        merge([_rec([0, 1], temp=[0, 0]), _rec([2, 3], temp=[0, 0])])


# -- mounting --------------------------------------------------------------------------------------------------
def test_mounting_remap_flu_to_frd():
    r = _rec([0.0], gyro=[[1.0, 2.0, 3.0]], accel=[[0.1, 0.2, 9.8]], mag=[[10.0, 20.0, 30.0]])
    b = r.mounted("x,-y,-z")
    assert b["gyro"].tolist() == [[1.0, -2.0, -3.0]]
    assert b["accel"].tolist() == [[0.1, -0.2, -9.8]]
    assert b.meta["mounting"]["remap"] == "x,-y,-z"
    assert "FRD" in b.meta["frame"]


def test_mounting_misalignment_vectors_and_quaternion_consistent():
    rng = np.random.default_rng(5)
    n = 50
    q_s = quat_normalize(rng.standard_normal((n, 4)))  # sensor→NED
    v_s = rng.standard_normal((n, 3))  # vectors in sensor axes
    r = _rec(np.arange(n, dtype=float), gyro=v_s, accel=v_s * 2, q=q_s)
    b = r.mounted("y,x,-z", (1.5, -0.7, 3.0))
    # the same physical vector expressed in NED is unchanged: q_b ⊗ v_b = q_s ⊗ v_s
    assert np.allclose(quat_rotate(b["q"], b["gyro"]), quat_rotate(q_s, v_s), atol=1e-12)
    assert np.allclose(np.linalg.norm(b["q"], axis=1), 1.0)
    assert np.allclose(np.linalg.norm(b["gyro"], axis=1), np.linalg.norm(v_s, axis=1))
    mat = np.array(b.meta["mounting"]["matrix_sensor_to_body"])
    assert np.allclose(mat @ mat.T, np.eye(3)) and np.linalg.det(mat) == pytest.approx(1.0)
    # pure misalignment: a small yaw rotates x towards y by that angle
    c = _rec([0.0], gyro=[[1.0, 0.0, 0.0]]).mounted("x,y,z", (0.0, 0.0, 2.0))
    assert math.degrees(math.atan2(c["gyro"][0, 1], c["gyro"][0, 0])) == pytest.approx(2.0)


def test_mirror_remaps_refused_and_mounting_spec_parsed():
    with pytest.raises(ImutoolError, match="mirror"):
        _rec([0.0], gyro=[[1.0, 0, 0]]).mounted("x,y,-z")
    assert parse_mounting("x,-y,-z;0.5,-0.2,1.0") == ("x,-y,-z", (0.5, -0.2, 1.0))
    with pytest.raises(ImutoolError, match="three numbers"):
        parse_mounting("x,-y,-z;1,2")


def test_bad_channel_shapes_refused():
    r = _rec([0.0, 1.0])
    with pytest.raises(ImutoolError, match="shape"):
        r.add("gyro", np.zeros((3, 3)))
    with pytest.raises(ImutoolError, match="not in recording"):
        r["gyro"]
    with pytest.raises(ImutoolError, match="no unit"):
        r.add("thing", [1.0, 2.0])
        r.get("thing", "deg")
