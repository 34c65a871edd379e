"""`imutool live` end to end: a ship recording fed as bridge frames into a pseudo-terminal, the sentences read from
another pseudo-terminal and a UDP socket on 127.0.0.1; and the faults (unplug, garbage, SIGKILL, full disk).

Each test runs `imutool live` in a subprocess (its own signals, its own ports), with this tree on PYTHONPATH.
"""

from __future__ import annotations

import json
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import formats
from formats.nmea.framing import parse_sentence
from formats.nmea.motion import parse_tss1
from imutool.attitude import EkfParams
from imutool.capture.bridge import Frame, Scales, encode_text
from imutool.capture.serve import open_pty
from imutool.filtering import run_filter
from imutool.roll import roll_cycles
from imutool.sim import run_simulate

ROOT = Path(__file__).resolve().parent.parent
LEVER = "0,0,-2"
pytest.importorskip("serial", reason="the live serial source needs pyserial")


@pytest.fixture(scope="module")
def ship(tmp_path_factory):
    path = tmp_path_factory.mktemp("ship") / "ship.csv"
    run_simulate("ship-roll", path, seed=7, duration=600.0, rate_hz=50.0)
    return formats.read(path)


def frames_of(rec, t_offset_us: int = 0, seq0: int = 0) -> list[bytes]:
    """The recording as bridge text frames (MPU6050/HMC5883L counts, MCU clock in µs)."""
    sc = Scales()
    acc = np.clip(np.round(rec["accel"] / sc.accel), -32768, 32767).astype(int)
    gyr = np.clip(np.round(rec["gyro"] / sc.gyro), -32768, 32767).astype(int)
    mag = np.clip(np.round(rec["mag"] / sc.mag_ut), -32768, 32767).astype(int)
    t_us = np.round((rec.time - rec.time[0]) * 1e6).astype(np.int64) + t_offset_us
    return [
        encode_text(Frame((seq0 + i) & 0xFFFF, int(t_us[i]) & 0xFFFFFFFF, (*acc[i], *gyr[i], *mag[i], 0)))
        for i in range(len(rec))
    ]


class Feeder(threading.Thread):
    """Writes frames into a pty master at ``speed`` × their own rate (50 Hz frames)."""

    def __init__(self, master: int, frames: list[bytes], speed: float, rate_hz: float = 50.0, garbage=None):
        super().__init__(daemon=True)
        self.master, self.frames, self.speed, self.rate = master, frames, speed, rate_hz
        self.garbage = garbage
        self.stop = False
        self.sent = 0

    def run(self) -> None:
        t0 = time.monotonic()
        batch = max(1, int(self.speed * self.rate / 100))  # ~100 writes a second
        for i in range(0, len(self.frames), batch):
            if self.stop:
                return
            data = b"".join(self.frames[i : i + batch])
            if self.garbage is not None:
                data = self.garbage(i, data)
            try:
                os.write(self.master, data)
            except OSError:
                return
            self.sent = i + batch
            due = t0 + (i + batch) / (self.rate * self.speed)
            if due > time.monotonic():
                time.sleep(due - time.monotonic())


class Reader(threading.Thread):
    """Collects what arrives on a pty master or a UDP socket."""

    def __init__(self, fd: int | None = None, sock: socket.socket | None = None):
        super().__init__(daemon=True)
        self.fd, self.sock, self.data, self.stop = fd, sock, bytearray(), False
        self.arrivals: list[tuple[float, bytes]] = []

    def run(self) -> None:
        src = self.sock if self.sock is not None else self.fd
        while not self.stop:
            r, _, _ = select.select([src], [], [], 0.1)
            if not r:
                continue
            try:
                chunk = self.sock.recv(65536) if self.sock is not None else os.read(self.fd, 65536)
            except OSError:
                return
            self.data += chunk
            self.arrivals.append((time.monotonic(), chunk))

    def lines(self) -> list[str]:
        return [ln for ln in self.data.decode("ascii", "replace").split("\r\n") if ln]


def live(args: list[str], **kw) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    code = "import sys; from imutool.cli import main; sys.exit(main())"
    return subprocess.Popen(
        [sys.executable, "-c", code, "live", *args], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, **kw,
    )  # fmt: skip


def wait_ready(proc: subprocess.Popen, timeout: float = 300.0) -> list[str]:
    """Read stderr until the engine says it is reading (the kernels are compiled then)."""
    lines = []
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        line = proc.stderr.readline()
        if not line:
            break
        lines.append(line)
        if "reading " in line:
            return lines
    raise AssertionError("imutool live did not start: " + "".join(lines))


def checked(lines: list[str]) -> dict[str, list]:
    """Every line's checksum and fields parse (pynmea2 where it knows the sentence); by type."""
    import pynmea2

    out: dict[str, list] = {}
    for ln in lines:
        if ln.startswith(":"):
            out.setdefault("TSS1", []).append(parse_tss1(ln))
            continue
        s = parse_sentence(ln, checksum_policy="require")
        key = s.type
        if key in ("XDR", "ROT", "HDT", "THS", "HDG"):
            pynmea2.parse(ln, check=True)
        out.setdefault(key, []).append(s)
    return out


def _f(x: str) -> float:
    return float(x) if x else float("nan")


def pashr_times(sentences, t_first: float) -> np.ndarray:
    """Input times (s) of PASHR sentences from their UTC time of day (unwrapped across midnight)."""
    tod = np.array([int(s.fields[0][:2]) * 3600 + int(s.fields[0][2:4]) * 60 + float(s.fields[0][4:])
                    for s in sentences])  # fmt: skip
    tod = np.unwrap(tod, period=86400.0)
    day0 = np.floor(t_first / 86400.0) * 86400.0
    t = day0 + tod
    return t + 86400.0 * np.round((t_first - t[0]) / 86400.0)


def test_acceptance_replay_through_ptys(ship, tmp_path):
    """10 minutes of ship motion through a pty into `imutool live`; sentences out on a pty and UDP; heel, roll
    amplitude/period, peak-hold and its reset checked against `filter` and `imutool roll` on the same samples."""
    m_in, s_in, name_in = open_pty()
    m_out, s_out, name_out = open_pty()
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    rd_pty, rd_udp = Reader(fd=m_out), Reader(sock=udp)
    rd_pty.start(), rd_udp.start()
    rec_dir = tmp_path / "rec"
    proc = live([
        name_in, "--protocol", "bridge", "--clock", "sensor", "--baud", "115200",
        "--out", f"serial://{name_out}?baud=115200", "--out", f"udp://127.0.0.1:{udp.getsockname()[1]}",
        "--sentences", "HRM,XDR,PASHR,TSS1,ROT", "--rate", "PASHR=10", "--rate", "XDR=10",
        "--record", str(rec_dir), "--motion", "ship", "--lever-arm", LEVER, "--settle", "30", "--json",
    ])  # fmt: skip
    wait_ready(proc)
    feeder = Feeder(m_in, frames_of(ship), speed=20.0)
    feeder.start()
    time.sleep(20.0)  # ~400 s of input: reset the peak-hold
    proc.send_signal(signal.SIGUSR1)
    feeder.join(120)
    time.sleep(1.5)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    rd_pty.stop = rd_udp.stop = True
    assert proc.returncode == 0, err
    summary = json.loads(out)
    assert summary["stop_reason"] == "SIGTERM"
    assert err.strip().splitlines()[-1].split(" imutool live: ")[1].startswith("stopped (SIGTERM)")
    assert summary["samples"] == len(ship)
    (tmp_path / "out_pty.nmea").write_bytes(bytes(rd_pty.data))  # kept for a failure's inspection
    by = checked(rd_pty.lines())
    by_udp = checked(rd_udp.lines())
    assert set(by) == {"HRM", "XDR", "PASHR", "TSS1", "ROT"} and set(by_udp) == set(by)
    assert len(by_udp["XDR"]) == len(by["XDR"]) == summary["sentences"]["XDR"]

    # heel against `filter` on the samples live received (its own raw recording)
    raw = next(rec_dir.glob("raw_*.csv"))
    params = EkfParams(motion="ship")
    ref = run_filter(raw, params=params, lever_arm=[0.0, 0.0, -2.0]).recording
    t_p = pashr_times(by["PASHR"], float(ref.time[0]))
    before = t_p < ref.time[0] - 1e-3  # V sentences while no sample had come yet (on the host's clock)
    assert all(s.fields[3] == "" and s.fields[10] == "0" for s, b in zip(by["PASHR"], before, strict=True) if b)
    after = t_p > ref.time[-1] + 1e-3  # after the input stopped: V sentences on, the last values held
    during = ~before & ~after
    assert during[before.sum() : before.sum() + during.sum()].all() and after[-1]
    by["PASHR"], t_p = [s for s, d in zip(by["PASHR"], during, strict=True) if d], t_p[during]
    i = np.searchsorted(ref.time, t_p - 5e-4)
    assert np.all(np.abs(ref.time[i] - t_p) < 1e-3)  # each PASHR carries a sample's time
    roll_p = np.array([_f(s.fields[3]) for s in by["PASHR"]])
    ok = np.isfinite(roll_p)
    assert ok.sum() > 0.9 * len(roll_p)
    assert np.max(np.abs(roll_p[ok] - ref["roll"][i][ok])) <= 0.0051  # 2 decimals: within 0.01 deg
    pitch_p = np.array([_f(s.fields[4]) for s in by["PASHR"]])
    assert np.nanmax(np.abs(pitch_p - ref["pitch"][i])) <= 0.0051

    # HRM: the same row as a PASHR (both on the grid of the first sample): its time is that PASHR's
    lines = rd_pty.lines()
    hrm_t, hrm = [], []
    for k, ln in enumerate(lines):
        if ln.startswith("$IIHRM"):
            nxt = next(x for x in lines[k + 1 :] if x.startswith("$PASHR"))
            hrm_t.append(pashr_times([parse_sentence(nxt)], float(ref.time[0]))[0])
            hrm.append(parse_sentence(ln).fields)
    hrm_t = np.array(hrm_t)
    assert {f[4] for f, t in zip(hrm, hrm_t, strict=True) if t > ref.time[-1] + 1.0} == {"V"}  # samples stopped
    hrm = [f for f, t in zip(hrm, hrm_t, strict=True) if t <= ref.time[-1] + 1e-3]
    hrm_t = hrm_t[hrm_t <= ref.time[-1] + 1e-3]
    status = [f[4] for f in hrm]
    assert status[0] == "V" and status[-1] == "A"
    first_a = status.index("A")
    assert 29.9 <= hrm_t[first_a] - ref.time[0] <= 40.0  # V while settling (30 s), then A
    assert all(s == "A" for s in status[first_a:])
    heel = np.array([_f(f[0]) for f in hrm])
    j = np.searchsorted(ref.time, hrm_t - 5e-4)
    assert np.nanmax(np.abs(heel[first_a:] - ref["roll"][j][first_a:])) <= 0.051
    # amplitude and period = `imutool roll` (roll_cycles) on the same trailing 120 s window, to HRM's 0.1
    checked_rows = 0
    for k in range(len(hrm)):
        if hrm_t[k] - ref.time[0] < 150:
            continue
        w = (ref.time >= hrm_t[k] - 120.0) & (ref.time <= hrm_t[k] + 1e-6)
        cyc = roll_cycles(ref.time[w], ref["roll"][w])
        port, stbd = np.flatnonzero(cyc.side == -1), np.flatnonzero(cyc.side == 1)
        assert _f(hrm[k][2]) == pytest.approx(cyc.amplitude_deg[port[-1]], abs=0.051)
        assert _f(hrm[k][3]) == pytest.approx(cyc.amplitude_deg[stbd[-1]], abs=0.051)
        assert _f(hrm[k][1]) == pytest.approx(cyc.period_s[-1], abs=0.051)
        checked_rows += 1
    assert checked_rows > 300
    # peak-hold: since the start, then since the reset (HRM notes: largest port/stbd heel since the reset)
    reset_fields = [f[7] for f in hrm]
    k_reset = next(k for k, r in enumerate(reset_fields) if r)
    assert 300 < hrm_t[k_reset] - ref.time[0] < 500
    for k in (k_reset - 1, len(hrm) - 1):
        since = ref.time[0] if k < k_reset else hrm_t[k_reset] - 1.0
        w = (ref.time >= since) & (ref.time <= hrm_t[k] + 1e-6)
        assert _f(hrm[k][6]) <= ref["roll"][w].max() + 0.051
        assert _f(hrm[k][5]) <= -ref["roll"][w].min() + 0.051
    w = (ref.time >= hrm_t[k_reset]) & (ref.time <= hrm_t[-1] + 1e-6)
    assert _f(hrm[-1][6]) >= ref["roll"][w].max() - 0.051
    assert len({r for r in reset_fields[k_reset:]}) == 1  # one reset, kept
    state = json.loads((rec_dir / "peak_hold.json").read_text())
    hhmmss = state["reset_utc"][11:19].replace(":", "")
    assert reset_fields[-1] == hhmmss and hrm[-1][8] == state["reset_utc"][8:10]
    assert summary["peak_hold_resets"] == [state["reset_utc"]]
    # TSS1 and ROT parse and carry the status: settled 'U'... only once heave is settled, else 'u'
    assert {t["status"] for t in by["TSS1"]} <= {"U", "u"}
    for fd in (m_in, s_in, m_out, s_out):
        os.close(fd)


def test_unplug_replug_garbage_and_sigkill(ship, tmp_path):
    """A sensor unplugged (its pty closed) → V within ~1 s; replugged (a new pty at the same path) → reopened and
    A again; garbage and corrupted frames counted and skipped; SIGKILL loses no completed recorded row."""
    link = tmp_path / "imu"
    m_in, s_in, name_in = open_pty()
    link.symlink_to(name_in)
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    rd = Reader(sock=udp)
    rd.start()
    rec_dir = tmp_path / "rec"
    proc = live([
        str(link), "--clock", "sensor", "--out", f"udp://127.0.0.1:{udp.getsockname()[1]}",
        "--sentences", "HRM", "--rate", "HRM=5", "--record", str(rec_dir), "--motion", "ship", "--settle", "5",
    ])  # fmt: skip
    wait_ready(proc)
    frames = frames_of(ship)
    rng = np.random.default_rng(3)

    def garbage(i: int, data: bytes) -> bytes:  # every ~50th write: noise bytes and a frame with a flipped bit
        if i % 50 == 0:
            bad = bytearray(data)
            bad[len(bad) // 2] ^= 0x04
            return bytes(rng.integers(0, 256, 40, dtype=np.uint8)) + bytes(bad)
        return data

    f1 = Feeder(m_in, frames[:2000], speed=1.0, garbage=garbage)  # 40 s (settled after ~25 s)
    f1.start()
    f1.join(60)
    t_unplug = time.monotonic()
    os.close(m_in)
    os.close(s_in)
    link.unlink()
    time.sleep(3.0)
    m2, s2, name2 = open_pty()
    link.symlink_to(name2)
    f2 = Feeder(m2, frames_of(ship.select(slice(2000, 2750)), t_offset_us=40_000_000, seq0=2000), speed=1.0)
    f2.start()
    f2.join(60)
    proc.send_signal(signal.SIGKILL)
    _, err = proc.communicate(timeout=30)
    rd.stop = True
    hrm = [(t, ln) for t, chunk in rd.arrivals for ln in chunk.decode().split("\r\n") if ln.startswith("$IIHRM")]
    status = [(t, parse_sentence(ln).fields[4]) for t, ln in hrm]
    before = [s for t, s in status if t < t_unplug]
    assert before[-1] == "A", err
    first_v = next(t for t, s in status if t > t_unplug and s == "V")
    assert first_v - t_unplug < 1.6  # V within 1 s (+ one HRM interval of 0.2 s and the port's read timeout)
    after = [s for t, s in status if t > t_unplug + 4.0]
    assert after and after[-1] == "A"  # reopened, samples again, the filter within bounds
    # the recording after SIGKILL: every row complete, times increasing, raw and estimates row for row
    raw = formats.read(next(rec_dir.glob("raw_*.csv")))
    est = formats.read(next(rec_dir.glob("estimate_*.csv")))
    n = min(len(raw), len(est))
    assert n > 2500
    assert np.all(np.diff(raw.time) > 0) and np.array_equal(raw.time[:n], est.time[:n])
    assert np.isfinite(est["roll"][:n]).all() and np.isfinite(raw["gyro"][:n]).all()
    for p in list(rec_dir.glob("*.csv")):
        text = p.read_bytes()
        body = text[: text.rfind(b"\n") + 1].decode().splitlines()
        cols = next(ln for ln in body if ln.startswith("time,")).count(",")
        assert all(ln.count(",") == cols for ln in body if ln and not ln.startswith("#"))
    events = [json.loads(x) for x in (rec_dir / "live_events.jsonl").read_text().splitlines()]
    assert events[0]["event"] == "started"
    os.close(m2)
    os.close(s2)


def test_garbage_counted_in_summary(ship, tmp_path):
    m_in, s_in, name_in = open_pty()
    proc = live([name_in, "--clock", "sensor", "--motion", "ship", "--settle", "2", "--json", "--duration", "40"])
    wait_ready(proc)

    def garbage(i: int, data: bytes) -> bytes:
        if i % 20 == 0:
            bad = bytearray(data)
            bad[10] ^= 0x01
            return b"\x00\xff garbage \xfe" + bytes(bad)
        return data

    feeder = Feeder(m_in, frames_of(ship.select(slice(0, 2400))), speed=10.0, garbage=garbage)
    feeder.start()
    out, err = proc.communicate(timeout=120)
    feeder.stop = True  # it has frames beyond --duration: stopped before its pty's descriptor is closed (and reused
    feeder.join(10)  # by the next test's file, which it would fill with garbage)
    s = json.loads(out)
    assert s["stop_reason"].startswith("duration")
    st = s["source_stats"]
    assert st["garbage_bytes"] > 0 and st["bad_checksum"] + st["malformed"] > 0
    assert s["status"] == "A"
    os.close(m_in)
    os.close(s_in)


def test_full_disk_stops_the_recording_not_the_outputs(ship, tmp_path):
    mnt = tmp_path / "small"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(mnt)], capture_output=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here: {r.stderr.decode().strip()}")
    try:
        path = tmp_path / "ship.csv"
        formats.write(ship.select(slice(0, 15000)), path)
        udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        udp.bind(("127.0.0.1", 0))
        rd = Reader(sock=udp)
        rd.start()
        proc = live([
            "--replay", str(path), "--speed", "30", "--record", str(mnt / "rec"), "--motion", "ship",
            "--settle", "5", "--out", f"udp://127.0.0.1:{udp.getsockname()[1]}", "--sentences", "XDR", "--json",
        ])  # fmt: skip
        out, err = proc.communicate(timeout=300)
        rd.stop = True
        assert proc.returncode == 0, err
        s = json.loads(out)
        assert s["recording"]["stopped"] and "disk full" in s["recording"]["stopped"]
        assert "recording stopped: " in err and "(the outputs go on)" in err
        assert 2995 <= s["sentences"]["XDR"] <= 3001  # 300 s at 10 Hz: every sentence went out
        time.sleep(0.5)
        assert len(rd.lines()) >= 2900  # and arrived (a replay paced at 30x: the UDP reader keeps up)
    finally:
        subprocess.run(["umount", str(mnt)], capture_output=True)


def test_v_is_sent_while_no_sensor_has_spoken_yet(tmp_path):
    m_in, s_in, name_in = open_pty()
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    rd = Reader(sock=udp)
    rd.start()
    proc = live([name_in, "--out", f"udp://127.0.0.1:{udp.getsockname()[1]}", "--sentences", "HRM", "--rate",
                 "HRM=2", "--motion", "ship"])  # fmt: skip
    wait_ready(proc)
    time.sleep(4.0)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    rd.stop = True
    hrm = [parse_sentence(ln) for ln in rd.lines()]
    assert len(hrm) >= 4 and {s.fields[4] for s in hrm} == {"V"} and all(s.fields[0] == "" for s in hrm)
    assert "no samples for" in err and err.strip().splitlines()[-1].split(" imutool live: ")[1].startswith(
        "stopped (SIGINT): 0 samples"
    )
    os.close(m_in)
    os.close(s_in)
