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


# -- GNSS topics: NavSatFix / TwistStamped read on their own streams, every other topic named --------------------
NAVSAT, TWIST, ODOM = "sensor_msgs/msg/NavSatFix", "geometry_msgs/msg/TwistStamped", "nav_msgs/msg/Odometry"


def _gnss_bag(path: Path, kind: str) -> Path:
    """A bag written with rosbags' own writer: Imu at 50 Hz, NavSatFix and TwistStamped at 5 Hz, Odometry."""
    from rosbags.typesys import Stores, get_typestore

    ros1 = kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    T, H = ts.types["builtin_interfaces/msg/Time"], ts.types["std_msgs/msg/Header"]
    V, Q = ts.types["geometry_msgs/msg/Vector3"], ts.types["geometry_msgs/msg/Quaternion"]
    Tw = ts.types["geometry_msgs/msg/Twist"]

    def hdr(ns, frame="gps"):
        st = T(ns // 10**9, ns % 10**9)
        return H(0, st, frame) if ros1 else H(st, frame)

    t0 = 1_700_000_000 * 10**9
    msgs: dict[str, tuple[str, list]] = {"/imu": (IMU, []), "/fix": (NAVSAT, []), "/vel": (TWIST, [])}
    msgs["/odom"] = (ODOM, [])
    for i in range(100):
        ns = t0 + i * 20_000_000
        cov = np.zeros(9)
        m = ts.types[IMU](hdr(ns, "imu"), Q(0, 0, 0, 1), cov, V(0.01, 0.02, 0.03), cov, V(0, 0, 9.8), cov)
        msgs["/imu"][1].append((ns, m))
    St = ts.types["sensor_msgs/msg/NavSatStatus"]
    for i in range(10):
        ns = t0 + 3_000_000 + i * 200_000_000
        status = -1 if i == 4 else 0
        pc = np.diag([0.25, 1.0, 4.0]).ravel()
        fix = ts.types[NAVSAT](hdr(ns), St(status, 1), 63.4 + i * 1e-5, 10.4 - i * 2e-5, 30.0 + i, pc, 2)
        msgs["/fix"][1].append((ns, fix))
        vel = ts.types[TWIST](hdr(ns + 1_000_000), Tw(V(1.0, 2.0, 0.5), V(0, 0, 0.1)))  # ENU: east 1, north 2, up 0.5
        msgs["/vel"][1].append((ns + 1_000_000, vel))
    P = ts.types["geometry_msgs/msg/PoseWithCovariance"]
    TC = ts.types["geometry_msgs/msg/TwistWithCovariance"]
    Pose, Pt = ts.types["geometry_msgs/msg/Pose"], ts.types["geometry_msgs/msg/Point"]
    for i in range(7):
        ns = t0 + i * 100_000_000
        od = ts.types[ODOM](
            hdr(ns, "odom"), "base_link", P(Pose(Pt(0, 0, 0), Q(0, 0, 0, 1)), np.zeros(36)),
            TC(Tw(V(1, 0, 0), V(0, 0, 0)), np.zeros(36)),
        )  # fmt: skip
        msgs["/odom"][1].append((ns, od))
    if ros1:
        from rosbags.rosbag1 import Writer

        w = Writer(path)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        w = Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3)
    with w:
        for name, (msgtype, lst) in msgs.items():
            conn = w.add_connection(name, msgtype, typestore=ts)
            for t, m in lst:
                w.write(conn, t, ts.serialize_ros1(m, msgtype) if ros1 else ts.serialize_cdr(m, msgtype))
    return path


@pytest.mark.parametrize("kind", ["ros1", "sqlite3"])
def test_gnss_topics_named_are_read_on_their_own_streams(tmp_path, kind):
    bag = _gnss_bag(tmp_path / ("g.bag" if kind == "ros1" else "g_ros2"), kind)
    rec = read_bag(bag, topic="/imu,/fix,/vel")
    assert rec.multi_clock
    assert {k: int(m.sum()) for k, m in rec.stream_rows.items()} == {"/imu": 100, "/fix": 10, "/vel": 10}
    t, lat = rec.series("lat")
    assert len(t) == 10 and np.isnan(lat[4]) and np.allclose(lat[[0, 9]], [63.4, 63.4 + 9e-5])
    assert np.allclose(rec.series("gnss_height")[1][[0, 9]], [30.0, 39.0])
    assert np.allclose(rec.series("gnss_lat_std")[1], 1.0) and np.allclose(rec.series("gnss_lon_std")[1], 0.5)
    assert np.allclose(rec.series("vel_n")[1], 2.0) and np.allclose(rec.series("vel_e")[1], 1.0)
    assert np.allclose(rec.series("vel_d")[1], -0.5)  # ENU up 0.5 → NED down -0.5
    assert len(rec.series("gyro")[0]) == 100 and np.isfinite(rec.series("gyro")[1]).all()
    assert rec.meta["bag"]["topics_not_read"] == [{"topic": "/odom", "type": ODOM, "messages": 7}]


def test_topics_not_read_are_named_with_type_and_count(tmp_path, capsys):
    import json

    from imutool.cli import main

    bag = _gnss_bag(tmp_path / "g.bag", "ros1")
    rec = read_bag(bag)
    assert not rec.multi_clock and len(rec) == 100  # unnamed GNSS topics do not change the IMU recording
    assert {(t["topic"], t["messages"]) for t in rec.meta["bag"]["topics_not_read"]} == {
        ("/fix", 10),
        ("/vel", 10),
        ("/odom", 7),
    }
    with pytest.raises(SystemExit) as e:
        main(["info", str(bag)])
    out, err = capsys.readouterr()
    assert e.value.code in (0, None)
    assert "NOT READ" in err and "/fix (sensor_msgs/msg/NavSatFix, 10 msgs; name it in --topic" in err
    assert "bag topic not read: /odom (nav_msgs/msg/Odometry, 7 msgs)" in out
    with pytest.raises(SystemExit):
        main(["info", str(bag), "--json"])
    s = json.loads(capsys.readouterr().out)
    assert len(s["bag_topics_not_read"]) == 3
