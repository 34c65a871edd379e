"""ROS bag reader/writer: fast decode vs rosbags, REP-103 → FRD/NED, round trips, topic choice, real bags."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from formats import ImutoolError, Recording
from formats.bags import (
    BagReader,
    frd_to_ros_quat,
    list_topics,
    open_bag,
    read_bag,
    recording_of,
    ros_to_frd_quat,
    write_bag,
)
from formats.bags.writer import serialise as _serialise
from formats.csv import read_csv, write_csv
from formats.frames import euler_to_quat, quat_rotate, quat_to_euler

IMU = "sensor_msgs/msg/Imu"
MAG = "sensor_msgs/msg/MagneticField"
VEC3 = "geometry_msgs/msg/Vector3Stamped"
RL = ("rosbags", "robot_localization")


# -- helpers: bags written message by message with rosbags itself (independent of our writer) ----------------
def _store(ros1: bool):
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)


def _header(ts, ros1: bool, ns: int, frame: str, seq: int = 0):
    T = ts.types["builtin_interfaces/msg/Time"]
    H = ts.types["std_msgs/msg/Header"]
    stamp = T(ns // 1_000_000_000, ns % 1_000_000_000)
    return H(seq, stamp, frame) if ros1 else H(stamp, frame)


def _imu_msg(ts, ros1, ns, frame, q_xyzw, gyro, accel, qcov, gcov, acov, seq=0):
    Q = ts.types["geometry_msgs/msg/Quaternion"]
    V = ts.types["geometry_msgs/msg/Vector3"]
    return ts.types[IMU](
        _header(ts, ros1, ns, frame, seq),
        Q(*q_xyzw),
        np.asarray(qcov, float),
        V(*gyro),
        np.asarray(gcov, float),
        V(*accel),
        np.asarray(acov, float),
    )


def _write_raw_bag(path: Path, kind: str, topics: dict[str, tuple[str, list]], compression: str | None = None):
    """topics: name -> (msgtype, [(record_ns, message object)]). kind: ros1 | sqlite3 | mcap."""
    ros1 = kind == "ros1"
    ts = _store(ros1)
    if ros1:
        from rosbags.rosbag1 import Writer

        w = Writer(path)
        if compression:
            w.set_compression(Writer.CompressionFormat[compression.upper()])
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        w = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3)
    with w:
        for name, (msgtype, msgs) in topics.items():
            conn = w.add_connection(name, msgtype, typestore=ts)
            for t, m in msgs:
                raw = ts.serialize_ros1(m, msgtype) if ros1 else ts.serialize_cdr(m, msgtype)
                w.write(conn, t, raw)
    return path


def _random_imu_msgs(
    ros1: bool, n: int, rng, frame="imu_link", t0_ns=1_700_000_000_000_000_000, dt_ns=10_000_000, full_cov=False
):
    ts = _store(ros1)
    msgs = []
    for i in range(n):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        c = [rng.normal(size=(3, 3)) for _ in range(3)]
        covs = [(a @ a.T).ravel() if full_cov else np.diag(np.diag(a @ a.T)).ravel() for a in c]
        ns = t0_ns + i * dt_ns
        msgs.append(
            (ns + 12345, _imu_msg(ts, ros1, ns, frame, q, rng.normal(size=3), rng.normal(size=3) * 9, *covs, seq=i))
        )
    return msgs


@pytest.fixture(scope="module")
def sim_rec():
    """A small 9-axis recording with an estimate (q + std) and extra channels, as read from an imutool CSV."""
    rng = np.random.default_rng(7)
    n = 400
    t = 12.0 + np.arange(n) * 0.01 + rng.uniform(0, 1e-4, n)
    rec = Recording(t)
    rec.add("gyro", rng.normal(size=(n, 3)) * 0.3)
    rec.add("accel", rng.normal(size=(n, 3)) + [0, 0, -9.81])
    rec.add("mag", rng.normal(size=(n, 3)) * 20 + [18, 2, 45])
    rec.add("q", euler_to_quat(rng.uniform(-0.5, 0.5, n), rng.uniform(-0.3, 0.3, n), rng.uniform(0, 6.28, n)))
    rec.add("roll_std", np.full(n, 0.4))
    rec.add("pitch_std", np.full(n, 0.45))
    rec.add("heading_std", rng.uniform(1, 3, n))
    rec.add("ref_roll", rng.normal(size=n))
    rec.add("temp", np.full(n, 21.5))
    return rec


# -- frame conventions ------------------------------------------------------------------------------------------
def test_quaternion_conversion_is_rep103_to_ned():
    # ROS: body x pointing East (identity FLU->ENU) is heading 90 deg in NED; yaw +30 deg (CCW) → heading 60 deg.
    for yaw_enu, heading in ((0.0, 90.0), (30.0, 60.0), (-45.0, 135.0)):
        h = np.radians(yaw_enu) / 2
        q = ros_to_frd_quat(np.array([0.0, 0.0, np.sin(h), np.cos(h)]))
        r, p, y = quat_to_euler(q)
        assert abs(r) < 1e-12 and abs(p) < 1e-12
        assert np.degrees(y) == pytest.approx(heading, abs=1e-9)
    # a ROS roll (about FLU x, right side up) is the same physical roll: starboard (right) side up = negative roll
    h = np.radians(10) / 2
    r, p, y = quat_to_euler(ros_to_frd_quat(np.array([np.sin(h), 0, 0, np.cos(h)])))
    assert np.degrees(r) == pytest.approx(10.0, abs=1e-9)  # +x rotation keeps its sense (same axis)
    # ROS pitch about FLU y (left) positive = nose down; NED pitch positive = bow up
    r, p, y = quat_to_euler(ros_to_frd_quat(np.array([0, np.sin(h), 0, np.cos(h)])))
    assert np.degrees(p) == pytest.approx(-10.0, abs=1e-9)
    q = euler_to_quat(np.array([0.1]), np.array([-0.2]), np.array([2.0]))
    assert np.allclose(ros_to_frd_quat(frd_to_ros_quat(q)), q, atol=1e-15)


def test_level_sensor_reads_minus_g_and_heading(tmp_path):
    """A level ROS IMU (z up reads +g) facing north-east: imutool sees accel z = -g, heading 45 deg, z-rate sign."""
    ts = _store(True)
    yaw = np.radians(45.0) / 2  # ENU yaw 45 deg: x between East and North → heading 45 deg
    msgs = [
        (
            i * 10**7 + 1,
            _imu_msg(
                ts,
                True,
                i * 10**7 + 1,
                "imu",
                [0, 0, np.sin(yaw), np.cos(yaw)],
                [0, 0, 0.1],
                [0, 0, 9.81],
                np.eye(3).ravel() * 1e-4,
                np.zeros(9),
                np.zeros(9),
            ),
        )
        for i in range(5)
    ]
    p = _write_raw_bag(tmp_path / "level.bag", "ros1", {"/imu": (IMU, msgs)})
    rec = read_bag(p)
    assert np.allclose(rec["accel"], [0, 0, -9.81])
    assert np.allclose(rec["gyro"], [0, 0, -0.1])  # CCW (left) turn in FLU = negative yaw rate in FRD
    _, _, hd = quat_to_euler(rec["q"])
    assert np.allclose(np.degrees(hd), 45.0)
    assert np.allclose(quat_rotate(rec["q"], rec["accel"]), [0, 0, -9.81])
    assert np.allclose(rec["roll_std"], np.degrees(0.01))
    assert "gyro_std" not in rec  # all-zero covariance = unknown → no channel


def test_full_covariance_rotated(tmp_path):
    rng = np.random.default_rng(3)
    msgs = _random_imu_msgs(False, 20, rng, full_cov=True)
    p = _write_raw_bag(tmp_path / "cov", "sqlite3", {"/imu": (IMU, msgs)})
    rec = read_bag(p)
    R = np.diag([1.0, -1.0, -1.0])
    for name, attr in (
        ("q_cov", "orientation_covariance"),
        ("gyro_cov", "angular_velocity_covariance"),
        ("accel_cov", "linear_acceleration_covariance"),
    ):
        c_flu = np.stack([getattr(m, attr) for _, m in msgs]).reshape(-1, 3, 3)
        expect = np.einsum("ij,njk,lk->nil", R, c_flu, R).reshape(-1, 9)
        assert np.array_equal(rec[name], expect)
        c = rec[name].reshape(-1, 3, 3)
        assert np.allclose(c, np.swapaxes(c, 1, 2))
        assert np.all(np.linalg.eigvalsh(c) > 0)


def test_absent_orientation_marked_minus_one(tmp_path):
    ts = _store(True)
    cov = np.zeros(9)
    cov[0] = -1
    msgs = [
        (
            i * 10**7 + 5,
            _imu_msg(ts, True, i * 10**7 + 5, "imu", [0, 0, 0, 0], [1, 2, 3], [4, 5, 6], cov, np.zeros(9), np.zeros(9)),
        )
        for i in range(4)
    ]
    rec = read_bag(_write_raw_bag(tmp_path / "noq.bag", "ros1", {"/imu": (IMU, msgs)}))
    assert "q" not in rec and "roll_std" not in rec
    assert np.array_equal(rec["gyro"], np.tile([1.0, -2.0, -3.0], (4, 1)))


# -- fast decode equals rosbags' own deserialisation ------------------------------------------------------------
@pytest.mark.parametrize(
    "kind,compression", [("ros1", None), ("ros1", "bz2"), ("ros1", "lz4"), ("sqlite3", None), ("mcap", None)]
)
def test_fast_equals_rosbags(tmp_path, kind, compression):
    rng = np.random.default_rng(11)
    ros1 = kind == "ros1"
    imu = _random_imu_msgs(ros1, 150, rng, full_cov=True)
    # one message with a different frame_id length (variable-length header)
    ts = _store(ros1)
    t, m = imu[70]
    imu[70] = (
        t,
        _imu_msg(
            ts,
            ros1,
            t - 12345,
            "a_much_longer_frame",
            [0, 0, 0, 1],
            [1, 1, 1],
            [2, 2, 2],
            np.eye(3).ravel(),
            np.eye(3).ravel(),
            np.eye(3).ravel(),
        ),
    )
    M = ts.types[MAG]
    V = ts.types["geometry_msgs/msg/Vector3"]
    mag = [
        (
            i * 13_000_000 + imu[0][0],
            M(
                _header(ts, ros1, i * 13_000_000 + imu[0][0], "mag"),
                V(*(rng.normal(size=3) * 4e-5)),
                np.eye(3).ravel() * 1e-14,
            ),
        )
        for i in range(120)
    ]
    name = "b.bag" if ros1 else f"b_{kind}"
    p = _write_raw_bag(tmp_path / name, kind, {"/imu/data": (IMU, imu), "/imu/mag": (MAG, mag)}, compression)
    fast = read_bag(p)
    slow = read_bag(p, fast=False)
    assert set(fast.channels) == set(slow.channels) >= {"gyro", "accel", "q", "mag", "q_cov", "mag_std"}
    assert np.array_equal(fast.time, slow.time)
    for k in fast.channels:
        assert np.array_equal(fast[k], slow[k], equal_nan=True), k
    assert sorted(fast.meta["bag"]["frame_id"]) == ["a_much_longer_frame", "imu_link", "mag"]
    # magnetometer interpolated onto the IMU clock (header stamps), converted T → µT and FLU → FRD
    tm = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for _, m in mag])
    vm = np.array([[m.magnetic_field.x, -m.magnetic_field.y, -m.magnetic_field.z] for _, m in mag]) * 1e6
    expect = np.stack([np.interp(fast.time, tm, vm[:, j]) for j in range(3)], axis=1)
    assert np.allclose(fast["mag"], expect, rtol=1e-9, atol=1e-6)
    assert fast.time[0] >= tm[0] and fast.time[-1] <= tm[-1]  # only the common span is kept
    for s in ("record",):
        r = read_bag(p, stamp=s)
        assert r.meta["bag"]["stamp"] == s


def test_serialisation_matches_rosbags():
    ts1, ts2 = _store(True), _store(False)
    rng = np.random.default_rng(5)
    floats = rng.normal(size=(3, 37))
    t = np.array([1.5, 2.25, 1_700_000_000.123456789])
    for ros1, ts in ((True, ts1), (False, ts2)):
        pay = _serialise(t, floats, "ros1" if ros1 else "cdr", "base_link")
        for i in range(3):
            f = floats[i]
            sec = int(np.floor(t[i]))
            ns = sec * 1_000_000_000 + int(round((t[i] - sec) * 1e9))
            m = _imu_msg(ts, ros1, ns, "base_link", f[0:4], f[13:16], f[25:28], f[4:13], f[16:25], f[28:37], seq=i)
            ref = bytes(ts.serialize_ros1(m, IMU) if ros1 else ts.serialize_cdr(m, IMU, little_endian=True))
            assert pay[i].tobytes() == ref


# -- round trips -------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("out", ["rt.bag", "rt.db3", "rt.mcap", "rt_folder", "rt_folder_mcap"])
def test_csv_bag_csv_round_trip(tmp_path, sim_rec, out):
    src = tmp_path / "in.csv"
    write_csv(sim_rec, src)
    rec = read_csv(src)
    kw = {"storage": "mcap"} if out.endswith("_mcap") else {}
    summary = write_bag(rec, tmp_path / out, **kw)
    assert sorted(summary["channels_not_written"]) == ["ref_roll", "temp"]
    back_csv = tmp_path / "back.csv"
    write_csv(read_bag(tmp_path / out), back_csv)
    back = read_csv(back_csv)
    # stamps are integer ns: time agrees within 1 ns (plus float64 rounding of the seconds value)
    assert np.max(np.abs(back.time - rec.time)) <= 1e-9 + 4e-15 * np.max(np.abs(rec.time))
    for k in ("gyro", "accel"):
        assert np.array_equal(back[k], rec[k]), k  # FLU↔FRD is a sign flip: exact
    for k in ("roll_std", "pitch_std", "heading_std"):  # deg → rad² variance → deg: a few roundings
        assert np.allclose(back[k], rec[k], rtol=1e-15, atol=0), k
    assert np.allclose(back["mag"], rec["mag"], rtol=4e-16, atol=0)  # µT ↔ T: one rounding each way
    assert np.allclose(back["q"], rec["q"], rtol=0, atol=5e-16)  # ENU↔NED quaternion product uses √½
    assert set(back.channels) == {"gyro", "accel", "mag", "q", "roll_std", "pitch_std", "heading_std"}


def test_write_errors_and_atomicity(tmp_path, sim_rec):
    with pytest.raises(ImutoolError, match="nothing to write"):
        write_bag(Recording(np.arange(3.0), {"temp": np.ones(3)}), tmp_path / "x.bag")
    bad = sim_rec.select(np.array([3, 2, 1]))
    with pytest.raises(ImutoolError, match="backwards"):
        write_bag(bad, tmp_path / "y.db3")
    assert not any(tmp_path.iterdir())  # nothing partial left behind
    # overwriting an existing bag works (atomic replace)
    write_bag(sim_rec, tmp_path / "z.bag")
    write_bag(sim_rec.select(slice(0, 10)), tmp_path / "z.bag")
    assert len(read_bag(tmp_path / "z.bag")) == 10


# -- topic selection and stamps -----------------------------------------------------------------------------------
def test_topic_selection_and_stamps(tmp_path):
    rng = np.random.default_rng(1)
    a = _random_imu_msgs(True, 10, rng)
    b = _random_imu_msgs(True, 7, rng, frame="imu2")
    p = _write_raw_bag(tmp_path / "two.bag", "ros1", {"/imu/a": (IMU, a), "/imu/b": (IMU, b)})
    with pytest.raises(ImutoolError) as e:
        read_bag(p)
    msg = str(e.value)
    assert "/imu/a (sensor_msgs/msg/Imu, 10 msgs)" in msg and "/imu/b (sensor_msgs/msg/Imu, 7 msgs)" in msg
    assert len(read_bag(p, topic="/imu/b")) == 7
    with pytest.raises(ImutoolError, match="not in bag"):
        read_bag(p, topic="/nope")
    tops = {t["topic"]: t for t in list_topics(p)}
    assert tops["/imu/a"]["count"] == 10 and tops["/imu/b"]["kind"] == "imu"
    # header stamps vs record time
    ra, rr = read_bag(p, topic="/imu/a"), read_bag(p, topic="/imu/a", stamp="record")
    assert np.allclose(rr.time - ra.time, 12345e-9, rtol=0, atol=5e-7)  # float64 at 1.7e9 s: 0.24 µs


def test_zero_header_stamps_suggest_record(tmp_path):
    ts = _store(False)
    msgs = [
        (
            10**9 + i * 10**7,
            _imu_msg(ts, False, 0, "imu", [0, 0, 0, 1], [0, 0, 0], [0, 0, 9.8], np.zeros(9), np.zeros(9), np.zeros(9)),
        )
        for i in range(5)
    ]
    p = _write_raw_bag(tmp_path / "zero", "sqlite3", {"/imu": (IMU, msgs)})
    with pytest.raises(ImutoolError, match="zero header stamp.*--stamp record"):
        read_bag(p)
    rec = read_bag(p, stamp="record")
    assert np.allclose(np.diff(rec.time), 0.01)


def test_vector3stamped_magnetometer(tmp_path):
    ts = _store(True)
    V3S = ts.types[VEC3]
    V = ts.types["geometry_msgs/msg/Vector3"]
    msgs = [(i * 10**7 + 7, V3S(_header(ts, True, i * 10**7 + 7, "mag"), V(0.2, 0.1, -0.4))) for i in range(6)]
    p = _write_raw_bag(tmp_path / "v.bag", "ros1", {"/imu/mag": (VEC3, msgs)})
    assert np.allclose(read_bag(p)["mag"], [0.2e6, -0.1e6, 0.4e6])  # tesla by default
    assert np.allclose(read_bag(p, vector3_mag_unit="gauss")["mag"], [20.0, -10.0, 40.0])  # 1 gauss = 100 µT


def test_unusual_payload_falls_back_to_rosbags(tmp_path):
    """Big-endian CDR is not on the fast path; rosbags decodes it."""
    rng = np.random.default_rng(2)
    msgs = _random_imu_msgs(False, 8, rng)
    ts = _store(False)
    from rosbags.rosbag2 import Writer

    with Writer(tmp_path / "be", version=9) as w:
        c = w.add_connection("/imu", IMU, typestore=ts)
        for i, (t, m) in enumerate(msgs):
            w.write(c, t, ts.serialize_cdr(m, IMU, little_endian=i % 2 == 0))
    rec = read_bag(tmp_path / "be")
    assert rec.meta["bag"]["topics"]["imu"]["decoded_by_rosbags"] == 4
    assert np.array_equal(rec["gyro"], read_bag(tmp_path / "be", fast=False)["gyro"])


# -- real bags ----------------------------------------------------------------------------------------------------
def test_real_ros1_and_ros2_conversions_agree(shared):
    b1 = read_bag(shared(*RL, "test2.bag"))
    for folder in ("robot_localization_test2_sqlite3", "robot_localization_test2_mcap"):
        b2 = read_bag(shared("rosbags", folder))  # ROS2 conversions made for this data set (see MANIFEST)
        assert np.array_equal(b1.time, b2.time)
        for k in b1.channels:
            assert np.array_equal(b1[k], b2[k]), (folder, k)
    assert len(b1) == 3061 and b1.meta["bag"]["frame_id"] == ["base_link"]
    slow = read_bag(shared(*RL, "test2.bag"), fast=False)  # rosbags' own per-message deserialisation
    for k in b1.channels:
        assert np.array_equal(b1[k], slow[k]), k
    # orientation and specific force agree: gravity in NED points up the z axis (reads -g)
    g = np.median(quat_rotate(b1["q"], b1["accel"]), axis=0)
    assert np.allclose(g, [0, 0, -9.81], atol=0.1)


def test_real_ros1_test1_rotated_mount(shared):
    rec = read_bag(shared(*RL, "test1.bag"))
    assert len(rec) == 11865 and rec.meta["bag"]["frame_id"] == ["imu_link"]
    # gravity on the sensor's +y (FLU) axis → FRD y reads about -9.8: the IMU is mounted on its side
    assert np.median(rec["accel"][:, 1]) == pytest.approx(-9.79, abs=0.1)
    g = np.median(quat_rotate(rec["q"], rec["accel"]), axis=0)
    assert np.allclose(g, [0, 0, -9.8], atol=0.1)


def test_truncated_bag_partial_read(shared, tmp_path):
    src = shared(*RL, "test1.bag")
    data = Path(src).read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: int(len(data) * 0.7)])
    rec = read_bag(cut)
    assert 0 < len(rec) < 11865
    assert rec.meta["bag"]["truncated"] and "messages recovered" in rec.meta["bag"]["partial_read"]
    tiny = tmp_path / "tiny.bag"
    tiny.write_bytes(data[:5000])
    with pytest.raises(ImutoolError, match="truncated"):
        read_bag(tiny)
    notbag = tmp_path / "junk.bag"
    notbag.write_bytes(b"hello world\n" * 10)
    with pytest.raises(ImutoolError, match="not a ROS1 bag"):
        read_bag(notbag)


def test_truncated_ros2_bags(shared, tmp_path):
    """MCAP cut short: complete chunks are read and the cut reported; cut too early: a clear error.
    (The ROS2 folders are conversions of test2.bag made for this data set, see the MANIFEST.)"""
    src = shared("rosbags", "robot_localization_test2_mcap")
    dst = tmp_path / "m"
    shutil.copytree(src, dst)
    f = next(dst.glob("*.mcap"))
    f.chmod(0o644)
    data = f.read_bytes()
    f.write_bytes(data[: int(len(data) * 0.9)])
    rec = read_bag(dst)
    assert 0 < len(rec) < 3061 and "messages recovered" in rec.meta["bag"]["partial_read"]
    full = read_bag(src)
    assert np.array_equal(rec["gyro"], full["gyro"][: len(rec)])
    f.write_bytes(data[:100000])
    with pytest.raises(ImutoolError, match="truncated"):
        read_bag(dst)
    db = tmp_path / "s.db3"
    db.write_bytes(next(shared("rosbags", "robot_localization_test2_sqlite3").glob("*.db3")).read_bytes()[:50000])
    with pytest.raises(ImutoolError):
        read_bag(db)


def test_corrupted_bytes_never_crash(tmp_path, sim_rec):
    """Random byte damage in an uncompressed and a bz2 ROS1 bag: a Recording (damage reported) or ImutoolError."""
    rng = np.random.default_rng(0)
    for comp in (None, "bz2"):
        good = tmp_path / f"good_{comp}.bag"
        write_bag(sim_rec, good, compression=comp)
        data = good.read_bytes()
        for trial in range(15):
            buf = bytearray(data)
            for pos in rng.integers(13, len(buf), size=int(rng.integers(1, 6))):
                buf[pos] = int(rng.integers(0, 256))
            p = tmp_path / f"bad_{comp}_{trial}.bag"
            p.write_bytes(bytes(buf))
            try:
                rec = read_bag(p)
            except ImutoolError:
                continue
            assert len(rec) <= len(sim_rec)


def test_sqlite_page_reader_equals_sql(tmp_path, sim_rec, monkeypatch):
    """The direct b-tree page walk of a .db3 gives exactly what SQL gives (several pages, two topics)."""
    import formats.bags.ros2_sqlite3 as rb

    p = tmp_path / "x.db3"
    write_bag(sim_rec, p)
    assert rb.sqlite_direct(p, [1, 2]) is not None  # the page walk is taken for this file
    direct = read_bag(p)
    monkeypatch.setattr(rb, "sqlite_direct", lambda *a: None)
    via_sql = read_bag(p)
    assert np.array_equal(direct.time, via_sql.time)
    for k in via_sql.channels:
        assert np.array_equal(direct[k], via_sql[k]), k


def test_corrupted_sqlite_pages_never_crash(tmp_path, sim_rec):
    """Random byte damage inside a .db3 (past the 100-byte header): a Recording or an ImutoolError."""
    good = tmp_path / "good.db3"
    write_bag(sim_rec, good)
    data = good.read_bytes()
    rng = np.random.default_rng(1)
    for trial in range(15):
        buf = bytearray(data)
        for pos in rng.integers(100, len(buf), size=int(rng.integers(1, 8))):
            buf[pos] = int(rng.integers(0, 256))
        p = tmp_path / f"bad{trial}.db3"
        p.write_bytes(bytes(buf))
        try:
            read_bag(p)
        except ImutoolError:
            pass


# -- one reader protocol -----------------------------------------------------------------------------------------
def test_every_backend_gives_the_same_recording(tmp_path, sim_rec):
    """One recording written by write_bag as ROS1, sqlite3 and MCAP, each opened by every back-end that reads it
    through the one protocol (context manager, topics, lazy messages, bulk raw): the same Recording, bit for bit."""
    from collections.abc import Iterator

    from formats.bags.ros1 import Ros1Bag
    from formats.bags.ros2_mcap import McapBag
    from formats.bags.ros2_rosbags import RosbagsBag
    from formats.bags.ros2_sqlite3 import Sqlite3Bag

    bag, db, mc = tmp_path / "x.bag", tmp_path / "x.db3", tmp_path / "x.mcap"
    for p in (bag, db, mc):
        write_bag(sim_rec, p)
    # open_bag picks the fast back-end for each of our files
    for p, cls in ((bag, Ros1Bag), (db, Sqlite3Bag), (mc, McapBag)):
        with open_bag(p) as b:
            assert type(b) is cls
    backends = [
        (Ros1Bag(str(bag)), "ros1"),
        (Sqlite3Bag(str(db), [db], None), "ros2-sqlite3"),
        (McapBag(str(mc), [mc]), "ros2-mcap"),
        (RosbagsBag(str(db), "sqlite3"), "ros2-sqlite3"),
        (RosbagsBag(str(mc), "mcap"), "ros2-mcap"),
    ]
    ref = read_bag(bag)
    cdr_payloads = None
    for b, fmt in backends:
        assert isinstance(b, BagReader) and b.format == fmt
        with b:
            topics = b.topics()
            assert {k: t.count for k, t in topics.items()} == {"/imu/data": 400, "/imu/mag": 400}
            imu = topics["/imu/data"]
            lazy = b.messages(imu)
            assert isinstance(lazy, Iterator)
            rows = [next(lazy), *lazy]  # one message at a time, then the rest
            raw = b.raw(imu)
            assert [t for t, _ in rows] == raw.rec_ns.tolist()
            bulk = [raw.buf[o : o + n].tobytes() for o, n in zip(raw.offs, raw.lens, strict=True)]
            assert [d for _, d in rows] == bulk
            if fmt != "ros1":  # the ROS2 back-ends hand out the same CDR bytes
                cdr_payloads = cdr_payloads or rows
                assert rows == cdr_payloads, fmt
            rec = recording_of(b, str(bag))
        assert rec.meta["bag"]["format"] == fmt
        assert rec.meta["bag"]["topics"] == ref.meta["bag"]["topics"]
        assert list(rec.channels) == list(ref.channels)
        assert np.array_equal(rec.time, ref.time), fmt
        for k in ref.channels:
            assert np.array_equal(rec[k], ref[k]), (fmt, k)
    # and that Recording is the one written (a back-end that mixed up messages or topics would fail here)
    assert np.array_equal(ref["gyro"], sim_rec["gyro"]) and np.array_equal(ref["accel"], sim_rec["accel"])
    assert np.allclose(ref["q"], sim_rec["q"], rtol=0, atol=5e-16)


def test_zero_orientation_is_missing_not_an_attitude(tmp_path, sim_rec):
    """Four zeros without the covariance flag: every message → no q (and a note), some → NaN there."""
    rec = sim_rec.copy()
    rec.add("q", np.zeros((len(rec), 4)))
    p = tmp_path / "zq.bag"
    write_bag(rec, p)
    back = read_bag(p)
    assert "q" not in back and "gyro" in back
    assert any("[0, 0, 0, 0]" in n and "not read" in n for n in back.meta["bag"]["notes"])
    rec.channels["q"][:] = euler_to_quat(np.zeros(len(rec)), np.zeros(len(rec)), np.zeros(len(rec)))
    rec.channels["q"][5:9] = 0.0
    p2 = tmp_path / "zq2.bag"
    write_bag(rec, p2)
    back = read_bag(p2)
    assert np.isnan(back["q"][5:9]).all() and np.isfinite(back["q"][:5]).all()


def test_columns_state_a_bags_units_and_are_refused_where_they_cannot_apply(tmp_path, sim_rec, capsys):
    """A driver that wrote µT into MagneticField (tesla): the warning names --columns, and --columns works on a
    bag (it was ignored); a renaming or a Parquet input is refused in one line."""
    from conftest import run_main as run

    rec = sim_rec.copy()
    rec.channels["mag"] = rec["mag"] * 1e6  # µT numbers in the tesla field
    bag = tmp_path / "magT.bag"
    write_bag(rec, bag)
    code, out, err = run(["info", bag], capsys)
    assert code == 0 and "UNITS: magnetometer" in err and "look like uT" in err and "header" not in err
    fix = "mag_x=mag_x:uT,mag_y=mag_y:uT,mag_z=mag_z:uT"
    assert f"--columns '{fix}'" in err
    back = read_bag(bag, columns=fix)
    np.testing.assert_allclose(back["mag"], sim_rec["mag"], rtol=1e-6)
    assert back.meta["column_mapping"].startswith("mag_x->mag_x[uT]")
    code, out, err = run(["info", bag, "--columns", fix], capsys)
    assert code == 0 and "UNITS" not in err
    code, out, err = run(["convert", bag, tmp_path / "m.csv", "--columns", fix], capsys)
    assert code == 0 and "UNITS" not in err
    np.testing.assert_allclose(read_csv(tmp_path / "m.csv")["mag"], sim_rec["mag"], rtol=1e-6)
    scaled = read_bag(bag, columns="gyro_x=gyro_x*2")  # a scale alone, in the field's own unit
    np.testing.assert_allclose(scaled["gyro"][:, 0], 2 * read_bag(bag)["gyro"][:, 0])
    code, out, err = run(["info", bag, "--columns", "mag_x=mag_y:uT"], capsys)
    assert code == 2 and "keep their names" in err and len(err.strip().splitlines()) == 1
    pytest.importorskip("pyarrow", reason="Parquet needs the [parquet] extra (pyarrow)")
    pq = tmp_path / "m.parquet"
    code, out, err = run(["convert", tmp_path / "m.csv", pq], capsys)
    assert code == 0, err
    code, out, err = run(["info", pq, "--columns", fix], capsys)
    assert code == 2 and "--columns applies to a CSV or a ROS bag" in err and len(err.strip().splitlines()) == 1
