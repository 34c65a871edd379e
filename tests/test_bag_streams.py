"""Bags and "no data" (issue 48, item 4): a missing field is covariance[0] = -1 with zeros, never NaN, on writing,
and NaN (never zeros) on reading; a many-clock recording is written one Imu topic per stream, on its own rows."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from formats import Recording
from formats.bags import read_bag, write_bag
from formats.frames import euler_to_quat
from formats.recording import join_streams

IMU = "sensor_msgs/msg/Imu"


def _messages(path: Path) -> dict[str, list]:
    """Every message of a bag, deserialised by rosbags itself (independent of our reader), by topic."""
    from rosbags.highlevel import AnyReader

    out: dict[str, list] = {}
    with AnyReader([path]) as r:
        for con, _, raw in r.messages():
            out.setdefault(con.topic, []).append(r.deserialize(raw, con.msgtype))
    return out


def _orientation(m) -> np.ndarray:
    o = m.orientation
    return np.array([o.x, o.y, o.z, o.w])


@pytest.mark.parametrize("name", ["nodata.bag", "nodata.db3"])
def test_missing_fields_are_minus_one_and_zeros_not_nan(tmp_path, name):
    n = 8
    t = 100.0 + np.arange(n) * 0.1
    q = euler_to_quat(np.full(n, 0.1), np.full(n, -0.05), np.linspace(0, 1, n))
    q[[2, 5]] = np.nan  # orientation unknown on two rows
    accel = np.tile([0.1, 0.2, -9.8], (n, 1))
    accel[3] = np.nan  # no accel on one row
    rec = Recording(t, {"q": q, "accel": accel})  # no gyro at all
    write_bag(rec, tmp_path / name)
    msgs = _messages(tmp_path / name)["/imu/data"]
    assert len(msgs) == n
    for i, m in enumerate(msgs):
        o = _orientation(m)
        assert np.all(np.isfinite(o)), f"message {i}: NaN in orientation {o}"
        if i in (2, 5):
            assert m.orientation_covariance[0] == -1 and np.all(o == 0)
        else:
            assert m.orientation_covariance[0] != -1 and abs(np.linalg.norm(o) - 1) < 1e-12
        assert m.angular_velocity_covariance[0] == -1  # the recording has no gyro
        assert (m.linear_acceleration_covariance[0] == -1) == (i == 3)
        assert np.all(np.isfinite([m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]))
    back = read_bag(tmp_path / name)
    assert "gyro" not in back and "gyro_std" not in back  # every message says "no gyro": never zeros
    assert np.isnan(back["q"][[2, 5]]).all() and np.isfinite(back["q"][[0, 1, 3, 4, 6, 7]]).all()
    assert np.isnan(back["accel"][3]).all() and np.allclose(back["accel"][[0, 7]], accel[[0, 7]])


def test_gyro_absent_on_some_messages_reads_nan_not_zero(tmp_path):
    n = 6
    t = np.arange(n) * 0.02 + 5.0
    gyro = np.tile([0.01, -0.02, 0.03], (n, 1))
    gyro[[1, 4]] = np.nan
    write_bag(Recording(t, {"gyro": gyro}), tmp_path / "g.bag")
    for i, m in enumerate(_messages(tmp_path / "g.bag")["/imu/data"]):
        v = [m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z]
        assert np.isfinite(v).all() and (m.angular_velocity_covariance[0] == -1) == (i in (1, 4))
    back = read_bag(tmp_path / "g.bag")
    assert np.isnan(back["gyro"][[1, 4]]).all()
    assert np.allclose(back["gyro"][[0, 2, 3, 5]], gyro[[0, 2, 3, 5]])


def _two_clock_recording() -> Recording:
    """An attitude stream at 10 Hz and a gyro stream at 25 Hz on their own clocks (no common rows but t=0)."""
    ta = np.arange(20) * 0.1
    tg = np.arange(50) * 0.04 + 0.013
    att = Recording(ta)
    att.add("roll", np.full(ta.size, 2.0), "deg")
    att.add("pitch", np.full(ta.size, -1.0), "deg")
    att.add("heading", np.linspace(10, 20, ta.size), "deg")
    gyr = Recording(tg, {"gyro": np.tile([0.0, 0.01, 0.02], (tg.size, 1))})
    return join_streams([att, gyr], ["PSXN23", "GYRO"])


def test_many_clock_recording_is_one_topic_per_stream_on_its_own_rows(tmp_path):
    rec = _two_clock_recording()
    assert rec.multi_clock and len(rec) == 70
    res = write_bag(rec, tmp_path / "mc.bag")
    assert res["messages"] == {"/imu/data/psxn23": 20, "/imu/data/gyro": 50}
    assert res["streams"] == {"/imu/data/psxn23": "PSXN23", "/imu/data/gyro": "GYRO"}
    msgs = _messages(tmp_path / "mc.bag")
    att, gyr = msgs["/imu/data/psxn23"], msgs["/imu/data/gyro"]
    assert all(m.orientation_covariance[0] != -1 and np.isfinite(_orientation(m)).all() for m in att)
    assert all(m.angular_velocity_covariance[0] == -1 for m in att)  # the attitude stream has no gyro
    assert all(m.orientation_covariance[0] == -1 and not _orientation(m).any() for m in gyr)
    assert all(m.angular_velocity_covariance[0] != -1 for m in gyr)
    back = read_bag(tmp_path / "mc.bag", topic="/imu/data/gyro")
    assert len(back) == 50 and "q" not in back and np.isfinite(back["gyro"]).all()


def test_many_clock_nmea_log_to_bag(shared, tmp_path):
    """A real interleaved log (Hemisphere-style $PASHR at 25 Hz with $GPGGA, $GPHDT, $GPRMC between): an Imu message
    only where the attitude sentence has a sample, never one per table row with a NaN quaternion."""
    import formats

    src = shared("nmea_gpsd", "rst39.log")
    lines = [ln for ln in src.read_text().splitlines() if ln.startswith("$")]
    log = tmp_path / "interleaved.log"
    log.write_text("\n".join(lines) + "\n")
    rec = formats.read(log)
    assert rec.multi_clock
    n_att = int((rec.own_rows("roll") & rec.own_rows("pitch") & rec.own_rows("heading")).sum())
    assert 0 < n_att < len(rec)  # rows of GGA/RMC/HDT alone are not attitude samples
    for name in ("x.bag", "x.mcap"):
        res = write_bag(rec, tmp_path / name)
        assert res["messages"] == {"/imu/data": n_att}
        assert any("heading" in s and "HDT" in s for s in res["notes"])  # HDT-only headings counted, not lost silently
        msgs = _messages(tmp_path / name)["/imu/data"]
        assert len(msgs) == n_att
        assert all(np.isfinite(_orientation(m)).all() for m in msgs)
        assert all(m.angular_velocity_covariance[0] == -1 for m in msgs)
        back = read_bag(tmp_path / name)
        assert len(back) == n_att and "gyro" not in back and "accel" not in back
        assert np.isfinite(back["q"]).all()
        r_in = rec.stream("roll")
        assert np.allclose(back.time, r_in.time, atol=1e-6)
