"""`imutool live`: the small-block EKF equals `filter`, the hub, the roll statistics, status and outputs."""

from __future__ import annotations

import json
import socket
import threading
import time

import numpy as np
import pytest

import formats
from imutool.attitude import EkfParams, EkfStepper, mag_interval, nominal_dt, run_ekf
from imutool.filtering import run_filter
from imutool.live import LiveHub, LiveSnapshot, run_live
from imutool.live.outputs import TcpServerOutput
from imutool.live.rollstats import LiveRoll
from imutool.live.sentences import SentenceScheduler, parse_rates
from imutool.roll import roll_cycles
from imutool.sim import run_simulate

PARAMS = EkfParams(motion="ship")
LEVER = [0.0, 0.0, -2.0]


@pytest.fixture(scope="module")
def ship_csv(tmp_path_factory):
    """A 10-minute ship recording at 50 Hz (simulated, seeded)."""
    path = tmp_path_factory.mktemp("ship") / "ship.csv"
    run_simulate("ship-roll", path, seed=5, duration=600.0, rate_hz=50.0)
    return path


def _estimates(folder):
    files = sorted(folder.glob("estimate_*.csv"))
    assert files, "no estimate file recorded"
    return formats.read(files[0])


def test_stepper_in_any_blocks_equals_one_call(ship_csv):
    rec = formats.read(ship_csv)
    t, g, a, m = rec.time[:6000], rec["gyro"][:6000], rec["accel"][:6000], rec["mag"][:6000]
    whole, _ = run_ekf(t, g, a, m, PARAMS)
    # the intervals fixed up front (as the engine does from its start-up span)
    stepper = EkfStepper(PARAMS, dt_nominal=nominal_dt(t), dt_mag=mag_interval(t, m), heading_held=True)
    qs, rng, i = [], np.random.default_rng(1), 0
    while i < len(t):
        j = min(len(t), i + int(rng.integers(1, 40)))
        qs.append(stepper.step(t[i:j], g[i:j], a[i:j], m[i:j]).q)
        i = j
    assert np.array_equal(np.concatenate(qs), whole.q)  # bit for bit


def test_replay_equals_filter(ship_csv, tmp_path):
    """A replay's live output equals `filter` on the same file (roll/pitch/heading within 1e-6 deg)."""
    ref = run_filter(ship_csv, params=PARAMS, lever_arm=LEVER).recording
    res = run_live(
        replay=ship_csv, speed=0, record=tmp_path / "rec", motion="ship", lever_arm=LEVER, settle_s=20,
        sentences=["HRM"], log=lambda m: None, handle_signals=False, replay_block_s=0.37,
    )  # fmt: skip
    est = _estimates(tmp_path / "rec")
    assert res.summary["samples"] == len(ref) == len(est)
    assert np.array_equal(est.time, ref.time)
    for ch in ("roll", "pitch"):
        assert np.max(np.abs(est[ch] - ref[ch])) < 1e-6, ch
    dh = (est["heading"] - ref["heading"] + 180.0) % 360.0 - 180.0
    assert np.max(np.abs(dh)) < 1e-6
    assert res.summary["status"] == "A" and res.summary["settled"]


def test_duration_stops_on_input_time(ship_csv):
    lines: list[str] = []
    res = run_live(
        replay=ship_csv, speed=0, duration=100, motion="ship", settle_s=20, log=lines.append,
        handle_signals=False,
    )  # fmt: skip
    assert res.summary["stop_reason"].startswith("duration")
    assert 99.9 <= res.summary["input_span_s"] <= 100.0
    assert lines[-1].startswith("stopped (duration 100 s reached)")


def test_hub_drops_oldest_and_closes():
    hub = LiveHub()
    sub = hub.subscribe(maxsize=3)
    for i in range(10):
        hub.publish(_snap(float(i)))
    assert sub.dropped == 7
    assert [sub.get(0).t for _ in range(3)] == [7.0, 8.0, 9.0]
    assert hub.latest().t == 9.0
    assert [s.t for s in hub.history(5)] == [4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
    hub.request_reset("web")
    assert [w for w, _ in hub.take_resets()] == ["web"] and hub.take_resets() == []
    stopped = []
    hub.on_stop(lambda: stopped.append(1))
    got = []
    th = threading.Thread(target=lambda: got.append(sub.get(5.0)))
    th.start()
    hub.close("end of input")
    th.join(2.0)
    assert got == [None] and stopped == [1] and hub.closed
    json.dumps(_snap(1.0).as_dict())


def _snap(t: float, **kw) -> LiveSnapshot:
    base = dict(
        utc=1.8e9 + t, t=t, roll_deg=1.0, pitch_deg=0.5, heading_deg=10.0, heading_ref="magnetic", rot_deg_min=0.0,
        heave_m=None, roll_amp_port_deg=None, roll_amp_stbd_deg=None, roll_period_s=None, peak_port_deg=0.0,
        peak_stbd_deg=1.0, peak_reset_utc=None, status="A", cause="", settled=True,
    )  # fmt: skip
    base.update(kw)
    return LiveSnapshot(**base)


def test_live_roll_equals_roll_cycles_on_its_window_and_keeps_the_reset(tmp_path):
    t = np.arange(0, 300, 0.02)
    heel = 12 * np.sin(2 * np.pi * t / 9.0) + 3 * np.sin(2 * np.pi * t / 31.0)
    state = tmp_path / "peak.json"
    lr = LiveRoll(window_s=120.0, state_path=state)
    for i in range(0, len(t), 7):
        lr.add(t[i : i + 7], heel[i : i + 7])
    lr.refresh()
    lr.evaluate()
    w = t >= t[-1] - 120.0
    cyc = roll_cycles(t[w], heel[w])
    last_port = np.flatnonzero(cyc.side == -1)[-1]
    last_stbd = np.flatnonzero(cyc.side == 1)[-1]
    assert lr.amp_port == pytest.approx(cyc.amplitude_deg[last_port], abs=1e-9)
    assert lr.amp_stbd == pytest.approx(cyc.amplitude_deg[last_stbd], abs=1e-9)
    assert lr.period == pytest.approx(cyc.period_s[-1], abs=1e-9)
    assert lr.peak_stbd == pytest.approx(heel.max()) and lr.peak_port == pytest.approx(-heel.min())
    lr.reset(1_800_000_000.0)
    lr.add(t[:10] + 400, np.full(10, 2.0))
    lr.save()
    again = LiveRoll(state_path=state)  # a restart keeps the reset and the peak since it
    assert again.reset_iso == "2027-01-15T08:00:00Z"
    assert again.peak_stbd == 2.0 and again.peak_port == 0.0


def test_scheduler_rates_and_talker():
    rates = parse_rates("HRM,XDR", ["XDR=20"])
    assert rates == {"HRM": 1.0, "XDR": 20.0}
    sch = SentenceScheduler(rates, talker="HE")
    due = [sch.due(k * 0.01) for k in range(200)]
    assert sum("XDR" in d for d in due) == 40 and sum("HRM" in d for d in due) == 2
    line = sch.lines(_snap(0.0, status="V"), ["HRM", "XDR"]).decode()
    assert line.startswith("$HEHRM,1.0,") and ",V," in line and "$HEXDR,A,0.50,D,PTCH,A,1.00,D,ROLL" in line
    with pytest.raises(Exception, match="sentence"):
        parse_rates("HRM,FOO")


def test_tcp_client_that_stops_reading_does_not_stall_the_others():
    out = TcpServerOutput("tcp://127.0.0.1:0", "127.0.0.1", 0, client_timeout_s=1.0).start()
    stuck = socket.create_connection(("127.0.0.1", out.port))
    stuck.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    good = socket.create_connection(("127.0.0.1", out.port))
    time.sleep(0.2)
    got = bytearray()
    good.setblocking(False)

    def drain() -> None:
        try:
            while chunk := good.recv(1 << 16):
                got.extend(chunk)
        except BlockingIOError:
            pass

    line = b"$IIXDR," + b"0" * 60 + b"*00\r\n"
    for _ in range(2000):  # ~1.4 MB: far more than the stuck client's socket buffers
        for _ in range(10):
            out.send(line)  # never blocks
        time.sleep(0.001)
        drain()
    end = time.monotonic() + 3
    while time.monotonic() < end and got.count(b"\r\n") < out.sent:
        time.sleep(0.01)
        drain()
    out.close()
    s = out.stats()
    assert s["client_dropped"] > 0 or s["clients_closed_stuck"] == 1
    assert s["sent"] + s["dropped"] == 20000
    assert got.count(b"\r\n") >= 0.9 * s["sent"]  # the reading client got (nearly) all that was accepted
    stuck.close()
    good.close()


class _FakePort:
    """A serial port that hands out bridge frames of a steady 50 Hz MCU clock, a few per read."""

    def __init__(self, *a, **k) -> None:
        from imutool.capture.bridge import Frame, encode_text

        self.frames = [encode_text(Frame(i, i * 20_000, (0, 0, 16384, 0, 0, 0, 100, 0, 300, 0))) for i in range(400)]
        self.i = 0
        self.in_waiting = 0

    def read(self, n: int) -> bytes:
        chunk = b"".join(self.frames[self.i : self.i + 5])
        self.i += 5
        return chunk

    def close(self) -> None:
        pass


@pytest.mark.parametrize("clock", ["host", "sensor"])
def test_a_host_clock_jump_does_not_move_the_time_stamps(monkeypatch, clock):
    from imutool.live import sources

    imu = sources.SerialImu("fake", 115200, "bridge", opener=_FakePort, clock=clock)
    times = []
    real = time.time
    for k in range(60):
        if k == 30:  # the host's clock steps an hour ahead (NTP, an operator): monotonic time does not
            monkeypatch.setattr(time, "time", lambda: real() + 3600.0)
        blk = imu.read(0.01)
        if blk is not None:
            times.append(blk.t)
    t = np.concatenate(times)
    assert len(t) == 300
    assert np.all(np.diff(t) > 0) and np.max(np.diff(t)) < 1.0
    if clock == "sensor":
        assert np.allclose(np.diff(t), 0.02, atol=1e-6)


def test_config_file_runs_the_service_and_refuses_unknown_keys(ship_csv, tmp_path, capsys):
    from formats.errors import ImutoolError
    from imutool.cli import main
    from imutool.live.config import read_config

    cfg = tmp_path / "live.toml"
    cfg.write_text(
        f'[source]\nreplay = "{ship_csv}"\nspeed = 0\n[filter]\nmotion = "ship"\nsettle_s = 10\n'
        f'lever_arm = [0.0, 0.0, -2.0]\n[output]\nsentences = ["HRM", "XDR"]\nrates = {{ XDR = 5 }}\n'
        f'talker = "HE"\n[record]\nrecord = "{tmp_path / "rec"}"\n'
    )
    with pytest.raises(SystemExit) as e:
        main(["live", "--config", str(cfg), "--duration", "30", "--json"])
    assert e.value.code in (0, None)
    s = json.loads(capsys.readouterr().out)
    assert s["sentences"] == {"HRM": 30, "XDR": 150}  # the file's rates, the command line's duration
    assert s["stop_reason"] == "duration 30 s reached" and s["recording"]["rows"] == 1500
    bad = tmp_path / "bad.toml"
    bad.write_text("[output]\nsentence = ['HRM']\n")
    with pytest.raises(ImutoolError, match="unknown key 'sentence'"):
        read_config(str(bad))


def test_hub_consumers_see_snapshots_and_reset_the_peak_hold(ship_csv, tmp_path):
    """`run_live(consumers=[start])`: a reader started with the engine gets snapshots (status, cause, roll), asks
    for a peak-hold reset through the hub (performed, logged and kept), is stopped at the end."""
    seen: list[LiveSnapshot] = []
    handles = []

    class Handle:
        def __init__(self, hub: LiveHub) -> None:
            self.sub, self.stopped, self.hub = hub.subscribe(10_000), False, hub
            self.th = threading.Thread(target=self.run, daemon=True)
            self.th.start()

        def run(self) -> None:
            while (s := self.sub.get(5.0)) is not None:
                seen.append(s)
                if s.t >= 200.0 and not any(x.peak_reset_utc for x in seen):
                    self.hub.request_reset("bridge display")

        def stop(self) -> None:
            self.stopped = True

    def start(hub: LiveHub) -> Handle:
        handles.append(Handle(hub))
        return handles[-1]

    logs: list[str] = []
    res = run_live(
        replay=ship_csv, speed=0, duration=300, motion="ship", settle_s=20, consumers=[start], log=logs.append,
        handle_signals=False, record=tmp_path / "rec", replay_block_s=0.05,
    )  # fmt: skip
    handles[0].th.join(5.0)
    assert handles[0].stopped and handles[0].hub.closed
    assert seen[0].status == "V" and "settling" in seen[0].cause and seen[-1].status == "A"
    assert 2900 <= len(seen) + handles[0].sub.dropped <= 3001  # 10 a second of input
    assert res.summary["peak_hold_resets"] and any("peak-hold reset by bridge display" in m for m in logs)
    after = [s for s in seen if s.peak_reset_utc]
    assert after and after[0].t >= 200.0 and after[-1].peak_reset_utc == res.summary["peak_hold_resets"][0]
    est = _estimates(tmp_path / "rec")
    since = est["roll"][est.time >= after[0].t - 1.0]  # (the reset fell within the block before this snapshot)
    assert after[-1].peak_stbd_deg <= since.max() + 1e-9 and after[-1].peak_port_deg <= -since.min() + 1e-9
    assert after[-1].peak_stbd_deg >= est["roll"][est.time >= after[0].t].max() - 1e-9


def test_i2c_source_polls_the_capture_drivers():
    from imutool.capture.fake_i2c import FakeHMC5883L, FakeMPU6050, FakeSMBus
    from imutool.live.sources import i2c_source

    bus = FakeSMBus({0x68: FakeMPU6050(accel_counts=(0, 0, 16384)), 0x1E: FakeHMC5883L(counts_xyz=(100, 0, 300))})
    src = i2c_source("fake", rate_hz=200.0, mag="hmc5883l", bus_obj=bus)
    blocks = [b for b in (src.read(0.05) for _ in range(20)) if b is not None]
    assert len(blocks) >= 10 and all(len(b) == 1 for b in blocks)
    t = np.concatenate([b.t for b in blocks])
    assert np.all(np.diff(t) > 0)
    assert abs(np.linalg.norm(blocks[0].accel[0]) - 9.80665) < 0.01 and np.linalg.norm(blocks[0].mag[0]) > 0
    assert src.stats["frames"] == len(blocks) and src.stats["read_errors"] == 0


def test_saturation_gives_v_with_its_cause_and_a_after(ship_csv, tmp_path):
    rec = formats.read(ship_csv).select(slice(0, 6000))  # 120 s
    acc = np.array(rec["accel"])
    acc[4000:4010, 2] = -16.0  # the accelerometer held at a range limit beyond 1.5 g for 10 samples (t = 80 s)
    rec.channels["accel"] = acc
    path = tmp_path / "clipped.csv"
    formats.write(rec, path)
    hub = LiveHub()
    sub = hub.subscribe(100_000)
    logs: list[str] = []
    res = run_live(replay=path, speed=0, motion="ship", settle_s=20, hub=hub, log=logs.append, handle_signals=False)
    snaps = []
    while (s := sub.get(0)) is not None:
        snaps.append(s)
    sat = [s for s in snaps if "input saturated" in s.cause]
    assert sat and all(s.status == "V" for s in sat)
    assert 79.9 <= sat[0].t <= 80.3 and sat[-1].t <= 80.2 + 2.0 + 0.2  # held for HOLD_S after the last one
    assert [s.status for s in snaps if 60 < s.t < 79.9] == ["A"] * len([s for s in snaps if 60 < s.t < 79.9])
    assert snaps[-1].status == "A" and res.summary["saturated_samples"] == 10
    assert any("status V: input saturated" in m for m in logs)


def test_aux_port_gives_gnss_velocity_and_gyrocompass_heading():
    pytest.importorskip("serial", reason="the second port needs pyserial")
    import os

    from formats.nmea.framing import checksum
    from imutool.capture.serve import open_pty
    from imutool.live.sources import AuxNmea

    master, slave, name = open_pty()
    aux = AuxNmea(name, 4800, max_age_s=0.5)
    for body in ("GPRMC,120000.00,A,5400.0,N,01000.0,E,10.0,90.0,061226,,,A", "HEHDT,87.5,T", "garbage"):
        os.write(master, f"${body}*{checksum(body)}\r\n".encode())
    deadline = time.monotonic() + 5
    while len(aux.values) < 3 and time.monotonic() < deadline:
        aux.poll()
    now = time.monotonic()
    got = aux.latest(now)
    assert got["sog"] == pytest.approx(10.0 * 1852 / 3600) and got["cog"] == 90.0
    assert got["heading_true"] == 87.5 and aux.stats["sentences"] == 2 and aux.stats["bad"] == 1
    assert aux.latest(now + 1.0) == {}  # too old: not used
    aux.close()
    os.close(master)
    os.close(slave)


def test_a_blocked_serial_output_drops_and_never_blocks():
    import os

    from imutool.capture.serve import open_pty
    from imutool.live.outputs import open_output

    master, slave, name = open_pty()  # nobody reads the master: the line fills and the writer blocks
    out = open_output(f"serial://{name}?baud=4800")
    line = b"$IIHRM," + b"1" * 60 + b"*00\r\n"
    for _ in range(20_000):  # 1.4 MB: far beyond the terminal's buffer
        out.send(line)
    s = out.stats()
    assert s["dropped"] > 0 and 20_000 - 1 <= s["sent"] + s["dropped"] + len(out.q) <= 20_000  # (one in its write)
    os.close(master)  # the writer's blocked write fails now; close does not hang
    out.close(timeout=1.0)
    os.close(slave)
