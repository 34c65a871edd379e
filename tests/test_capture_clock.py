"""One time per captured frame: MCU clock → UTC for bridge frames, baud-rate spread for NMEA lines."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

import formats
from imutool.capture.clock import FrameClock, spread_by_baud, strictly_increasing


def _feed(clock, t_send, mcu_us, seq, rng, t0=1.75e9, latency=(0.001, 0.005)):
    """Batches as a serial read delivers them: everything sent by the read time, one arrival stamp."""
    out, i, now = [], 0, 0.0
    while i < len(t_send):
        now += rng.uniform(0.01, 0.02)
        j = int(np.searchsorted(t_send, now, side="right"))
        if j > i:
            out.append(clock.map(mcu_us[i:j], seq[i:j], t0 + now + rng.uniform(*latency)))
            i = j
    return np.concatenate(out)


@pytest.mark.slow
def test_mcu_clock_with_drift_and_wrap_is_mapped_to_utc_per_frame():
    rng = np.random.default_rng(1)
    t_send = np.arange(200 * 300) / 200.0  # 5 min at 200 Hz
    mcu_us = ((t_send * (1 - 80e-6) + 4290.0) * 1e6).astype(np.int64) % (1 << 32)  # wraps after ~5 s
    seq = np.arange(len(t_send)) % 65536
    clock = FrameClock()
    t = _feed(clock, t_send, mcu_us, seq, rng)
    assert len(t) == len(t_send) and np.all(np.diff(t) > 0)  # one distinct time per frame
    err = t - (1.75e9 + t_send)
    # within the read latency (1–5 ms); before the drift is fitted (a few windows) up to ~1 ms early
    assert np.all(err > -1e-3) and np.all(err < 0.006) and np.all(err[len(err) // 2 :] >= 0)
    assert np.std(np.diff(t) - 0.005) < 2e-4  # the MCU's steady spacing, not the read bursts
    assert abs(clock.as_meta()["drift_ppm"] - 80) < 10


def test_mcu_restart_starts_a_new_segment_and_times_keep_increasing():
    rng = np.random.default_rng(2)
    t_send = np.arange(200 * 20) / 200.0
    mcu = (t_send * 1e6).astype(np.int64)
    mcu[2000:] -= mcu[2000]  # the MCU rebooted: its clock starts again at 0
    clock = FrameClock()
    t = _feed(clock, t_send, mcu, np.arange(len(t_send)), rng)
    assert np.all(np.diff(t) > 0) and clock.segments == 2
    assert np.max(np.abs(t - (1.75e9 + t_send))) < 0.03


def test_bridge_without_a_clock_falls_back_to_sequence_numbers():
    rng = np.random.default_rng(3)
    t_send = np.arange(100 * 30) / 100.0
    clock = FrameClock()
    t = _feed(clock, t_send, np.zeros(len(t_send), np.int64), np.arange(len(t_send)) % 65536, rng)
    assert clock.source == "seq" and np.all(np.diff(t) > 0)
    assert abs(np.median(np.diff(t[1000:])) - 0.01) < 5e-4


def test_nmea_lines_of_one_read_are_spread_by_the_baud_rate():
    t = spread_by_baud(100.0, [40, 40, 40], 10, 4800)
    assert np.allclose(t, 100.0 - np.array([92, 51, 10]) * 10 / 4800)
    assert np.all(np.diff(t) > 0)
    t2 = spread_by_baud(100.0, [40], 0, 4800, last=100.0)  # never before the previous read's last line
    assert t2[0] > 100.0
    assert np.all(np.diff(strictly_increasing(np.array([3.0, 3.0, 2.0, 5.0]), 2.5)) > 0)


@pytest.mark.slow
def test_capture_from_simulate_serve_then_info_keeps_every_frame(tmp_path):
    """`imutool simulate --serve` into a pseudo-terminal, `imutool capture serial`, `imutool info`: rows in = out."""
    link = str(tmp_path / "port")
    out = tmp_path / "deck.csv"
    log = tmp_path / "sent.json"
    cli = [sys.executable, "-c", "from imutool.cli import main; main()"]
    env = dict(os.environ)
    server = subprocess.Popen(
        cli
        + [
            "simulate",
            "--serve",
            link,
            "--protocol",
            "bridge",
            "--rate",
            "200",
            "--duration",
            "4",
            "--serve-log",
            str(log),
            "--start-delay",
            "0.5",
            "--start-when",
            str(out.with_suffix(".events.jsonl")),
            "-q",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        deadline = time.monotonic() + 30
        while not os.path.lexists(link) and time.monotonic() < deadline:
            time.sleep(0.05)
        cap = subprocess.run(
            cli
            + [
                "capture",
                "serial",
                link,
                "--baud",
                "115200",
                "--protocol",
                "bridge",
                "-o",
                str(out),
                "--duration",
                "9s",
                "--status",
                "0",
                "--json",
            ],
            capture_output=True,
            text=True,
            timeout=60,
            env=env,
        )
        assert cap.returncode == 0, cap.stderr
        server.wait(timeout=30)
    finally:
        if server.poll() is None:
            server.kill()
    sent = json.loads(log.read_text())
    summary = json.loads(cap.stdout)
    assert summary["dropped"] == 0 and summary["errors"] == 0
    info = subprocess.run(cli + ["info", str(out), "--json"], capture_output=True, text=True, timeout=60)
    assert info.returncode == 0, info.stderr
    assert json.loads(info.stdout)["rows"] == sent["sent"] == summary["rows"]  # rows in = rows out
    rec = formats.read(out)
    assert len(np.unique(rec.time)) == len(rec) == sent["sent"] and np.all(np.diff(rec.time) > 0)
    assert np.median(np.diff(rec.time)) == pytest_approx(0.005, 5e-4)
    # and no later command drops anything
    filt = subprocess.run(
        cli + ["filter", str(out), "-o", str(tmp_path / "est.csv"), "--json"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert filt.returncode == 0, filt.stderr
    v = json.loads(filt.stdout)["validation"][0]
    assert v["rows_dropped"] == 0 and v["rows_kept"] == sent["sent"]


def pytest_approx(x, tol):
    import pytest

    return pytest.approx(x, abs=tol)
