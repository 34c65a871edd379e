"""Raw-IMU vendor protocols (formats.imu_protocols): VectorNav ASCII $VNYMR/$VNIMU and WitMotion 0x55 packets.

Round trips of known values, corrupted checks, garbage between frames, frames split at every byte, the signs
(a unit at rest level gives roll 0, pitch 0 from its accel; a nose-up tilt gives + pitch), the live adapter and
`imutool capture serial --protocol vectornav|witmotion` through a pseudo-terminal.
"""

from __future__ import annotations

import math
import os
import threading
import time

import numpy as np
import pytest

from formats.imu_protocols import PROTOCOLS, make_decoder
from formats.imu_protocols.vectornav import crc16, encode_vnimu, encode_vnymr, xor_checksum
from formats.imu_protocols.witmotion import ACCEL_PER_COUNT, GYRO_PER_COUNT, encode_witmotion, packet
from formats.units import STANDARD_GRAVITY as G
from imutool.baseline import accel_tilt

RNG = np.random.default_rng(3)


def _values(n: int = 20):
    """n rows of imutool-convention values: rpy deg, mag µT, accel m/s², gyro rad/s (FRD)."""
    rpy = np.column_stack([RNG.uniform(-40, 40, n), RNG.uniform(-30, 30, n), RNG.uniform(-179, 179, n)])
    mag = RNG.uniform(-60, 60, (n, 3))
    acc = RNG.uniform(-15, 15, (n, 3))
    gyr = RNG.uniform(-3, 3, (n, 3))
    return rpy, mag, acc, gyr


def _vn_stream(n: int = 20, crc: bool = False):
    rpy, mag, acc, gyr = _values(n)
    frames = [
        encode_vnymr(rpy[i], mag[i], acc[i], gyr[i], crc=crc) if i % 3 else encode_vnimu(mag[i], acc[i], gyr[i])
        for i in range(n)
    ]
    return frames, rpy, mag, acc, gyr


def _wit_stream(n: int = 20):
    rpy, mag, acc, gyr = _values(n)
    frames = [encode_witmotion(acc[i], gyr[i], mag[i], rpy[i]) for i in range(n)]
    return frames, rpy, mag, acc, gyr


def test_checksums():
    assert crc16(b"123456789") == 0x31C3  # CRC-16-CCITT (XModem) check value
    assert xor_checksum(b"VNRRG,1") == (ord("V") ^ ord("N") ^ ord("R") ^ ord("R") ^ ord("G") ^ ord(",") ^ ord("1"))
    line = encode_vnymr((1, 2, 3), (0, 0, 0), (0, 0, -9.8), (0, 0, 0), crc=True)
    assert len(line.split(b"*")[1].strip()) == 4


@pytest.mark.parametrize("crc", [False, True])
def test_vectornav_round_trip(crc):
    frames, rpy, mag, acc, gyr = _vn_stream(30, crc)
    dec = make_decoder("vectornav")
    s = dec.feed(b"".join(frames))
    assert len(s) == 30 and dec.stats.frames == 30 and dec.stats.bad_checksum == 0
    np.testing.assert_allclose(s.accel, acc, atol=5.1e-4)
    np.testing.assert_allclose(s.gyro, gyr, atol=5.1e-7)
    np.testing.assert_allclose(s.mag, mag, atol=5.1e-3)  # 1e-4 gauss = 0.01 µT
    ymr = np.arange(30) % 3 != 0
    np.testing.assert_allclose(s.attitude[ymr], rpy[ymr], atol=5.1e-4)  # roll, pitch, yaw in that order
    assert np.isnan(s.attitude[~ymr]).all() and np.allclose(s.temp[~ymr], 25.0)
    assert list(s.end) == list(np.cumsum([len(f) for f in frames]) - 1)  # complete at its CR


def test_witmotion_round_trip():
    frames, rpy, mag, acc, gyr = _wit_stream(30)
    dec = make_decoder("witmotion")
    s = dec.feed(b"".join(frames))
    # cycles 1 and 2 are closed by the next one's start, then the cycle's packet set is known: each at its end
    assert len(s) == 30 and list(s.end[2:]) == list(np.cumsum([len(f) for f in frames])[2:])
    np.testing.assert_allclose(s.accel, acc, atol=ACCEL_PER_COUNT / 2 + 1e-9)
    np.testing.assert_allclose(s.gyro, gyr, atol=GYRO_PER_COUNT / 2 + 1e-9)
    np.testing.assert_allclose(s.mag, mag, atol=0.051)
    att = s.attitude
    np.testing.assert_allclose(att[:, :2], rpy[:, :2], atol=180 / 32768)
    dyaw = (att[:, 2] - rpy[:, 2] + 180) % 360 - 180
    assert np.max(np.abs(dyaw)) < 180 / 32768 + 1e-9
    assert dec.stats.bad_checksum == dec.stats.garbage_bytes == dec.stats.incomplete == 0


@pytest.mark.parametrize("name", sorted(PROTOCOLS))
def test_split_at_every_byte_boundary(name):
    frames = (_vn_stream(6) if name == "vectornav" else _wit_stream(6))[0]
    data = b"".join(frames)
    ref = make_decoder(name).feed(data)
    for cut in range(1, len(data)):
        dec = make_decoder(name)
        a, b = dec.feed(data[:cut]), dec.feed(data[cut:])
        np.testing.assert_array_equal(np.vstack([a.accel, b.accel]), ref.accel)
        np.testing.assert_array_equal(np.vstack([a.gyro, b.gyro]), ref.gyro)
        assert list(a.end) + [e + cut for e in b.end] == list(ref.end)  # offsets in each read's own bytes
        assert dec.stats.garbage_bytes == 0 and dec.stats.bad_checksum == 0
    dec = make_decoder(name)  # one byte a read
    got = [dec.feed(data[i : i + 1]) for i in range(len(data))]
    np.testing.assert_array_equal(np.vstack([g.accel for g in got if len(g)]), ref.accel)
    assert all(list(g.end) == [1] for g in got if len(g))


def _corrupt_check(frame: bytes, name: str) -> bytes:
    if name == "vectornav":
        star = frame.index(b"*")
        d = frame[star + 1 : star + 2]
        return frame[: star + 1] + (b"0" if d != b"0" else b"1") + frame[star + 2 :]
    return frame[:10] + bytes([(frame[10] + 1) & 0xFF]) + frame[11:]  # the 0x51 packet's sum


@pytest.mark.parametrize("name", sorted(PROTOCOLS))
def test_corrupted_checksum_is_counted_and_skipped(name):
    frames = (_vn_stream(9) if name == "vectornav" else _wit_stream(9))[0]
    ref = make_decoder(name).feed(b"".join(frames) + frames[0])
    bad = list(frames)
    bad[4] = _corrupt_check(bad[4], name)
    dec = make_decoder(name)
    s = dec.feed(b"".join(bad) + frames[0])
    assert dec.stats.bad_checksum == 1
    assert len(s) == len(ref) - 1  # the corrupted sample (and only it) is lost
    keep = [i for i in range(len(ref)) if i != 4]
    np.testing.assert_array_equal(s.accel, ref.accel[keep])
    if name == "witmotion":
        assert dec.stats.incomplete == 1 and dec.stats.resyncs == 1


@pytest.mark.parametrize("name", sorted(PROTOCOLS))
def test_garbage_between_frames(name):
    frames = (_vn_stream(10) if name == "vectornav" else _wit_stream(10))[0]
    junk = [b"", b"\x00\x01abc", b"\xff" * 17, b"#hello", b"\x10\x21"]  # no '$', no 0x55
    data = b"".join(f + junk[i % len(junk)] for i, f in enumerate(frames))
    n_junk = sum(len(junk[i % len(junk)]) for i in range(len(frames)))
    n_runs = sum(1 for i in range(len(frames)) if junk[i % len(junk)])
    dec = make_decoder(name)
    s = dec.feed(data + frames[0])
    ref = make_decoder(name).feed(b"".join(frames) + frames[0])
    np.testing.assert_array_equal(s.accel, ref.accel)
    assert dec.stats.garbage_bytes == n_junk and dec.stats.resyncs == n_runs
    # random noise with frame starts in it: every clean frame after it still decodes
    rng = np.random.default_rng(1)
    noisy = b"".join(f + rng.integers(0, 256, 40, dtype=np.uint8).tobytes() for f in frames)
    dec = make_decoder(name)
    s = dec.feed(noisy + frames[0])
    assert len(s) >= len(ref) - 1 and dec.stats.garbage_bytes >= 40 * (len(frames) - 1)


def test_vectornav_cut_sentence_and_other_sentences():
    good = encode_vnymr((1, 2, 3), (10, 20, 30), (0, 0, -9.8), (0, 0, 0))
    cut = good[:40]  # a sentence cut short by the next one's start
    dec = make_decoder("vectornav")
    s = dec.feed(cut + good + b"$VNRRG,5,115200*XX\r\n" + b"$VNYMR,1,2*00\r\n")
    assert len(s) == 1 and dec.stats.garbage_bytes == 40 and dec.stats.other == 1
    assert dec.stats.extra["unchecked"] == 1 and dec.stats.bad_checksum == 1
    long = b"$" + b"1" * 600  # a '$' that starts nothing: given up, then resynchronised
    s = dec.feed(long + good)
    assert len(s) == 1 and dec.stats.garbage_bytes >= 40 + 601


# -- signs -------------------------------------------------------------------------------------------------
def _vn_line(body: str) -> bytes:
    return f"${body}*{xor_checksum(body.encode()):02X}\r\n".encode()


# The VN-100 User Manual's (UM001 rev 2.22, §7.2.3) example response of register 27 (Yaw, Pitch, Roll, Magnetic,
# Acceleration and Angular Rates) — facts from the vendor's document: its checksum and its signs.
VN_MANUAL_27 = (
    "VNRRG,27,+006.380,+000.023,-001.953,+1.0640,-0.2531,+3.0614,+00.005,+00.344,-09.758,-0.001222,-0.000450,-0.001218"
)


def test_vectornav_manual_example():
    assert xor_checksum(VN_MANUAL_27.encode()) == 0x4F  # the manual's '*4F'
    assert xor_checksum(b"VNRRG,8,+006.271,+000.031,-002.000") == 0x66  # register 8's example, '*66'
    s = make_decoder("vectornav").feed(_vn_line(VN_MANUAL_27.replace("VNRRG,27", "VNYMR")))
    roll, pitch = np.degrees(accel_tilt(s.accel))
    # the unit's own roll (−1.953°, pitch 0.023°) is what imutool's FRD specific-force convention gives from the
    # accelerometer of the same sample (−2.02°, −0.03°): VectorNav's accel passes unchanged, signs and all
    assert s.attitude[0] == pytest.approx([-1.953, 0.023, 6.380])
    assert roll[0] == pytest.approx(-1.953, abs=0.1) and pitch[0] == pytest.approx(0.023, abs=0.1)
    assert s.accel[0, 2] == pytest.approx(-9.758) and s.mag[0] == pytest.approx([106.40, -25.31, 306.14])


def test_signs_vectornav_rest_and_nose_up():
    """As VectorNav sends them: at rest level accel ≈ (0, 0, −9.8); bow up 10°: accel_x = +g sin 10°."""
    rest = _vn_line("VNYMR,+010.000,+000.000,+000.000,+0.2000,+0.0100,+0.4000,+00.000,+00.000,-09.807,"
                    "+0.000000,+0.000000,+0.000000")  # fmt: skip
    s10, c10 = G * math.sin(math.radians(10)), G * math.cos(math.radians(10))
    up = _vn_line(f"VNIMU,+0.2000,+0.0100,+0.4000,{s10:+07.3f},+00.000,{-c10:+07.3f},+0.000000,+0.100000,"
                  "+0.000000,+25.0,+101.325")  # fmt: skip
    s = make_decoder("vectornav").feed(rest + up)
    roll, pitch = np.degrees(accel_tilt(s.accel))
    assert abs(roll[0]) < 0.01 and abs(pitch[0]) < 0.01
    assert pitch[1] == pytest.approx(10.0, abs=0.01) and abs(roll[1]) < 0.01
    assert s.accel[0, 2] < -9.8 and s.gyro[1, 1] > 0  # bow rising: + rate about starboard y
    assert s.mag[0] == pytest.approx([20.0, 1.0, 40.0])  # gauss → µT


def test_signs_witmotion_rest_and_nose_up():
    """As a WT901 sends them, lying flat (Z up, X to the bow): az = +1 g at rest; bow up 10°: ax = +g sin 10°
    on the module's X, az = +g cos 10°; a right-hand turn about its Y (port) puts the bow down."""
    one_g = 1.0 / 16 * 32768  # counts
    s10, c10 = math.sin(math.radians(10)), math.cos(math.radians(10))
    cyc = lambda ax, az, wy: packet(0x51, [ax * one_g, 0, az * one_g, 2500]) + packet(0x52, [0, wy, 0, 2500])  # noqa: E731
    dec = make_decoder("witmotion")
    s = dec.feed(cyc(0, 1, 0) + cyc(s10, c10, -100) + cyc(0, 1, 0))
    roll, pitch = np.degrees(accel_tilt(s.accel))
    assert s.accel[0] == pytest.approx([0, 0, -G], abs=1e-6)
    assert abs(roll[0]) < 0.01 and abs(pitch[0]) < 0.01
    assert pitch[1] == pytest.approx(10.0, abs=0.02) and abs(roll[1]) < 0.01
    assert s.gyro[1, 1] > 0  # bow rising = a left-hand turn about port-pointing Y = + about starboard y
    att = (
        make_decoder("witmotion")
        .feed(
            (
                packet(0x51, [0, 0, one_g, 0])
                + packet(0x52, [0, 0, 0, 0])
                + packet(0x53, [5 / 180 * 32768, -10 / 180 * 32768, 30 / 180 * 32768, 0])
            )
            * 2  # fmt: skip
        )
        .attitude
    )
    assert att[0] == pytest.approx([5.0, 10.0, -30.0], abs=0.01)  # roll kept, pitch and yaw reversed


# -- the live adapter ----------------------------------------------------------------------------------------
def test_live_adapter_times_and_registry():
    from imutool.live.sources import DECODERS

    assert {"vectornav", "witmotion", "bridge"} <= set(DECODERS)
    dec = DECODERS["vectornav"](clock="host", baud=115200)
    frames = _vn_stream(5)[0]
    data = b"".join(frames)
    blk = dec.feed(data, 100.0)
    per_byte = 10 / 115200
    expect = 100.0 - (len(data) - (np.cumsum([len(f) for f in frames]) - 1)) * per_byte
    np.testing.assert_allclose(blk.t, expect, atol=1e-9)
    blk2 = dec.feed(frames[0] + frames[1], 100.0)  # a late read cannot go back in time
    assert blk2.t[0] > blk.t[-1] and np.all(np.diff(blk2.t) > 0)
    assert set(blk.extra) == {"vendor_roll", "vendor_pitch", "vendor_yaw"} and blk.mag is not None
    assert dec.stats["frames"] == 7 and "resyncs" in dec.stats
    from formats.errors import ImutoolError

    with pytest.raises(ImutoolError, match="no device clock"):
        DECODERS["witmotion"](clock="sensor", baud=9600)


def test_live_adapter_keeps_the_period_through_a_backlog():
    """100 Hz frames read one at a time with arrival jitter, then a 0.5 s stall and its 50 frames read in two
    pieces: the times keep the device's period (not the bytes' time, not squeezed), jitter does not reach them,
    and a real pause of the device (10 s) starts again at the arrivals."""
    from imutool.live.sources import DECODERS

    dec = DECODERS["vectornav"](clock="host", baud=921600)
    frames = _vn_stream(400)[0]
    jitter = lambda k: 0.003 * ((k * 7) % 5) / 4  # noqa: E731  (0..3 ms of latency)
    t = [dec.feed(frames[k], 10.0 + k * 0.01 + jitter(k)).t[0] for k in range(200)]
    assert dec.period_s == pytest.approx(0.01, rel=5e-3)
    assert np.ptp(np.diff(t[150:])) < 0.5e-3  # the jitter (3 ms) is gone from the spacing
    a = dec.feed(b"".join(frames[200:225]), 10.0 + 249 * 0.01 + 0.001).t
    b = dec.feed(b"".join(frames[225:250]), 10.0 + 249 * 0.01 + 0.0012).t
    both = np.concatenate([[t[-1]], a, b])
    d = np.diff(both)
    assert np.median(d) == pytest.approx(0.01, rel=0.01) and d.min() > 0.008 and d.max() < 0.016  # not squeezed
    late = dec.feed(frames[250], 10.0 + 260.0 * 0.01 + 10.0).t  # the device paused 10 s
    assert late[0] == pytest.approx(10.0 + 260.0 * 0.01 + 10.0 - 10 / 921600, abs=1e-9)  # (its LF followed)


# -- capture serial through a pty ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(PROTOCOLS))
def test_capture_serial_vendor_protocol(tmp_path, name):
    pytest.importorskip("serial")
    from formats.csv import read_csv
    from imutool.capture.runtime import StopFlag
    from imutool.capture.serve import open_pty
    from imutool.capture.vendor import capture_vendor

    frames, rpy, mag, acc, gyr = _vn_stream(40) if name == "vectornav" else _wit_stream(40)
    master, slave, dev = open_pty()
    stop = StopFlag()

    def feed():
        time.sleep(0.5)
        for i, f in enumerate(frames):
            os.write(master, f + (b"\x00junk" if i == 7 else b""))
            time.sleep(0.005)
        end = time.monotonic() + 120  # (the first run compiles the CSV writer before it reads)
        while time.monotonic() < end and _data_rows(out) < len(frames):
            time.sleep(0.1)
        time.sleep(0.3)
        stop.stop = True

    out = tmp_path / "imu.csv"
    th = threading.Thread(target=feed, daemon=True)
    th.start()
    summary = capture_vendor(dev, 115200, str(out), name, status_s=None, quiet=True, stop=stop)
    th.join()
    os.close(master), os.close(slave)
    rec = read_csv(str(out))
    n = 40
    assert len(rec) == n and summary["decoder"]["garbage_bytes"] == 5
    np.testing.assert_allclose(rec["accel"], acc[:n], atol=ACCEL_PER_COUNT)
    assert np.all(np.diff(rec.time) > 0)
    text = out.read_text()
    assert "conventions:" in text and ("FLU" in text if name == "witmotion" else "FRD" in text)


def _data_rows(path) -> int:
    try:
        return sum(1 for ln in path.read_text().splitlines() if ln and ln[0].isdigit())
    except OSError:
        return 0


def test_capture_serial_cli_protocol_switch(tmp_path):
    """`imutool capture serial PTY --protocol witmotion --duration 2 --json`: the CLI reaches the decoder."""
    pytest.importorskip("serial")
    import json
    import subprocess
    import sys
    from pathlib import Path

    from imutool.capture.serve import open_pty

    master, slave, dev = open_pty()
    frames = _wit_stream(30)[0]
    done = threading.Event()

    def feed():  # (pyserial empties the input buffer when it opens the port: keep sending)
        k = 0
        while not done.is_set():
            os.write(master, frames[k % 30])
            k += 1
            time.sleep(0.02)

    threading.Thread(target=feed, daemon=True).start()
    root = Path(__file__).resolve().parent.parent
    r = subprocess.run(
        [sys.executable, "-c", "from imutool.cli import main; main()", "capture", "serial", dev, "--baud",
         "115200", "--protocol", "witmotion", "--duration", "2", "-o", str(tmp_path / "w.csv"), "--json"],
        capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(root)}, timeout=300,
    )  # fmt: skip
    done.set()
    time.sleep(0.1)
    os.close(master), os.close(slave)
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    d = summary["decoder"]
    assert summary["rows"] >= 20 and d["samples"] == summary["rows"] and d["bad_checksum"] == 0
    assert 4 * summary["rows"] <= d["frames"] <= 4 * summary["rows"] + 7  # (+ a cycle begun or not yet learned)
