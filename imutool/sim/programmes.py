"""Simulated test programmes for the evidence reports (``imutool report``): a device under test (DUT) against a
reference, as two recordings of angles (not raw sensor samples like the scenarios of :mod:`imutool.sim`).

``inclinometer_test`` follows the ISO 19697-style sequence a tilt/motion table would run: static heel steps on both
sides, sinusoidal roll at several period/amplitude combinations (one asymmetric), and a long static hold
(drift). ``heading_test`` follows ISO 22090-2 / MSC.116(73): static headings on a turntable, turns at several
rates of turn (follow-up) and a rolling segment at a constant heading (dynamic error).

The DUT carries known injected errors so the report can be checked against them:
``dut = (1 + scale) · truth(t − lag) + offset + drift·t + noise`` (deg; for heading also a semicircular deviation
``a·sin h + b·cos h`` and a roll coupling ``c·roll``). Angles deg, roll + starboard down, heading clockwise from
north; time s from the start of the programme. Deterministic for a seed. ``sea_pair`` is two motion sensors on
one ship at sea (irregular roll from the JONSWAP shape of :mod:`imutool.sim.sea`); ``write_sample_data`` writes
the bundled report examples (sample_data/).
"""

from __future__ import annotations

import os
from datetime import datetime, timezone
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.atomic import atomic_path
from imutool.nmea_out import nmea_lines
from imutool.roll import MOTION_TABLE
from imutool.sim.sea import jonswap_shape
from imutool.sim.sensor import GRAVITY

DEFAULT_STEPS = (0.0, 5.0, 10.0, 20.0, 30.0, 45.0, -5.0, -10.0, -20.0, -30.0, -45.0, 0.0)
# (period s, starboard amplitude deg, port amplitude deg, cycles): periods 4-30 s (standards.md P10, I)
DEFAULT_DYNAMIC = (
    (4.0, 5.0, 5.0, 8),
    (8.0, 10.0, 10.0, 6),
    (12.0, 20.0, 20.0, 5),
    (15.0, 25.0, 15.0, 4),
    (30.0, 15.0, 15.0, 3),
)


def _ramp(a: float, b: float, n: int) -> np.ndarray:
    """Smooth (raised-cosine) transition from a to b over n samples."""
    s = 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, n, endpoint=False))
    return a + (b - a) * s


def inclinometer_programme(
    rate_hz: float = 10.0,
    steps: tuple[float, ...] = DEFAULT_STEPS,
    hold_s: float = 20.0,
    transition_s: float = 4.0,
    dynamic: tuple = DEFAULT_DYNAMIC,
    long_deg: float = 5.0,
    long_s: float = 3700.0,
    long_rate_hz: float = 1.0,
    lat_accel_ms2: float = 0.0,
    lat_accel_s: float = 60.0,
    lat_accel_period_s: float = 20.0,
) -> tuple[np.ndarray, np.ndarray, list[dict[str, Any]], np.ndarray]:
    """True table heel and the programme: (t s, heel deg + stbd, segments [{kind, start, end, ...}], lateral
    acceleration m/s² + starboard).

    Static steps (to the declared range), sinusoidal roll (periods 4-30 s by default), an optional
    lateral-acceleration segment (table level, a sled/centrifuge applies ``lat_accel_ms2`` as a sine of
    ``lat_accel_period_s``: the heel must stay 0 while the specific force tilts) and a long static hold at
    ``long_deg``, sampled at ``long_rate_hz`` (an hours-long hold at a low rate keeps files small; the time
    base is then not uniform, which every reader accepts).
    """
    dt = 1.0 / rate_hz
    ts: list[np.ndarray] = []
    hs: list[np.ndarray] = []
    acc: list[np.ndarray] = []
    segs: list[dict[str, Any]] = []
    cur = 0.0
    n_hold = int(round(hold_s * rate_hz))
    n_tr = int(round(transition_s * rate_hz))

    def t_now() -> float:
        return float(ts[-1][-1] + dt) if ts else 0.0

    def add(x: np.ndarray, a: np.ndarray | None = None, step: float = dt) -> tuple[float, float]:
        t0 = t_now()
        ts.append(t0 + np.arange(x.size) * step)
        hs.append(x)
        acc.append(np.zeros(x.size) if a is None else a)
        return t0, float(ts[-1][-1] + step) if x.size else t0

    for i, s in enumerate(steps):
        if i > 0 or s != cur:
            add(_ramp(cur, s, n_tr))
        t0, t1 = add(np.full(n_hold, s))
        segs.append({"kind": "static", "start": t0, "end": t1, "reference_deg": s})
        cur = s
    for period, a_s, a_p, cycles in dynamic:
        add(_ramp(cur, 0.0, n_tr))
        cur = 0.0
        n = int(round(cycles * period * rate_hz))
        sn = np.sin(2 * np.pi * np.arange(n) * dt / period)
        t0, t1 = add(np.where(sn > 0, a_s * sn, a_p * sn))
        segs.append(
            {
                "kind": "dynamic",
                "start": t0,
                "end": t1,
                "period_s": period,
                "amp_stbd_deg": a_s,
                "amp_port_deg": a_p,
                "cycles": cycles,
            }
        )
    if lat_accel_ms2 > 0 and lat_accel_s > 0:
        add(_ramp(cur, 0.0, n_tr))
        cur = 0.0
        n = int(round(lat_accel_s * rate_hz))
        a = lat_accel_ms2 * np.sin(2 * np.pi * np.arange(n) * dt / lat_accel_period_s)
        t0, t1 = add(np.zeros(n), a)
        segs.append(
            {
                "kind": "lateral_acceleration",
                "start": t0,
                "end": t1,
                "reference_deg": 0.0,
                "lat_accel_ms2": lat_accel_ms2,
                "period_s": lat_accel_period_s,
            }
        )
    if long_s > 0:
        add(_ramp(cur, long_deg, n_tr))
        step = 1.0 / long_rate_hz
        t0, t1 = add(np.full(int(round(long_s * long_rate_hz)), long_deg), step=step)
        segs.append({"kind": "long", "start": t0, "end": t1 - step, "reference_deg": long_deg})
    return np.concatenate(ts), np.concatenate(hs), segs, np.concatenate(acc)


def _shift(t: np.ndarray, x: np.ndarray, lag_s: float) -> np.ndarray:
    """x(t − lag) by linear interpolation (held at the ends)."""
    return np.interp(t - lag_s, t, x)


def inclinometer_test(
    rate_hz: float = 10.0,
    seed: int = 0,
    offset_deg: float = 0.0,
    scale: float = 0.0,
    lag_s: float = 0.0,
    noise_deg: float = 0.0,
    drift_deg_per_h: float = 0.0,
    ref_noise_deg: float = 0.0,
    long_s: float = 3700.0,
    accel_coupling: float = 0.0,
    **programme: Any,
) -> tuple[Recording, Recording, list[dict[str, Any]]]:
    """(DUT recording, reference recording, segments) for an inclinometer test on a simulated tilt table.

    Both recordings hold ``roll`` (deg, + starboard down) and ``pitch`` (0); the reference also holds
    ``lat_accel`` (m/s², + starboard: the kinematic lateral acceleration applied, gravity excluded).
    ``accel_coupling`` is the fraction of the apparent tilt atan(a/g) that leaks into the DUT heel (1 for an
    accelerometer-only inclinometer, ~0 for a gyro-aided one). Injected DUT errors are stored in
    ``dut.meta['injected']``. Segments give the static steps (use them as a ``--static-steps`` file).
    """
    rng = np.random.default_rng(seed)
    t, heel, segs, lat = inclinometer_programme(rate_hz=rate_hz, long_s=long_s, **programme)
    ref = heel + (rng.normal(0.0, ref_noise_deg, heel.size) if ref_noise_deg > 0 else 0.0)
    dut = (1.0 + scale) * _shift(t, heel, lag_s) + offset_deg + drift_deg_per_h * t / 3600.0
    dut = dut + accel_coupling * np.degrees(np.arctan2(_shift(t, lat, lag_s), GRAVITY))
    if noise_deg > 0:
        dut = dut + rng.normal(0.0, noise_deg, heel.size)
    zeros = np.zeros_like(t)
    common = {
        "frame": "vessel body FRD (x bow, y starboard, z down)",
        "convention": "roll + starboard down (deg)",
        "rate_hz": rate_hz,
        "seed": seed,
    }
    inj = {
        "offset_deg": offset_deg,
        "scale": scale,
        "lag_s": lag_s,
        "noise_deg": noise_deg,
        "drift_deg_per_h": drift_deg_per_h,
        "accel_coupling": accel_coupling,
    }
    r_dut = Recording(
        t.copy(),
        {"roll": dut, "pitch": zeros.copy()},
        {"roll": "deg", "pitch": "deg"},
        {**common, "sensor": "simulated inclinometer (DUT)", "device": "SIM-INC-1 s/n 0001 fw 1.0", "injected": inj},
    )
    ch = {"roll": ref, "pitch": zeros.copy()}
    units = {"roll": "deg", "pitch": "deg"}
    if np.any(lat != 0):
        ch["lat_accel"] = lat
        units["lat_accel"] = "m/s^2"
    r_ref = Recording(
        t.copy(),
        ch,
        units,
        {**common, "sensor": "simulated tilt table encoder (reference)", "reference_noise_deg": ref_noise_deg},
    )
    return r_dut, r_ref, segs


def irregular_roll(
    duration_s: float,
    rate_hz: float = 1.0,
    tp_s: float = 10.0,
    std_deg: float = 0.5,
    gamma: float = 3.3,
    seed: int = 0,
    n_comp: int = 400,
) -> tuple[np.ndarray, np.ndarray]:
    """Irregular ship roll (t s, heel deg) from a JONSWAP-shaped spectrum (peak period tp_s, peak enhancement
    gamma) as a sum of n_comp sines with random phases, scaled to a standard deviation of std_deg.

    A ship's roll response is narrow-banded around its natural period; the JONSWAP shape with gamma 3.3 is
    a stand-in for that (imutool's test model, not a seakeeping computation).
    """
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    wp = 2 * np.pi / tp_s
    w = np.linspace(0.4 * wp, 3.0 * wp, n_comp)
    spec = jonswap_shape(w, tp_s, gamma)
    amp = np.sqrt(2 * spec * (w[1] - w[0]))
    ph = rng.uniform(0, 2 * np.pi, n_comp)
    x = (amp[None, :] * np.cos(w[None, :] * t[:, None] + ph[None, :])).sum(axis=1)
    return t, x * std_deg / x.std()


def sea_pair(
    duration_s: float = 1800.0,
    rate_hz: float = 1.0,
    tp_s: float = 10.0,
    std_deg: float = 0.5,
    seed: int = 0,
    noise_ref_deg: float = 0.02,
    noise_dut_deg: float = 0.03,
    quant_deg: float = 0.01,
    offset_deg: float = 0.0,
    scale: float = 0.0,
) -> tuple[Recording, Recording]:
    """Two motion sensors on one ship at sea: (DUT, reference), each heel = truth + its own white noise,
    quantised to quant_deg (a 0.01° output resolution), sampled at rate_hz; the DUT optionally with an offset
    (deg) and a scale error (fraction)."""
    t, x = irregular_roll(duration_s, rate_hz, tp_s, std_deg, seed=seed)
    rng = np.random.default_rng(seed + 1000)
    ref = x + rng.normal(0.0, noise_ref_deg, x.size)
    dut = (1 + scale) * x + offset_deg + rng.normal(0.0, noise_dut_deg, x.size)
    q = (lambda v: np.round(v / quant_deg) * quant_deg) if quant_deg > 0 else (lambda v: v)
    meta = {"frame": "vessel body FRD", "convention": "roll + starboard down (deg)", "rate_hz": rate_hz}
    r_dut = Recording(
        t.copy(),
        {"roll": q(dut)},
        {"roll": "deg"},
        {
            **meta,
            "sensor": "simulated motion sensor B (DUT)",
            "injected": {"offset_deg": offset_deg, "scale": scale, "noise_deg": noise_dut_deg},
        },
    )
    r_ref = Recording(t.copy(), {"roll": q(ref)}, {"roll": "deg"}, {**meta, "sensor": "simulated motion sensor A"})
    return r_dut, r_ref


def write_steps_csv(segs: list[dict[str, Any]], path: str) -> None:
    """Write the static segments as a steps file: ``start,end,reference`` (s, s, deg), atomically."""
    rows = [s for s in segs if s["kind"] in ("static", "long")]
    with atomic_path(path) as tmp, open(tmp, "w") as f:
        f.write("start,end,reference\n")
        for s in rows:
            f.write(f"{s['start']:.3f},{s['end']:.3f},{s['reference_deg']:.3f}\n")


def heading_programme(
    rate_hz: float = 10.0,
    headings: int = 8,
    hold_s: float = 20.0,
    slew_dps: float = 5.0,
    turn_rates: tuple[float, ...] = (8.0, 20.0),
    turn_deg: float = 360.0,
    roll_amp_deg: float = 10.0,
    roll_period_s: float = 10.0,
    rolling_s: float = 60.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """True (t s, heading deg unwrapped, roll deg, segments) of a turntable heading test."""
    dt = 1.0 / rate_hz
    hs: list[np.ndarray] = []
    segs: list[dict[str, Any]] = []
    cur = 0.0
    n_hold = int(round(hold_s * rate_hz))

    def t_now() -> float:
        return sum(p.size for p in hs) * dt

    def slew(to: float, rate: float, kind: str | None = None) -> None:
        nonlocal cur
        n = max(2, int(round(abs(to - cur) / rate * rate_hz)))
        t0 = t_now()
        if kind is None:
            hs.append(_ramp(cur, to, n))
        else:  # constant rate with short smooth ends
            n_acc = int(round(1.0 * rate_hz))
            body = np.linspace(cur, to, n, endpoint=False)
            hs.append(body)
            segs.append(
                {
                    "kind": kind,
                    "start": t0 + n_acc * dt,
                    "end": t_now() - n_acc * dt,
                    "rate_dps": float(np.sign(to - cur) * rate),
                }
            )
        cur = to

    for k in range(headings):
        h = 360.0 * k / headings
        if k:
            slew(h, slew_dps)
        t0 = t_now()
        hs.append(np.full(n_hold, h))
        segs.append({"kind": "static", "start": t0, "end": t_now(), "heading_deg": h})
    for r in turn_rates:
        slew(cur + turn_deg, r, kind="turn")
        hs.append(np.full(int(round(5 * rate_hz)), cur))
    t0 = t_now()
    n_roll = int(round(rolling_s * rate_hz))
    hs.append(np.full(n_roll, cur))
    segs.append(
        {
            "kind": "rolling",
            "start": t0,
            "end": t_now(),
            "heading_deg": cur % 360.0,
            "roll_amp_deg": roll_amp_deg,
            "roll_period_s": roll_period_s,
        }
    )
    heading = np.concatenate(hs)
    t = np.arange(heading.size) * dt
    roll = np.zeros_like(t)
    m = t >= t0
    roll[m] = roll_amp_deg * np.sin(2 * np.pi * (t[m] - t0) / roll_period_s)
    return t, heading, roll, segs


def heading_test(
    rate_hz: float = 10.0,
    seed: int = 0,
    offset_deg: float = 0.0,
    semicircular_deg: tuple[float, float] = (0.0, 0.0),
    lag_s: float = 0.0,
    noise_deg: float = 0.0,
    roll_coupling: float = 0.0,
    **programme: Any,
) -> tuple[Recording, Recording, list[dict[str, Any]]]:
    """(DUT e.g. a digital magnetic compass, reference gyro, segments) for a heading-device test.

    DUT heading = truth(t − lag) + offset + a·sin(h) + b·cos(h) + roll_coupling·roll + noise (deg, wrapped to
    [0, 360)). Both recordings hold ``heading`` (deg) and ``roll`` (deg, truth).
    """
    rng = np.random.default_rng(seed)
    t, h, roll, segs = heading_programme(rate_hz=rate_hz, **programme)
    hl = _shift(t, h, lag_s)
    a, b = semicircular_deg
    hr = np.radians(hl)
    dut = hl + offset_deg + a * np.sin(hr) + b * np.cos(hr) + roll_coupling * _shift(t, roll, lag_s)
    if noise_deg > 0:
        dut = dut + rng.normal(0.0, noise_deg, t.size)
    common = {"frame": "NED; heading clockwise from north (deg)", "rate_hz": rate_hz, "seed": seed}
    inj = {
        "offset_deg": offset_deg,
        "semicircular_deg": list(semicircular_deg),
        "lag_s": lag_s,
        "noise_deg": noise_deg,
        "roll_coupling": roll_coupling,
    }
    r_dut = Recording(
        t.copy(),
        {"heading": dut % 360.0, "roll": roll.copy()},
        {},
        {
            **common,
            "sensor": "simulated digital magnetic compass (DUT)",
            "device": "SIM-DMC-1 s/n 0002 fw 1.0",
            "injected": inj,
        },
    )
    r_ref = Recording(
        t.copy(),
        {"heading": h % 360.0, "roll": roll.copy()},
        {},
        {**common, "sensor": "simulated gyro compass / turntable encoder (reference)"},
    )
    return r_dut, r_ref, segs


SAMPLE_INCLINOMETER_ERRORS = {
    "offset_deg": 0.2,
    "scale": 0.01,
    "lag_s": 0.02,
    "noise_deg": 0.05,
    "drift_deg_per_h": 0.1,
    "accel_coupling": 0.05,
}
SAMPLE_LATERAL_ACCEL_MS2 = 1.0  # the sample programme's lateral-acceleration segment (peak, m/s²)
SAMPLE_HEADING_ERRORS = {
    "offset_deg": 0.2,
    "semicircular_deg": (0.3, -0.2),
    "lag_s": 0.02,
    "noise_deg": 0.05,
    "roll_coupling": 0.02,
}


def write_sample_data(folder: str, seed: int = 1, rate_hz: float = 10.0) -> dict[str, str]:
    """Write the bundled report examples into ``folder`` and return {name: path}.

    inclinometer_dut.csv / inclinometer_reference.csv / inclinometer_steps.csv (tilt-table programme: steps to
    ±45°, roll periods 4-30 s, a lateral-acceleration segment, a 1 h hold at 1 Hz; DUT with
    SAMPLE_INCLINOMETER_ERRORS), inclinometer_dut.nmea (the DUT as a time-stamped HRM capture, from
    ``imutool nmea``'s generator), heading_dut.csv / heading_reference.csv (SAMPLE_HEADING_ERRORS; turns at 8
    and 20 °/s). The test record example ``test_info.toml`` is a hand-written file, not generated.
    """
    os.makedirs(folder, exist_ok=True)
    out = {}
    dut, ref, segs = inclinometer_test(
        rate_hz=rate_hz,
        seed=seed,
        ref_noise_deg=0.01,
        lat_accel_ms2=SAMPLE_LATERAL_ACCEL_MS2,
        **SAMPLE_INCLINOMETER_ERRORS,
    )
    for name, rec in (("inclinometer_dut.csv", dut), ("inclinometer_reference.csv", ref)):
        out[name] = os.path.join(folder, name)
        formats.write(rec, out[name])
    out["inclinometer_steps.csv"] = os.path.join(folder, "inclinometer_steps.csv")
    write_steps_csv(segs, out["inclinometer_steps.csv"])
    out["inclinometer_dut.nmea"] = os.path.join(folder, "inclinometer_dut.nmea")
    with atomic_path(out["inclinometer_dut.nmea"]) as tmp, open(tmp, "w", newline="") as fh:
        utc0 = datetime(2026, 1, 5, 8, 0, 0, tzinfo=timezone.utc)  # peak-hold reset = start of the test
        # the simulated device on a motion table: level is 0° and its cycle band a fixed ±0.5°
        hrm_kw = {"utc_start": utc0, "hysteresis_deg": 0.5, **MOTION_TABLE}
        for ts, s in nmea_lines(dut, ["HRM"], None, roll_kw=hrm_kw):
            fh.write(f"{ts:.3f} {s}\r\n")
    hd, hr, _ = heading_test(rate_hz=rate_hz, seed=seed, **SAMPLE_HEADING_ERRORS)
    for name, rec in (("heading_dut.csv", hd), ("heading_reference.csv", hr)):
        out[name] = os.path.join(folder, name)
        formats.write(rec, out[name])
    return out
