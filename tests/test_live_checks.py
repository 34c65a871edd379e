"""`imutool live`: the windowed self-checks of the status (imutool/live/checks.py), each turning V with its cause
on a fault in the input, clearing with hysteresis, and a clean replay staying A after settling."""

from __future__ import annotations

import numpy as np
import pytest

import formats
from imutool.live import LiveHub, run_live
from imutool.live.checks import CLEAR_S, SCALE_WINDOW_S, STUCK_S
from imutool.sim import run_simulate

RATE = 50.0
FAULT = (100.0, 150.0)  # s: the span of the input that is damaged


@pytest.fixture(scope="module")
def ship(tmp_path_factory):
    """4 minutes of a rolling ship at 50 Hz (simulated, seeded)."""
    path = tmp_path_factory.mktemp("checks") / "ship.csv"
    run_simulate("ship-roll", path, seed=5, duration=240.0, rate_hz=RATE)
    return formats.read(path)


def _replay(rec, tmp_path, name):
    path = tmp_path / f"{name}.csv"
    formats.write(rec, path)
    hub = LiveHub()
    sub = hub.subscribe(100_000)
    logs: list[str] = []
    res = run_live(replay=path, speed=0, motion="ship", settle_s=20, lever_arm=[0.0, 0.0, -2.0], hub=hub,
                   log=logs.append, handle_signals=False)  # fmt: skip
    snaps = []
    while (s := sub.get(0)) is not None:
        snaps.append(s)
    return res.summary, snaps, logs


def _damaged(rec, channel, fn):
    out = rec.select(slice(0, len(rec)))
    i = (out.time - out.time[0] >= FAULT[0]) & (out.time - out.time[0] < FAULT[1])
    for name in ("gyro", "accel") if channel == "both" else (channel,):
        x = np.array(out[name])
        x[i] = fn(x[i])
        out.channels[name] = x
    return out


def _with(snaps, words):
    return [s for s in snaps if words in s.cause]


def test_clean_replay_stays_a_after_settling(ship, tmp_path):
    summary, snaps, logs = _replay(ship, tmp_path, "clean")
    after = [s.status for s in snaps if s.t - snaps[0].t > 25.0]
    assert after and set(after) == {"A"}
    assert summary["self_checks"]["failures"] == {}
    last = summary["self_checks"]["gyro_scale_last"]  # the verdict was reached, and clean
    assert last["pairs"] >= 20 and 0.8 < last["scale"] < 1.25


@pytest.mark.parametrize(
    "fault, channel, fn, cause, first_within",
    [
        # a gyro read in the wrong range: every rate twice too large
        ("gyro x2", "gyro", lambda g: 2.0 * g, "gyro scale check (rates", SCALE_WINDOW_S + 10.0),
        # the accelerometer's y register frozen at its last value
        (
            "stuck accel y",
            "accel",
            lambda a: np.column_stack([a[:, 0], np.full(len(a), a[0, 1]), a[:, 2]]),
            "stuck input (accel y",
            STUCK_S + 0.5,
        ),
        # the whole sensor frozen: every axis repeats one frame (accel here, gyro below)
        (
            "flatlined",
            "both",
            lambda x: np.broadcast_to(x[:1], x.shape).copy(),
            "stuck input (all six axes",
            STUCK_S + 0.5,
        ),
        # the accelerometer in g read as m/s²
        ("accel units", "accel", lambda a: a / 9.80665, "accelerometer far from g", 0.9 * 10.0 + 0.5),
    ],
)
def test_a_fault_in_the_input_turns_v_with_its_cause_and_clears(ship, tmp_path, fault, channel, fn, cause,
                                                                first_within):  # fmt: skip
    summary, snaps, logs = _replay(_damaged(ship, channel, fn), tmp_path, fault.replace(" ", "_"))
    t0 = snaps[0].t
    hit = _with(snaps, cause)
    assert hit, f"{fault}: no status with cause {cause!r}"
    assert all(s.status == "V" for s in hit)
    first = hit[0].t - t0
    assert FAULT[0] <= first <= FAULT[0] + first_within  # causal: not before the fault, and soon after it
    assert any(f"status V: {cause}" in m or f"; {cause}" in m for m in logs if m.startswith("status V"))
    # cleared with hysteresis once the input is sound again (the windowed check's window plus CLEAR_S)
    last = hit[-1].t - t0
    window = SCALE_WINDOW_S if "scale" in cause else 10.0 if "far from g" in cause else 0.0
    assert FAULT[1] + CLEAR_S - 0.5 <= last <= FAULT[1] + window + CLEAR_S + 10.0 + 0.5
    assert all(s.status == "V" for s in snaps if FAULT[1] <= s.t - t0 <= FAULT[1] + CLEAR_S - 0.5)
    assert cause not in snaps[-1].cause
    if fault != "flatlined":  # (after 50 s of a frozen gyro the filter's own consistency check takes longer)
        assert snaps[-1].status == "A", snaps[-1].cause


def test_a_saturated_axis_turns_v_with_its_cause(ship, tmp_path):
    def clip(g):
        g = g.copy()
        g[:, 0] = np.clip(g[:, 0] * 20.0, -1.5, 1.5)  # a roll rate beyond a ±1.5 rad/s range: flat tops
        return g

    summary, snaps, logs = _replay(_damaged(ship, "gyro", clip), tmp_path, "saturated")
    hit = _with(snaps, "input saturated")
    assert hit and all(s.status == "V" for s in hit)
    assert FAULT[0] <= hit[0].t - snaps[0].t <= FAULT[0] + 10.0
    assert summary["saturated_samples"] > 0
