"""Sea-state and heave-platform scenarios: vessel heave/roll/pitch in irregular (JONSWAP) seas with truth.

Frames: body FRD, world NED; heave truth ``ref_heave`` is metres **positive up** at the IMU (the vessel's centre
of gravity), ``ref_heave_rate`` m/s positive up, ``ref_heave_accel`` m/s² positive up.

The accelerometer is a MEMS model (noise density, bias random walk) with the paper's constant bias: the heave
(vertical, positive-up) acceleration reads −0.022 m/s² too low (heave paper §3: "常值零偏为 −0.022 m/s²"). In FRD
the body z axis points down, so that is a bias of +0.022 m/s² on ``accel_z``.
"""

from __future__ import annotations

import numpy as np

from formats import Recording
from formats.frames import euler_to_quat
from imutool.sim.sensor import GRAVITY, MPU6050_GYRO, SensorErrors, body_rates_from_euler, imu_recording

# An MRU-grade MEMS accelerometer (ADXL355 class: ~25 µg/√Hz) with a slow bias random walk.
HEAVE_ACCEL_NOISE_UG = 25.0  # µg/√Hz
HEAVE_ACCEL_BIAS_UP = -0.022  # m/s², bias of the heave (up) acceleration, as measured in the heave paper
HEAVE_ACCEL_BIAS_RW = 2e-5  # m/s²/√s


def _accel_errors(noise_ug: float, bias_up: float, bias_rw: float) -> SensorErrors:
    return SensorErrors(
        noise_density=noise_ug * 1e-6 * GRAVITY, bias=np.array([0.004, -0.003, -bias_up]), bias_rw=bias_rw, quantum=0.0
    )


def jonswap_shape(omega: np.ndarray, tp: float, gamma: float = 3.3) -> np.ndarray:
    """The JONSWAP spectrum's shape ω⁻⁵ e^{−1.25 (ωp/ω)⁴} γ^r (ω rad/s, peak period tp s, peak enhancement γ),
    unscaled; 0 at ω ≤ 0."""
    w = np.asarray(omega, float)
    wp = 2 * np.pi / tp
    sigma = np.where(w <= wp, 0.07, 0.09)
    r = np.exp(-((w - wp) ** 2) / (2 * sigma**2 * wp**2))
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        return np.where(w > 0, w**-5.0 * np.exp(-1.25 * (wp / w) ** 4) * gamma**r, 0.0)


def jonswap(omega: np.ndarray, hs: float, tp: float, gamma: float = 3.3) -> np.ndarray:
    """JONSWAP wave-elevation spectrum S(ω) (m²·s/rad) scaled so that 4·√m0 = Hs."""
    w = np.asarray(omega, float)
    s = jonswap_shape(w, tp, gamma)
    m0 = np.trapezoid(s, w)
    return s * (hs / 4.0) ** 2 / m0 if m0 > 0 else s


def _second_order(omega: np.ndarray, wn: float, zeta: float) -> np.ndarray:
    """Complex response of a damped second-order system with unit static gain."""
    return wn**2 / (wn**2 - omega**2 + 2j * zeta * wn * omega)


def _components(hs, tp, n, rng, gamma):
    wp = 2 * np.pi / tp
    edges = np.linspace(0.35 * wp, 3.5 * wp, n + 1)
    dw = np.diff(edges)
    w = edges[:-1] + dw * rng.uniform(0.2, 0.8, n)  # jittered: no exact repetition period
    amp = np.sqrt(2 * jonswap(w, hs, tp, gamma) * dw)
    phase = rng.uniform(0, 2 * np.pi, n)
    return w, amp, phase


def _synth(t, w, c):
    """x(t) = Re Σ c_k e^{iω_k t}, and its first and second derivatives (chunked for memory)."""
    x = np.empty(len(t))
    dx = np.empty(len(t))
    ddx = np.empty(len(t))
    step = max(1, 2_000_000 // max(1, len(w)))
    for i in range(0, len(t), step):
        e = np.exp(1j * np.outer(t[i : i + step], w)) * c
        x[i : i + step] = e.real.sum(1)
        dx[i : i + step] = (e * (1j * w)).real.sum(1)
        ddx[i : i + step] = (e * (-(w**2))).real.sum(1)
    return x, dx, ddx


def _finish(
    t, heave, dheave, ddheave, roll, droll, pitch, dpitch, heading, rng, accel_errors, meta, accel_horizontal=None
):
    rates = body_rates_from_euler(roll, pitch, droll, dpitch, np.zeros_like(t))
    q = euler_to_quat(roll, pitch, np.full_like(t, heading))
    accel_ned = np.zeros((len(t), 3))
    accel_ned[:, 2] = -ddheave  # NED down = −heave
    if accel_horizontal is not None:
        accel_ned[:, :2] = accel_horizontal  # surge/sway in waves: what disturbs a real tilt filter
    rec = imu_recording(
        t,
        q,
        accel_ned,
        rng,
        gyro_errors=MPU6050_GYRO,
        accel_errors=accel_errors,
        mag_errors=None,
        gyro_true=rates,
        meta=meta,
    )
    rec.add("ref_heave", heave, "m")
    rec.add("ref_heave_rate", dheave, "m/s")
    rec.add("ref_heave_accel", ddheave, "m/s^2")
    rec.meta["heave_convention"] = "heave m positive UP at the IMU (vessel CoG); accel body FRD"
    return rec


def sea_state(
    duration: float | None = None,
    rate_hz: float | None = None,
    seed: int = 0,
    hs: float = 2.0,
    tp: float = 9.0,
    gamma: float = 3.3,
    heave_period: float = 7.0,
    heave_damping: float = 0.35,
    roll_period: float = 11.0,
    roll_damping: float = 0.08,
    pitch_period: float = 6.5,
    pitch_damping: float = 0.3,
    wave_direction_deg: float = 60.0,
    heading_deg: float = 30.0,
    components: int = 240,
    accel_noise_ug: float = HEAVE_ACCEL_NOISE_UG,
    accel_bias_up: float = HEAVE_ACCEL_BIAS_UP,
    accel_bias_rw: float = HEAVE_ACCEL_BIAS_RW,
    horizontal: float = 1.0,
) -> Recording:
    """A vessel in a JONSWAP sea (Hs m, Tp s, γ) with a 6-axis MEMS IMU at its centre of gravity.

    Heave = wave elevation through a damped 2nd-order response (natural period ``heave_period`` s); roll and
    pitch = wave slope k·ζ (k = ω²/g, deep water) through 2nd-order responses, projected by the relative wave
    direction (deg, 0 = head seas). Surge/sway: the deep-water orbital motion (horizontal amplitude = the
    elevation's, a quarter period ahead, along the wave direction) through the heave response, scaled by
    ``horizontal`` (0 = none); these horizontal accelerations are what gives a real tilt filter its attitude
    error in waves. Defaults: 1200 s at 50 Hz. Truth: ref_heave/ref_heave_rate (m, m/s, up),
    ref_q, ref_roll/pitch/heading, ref_gyro, ref_accel. ``meta``: significant heave 4·std(heave), sea parameters.
    """
    duration = 1200.0 if duration is None else float(duration)
    rate_hz = 50.0 if rate_hz is None else float(rate_hz)
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration * rate_hz)) + 1) / rate_hz
    w, amp, phase = _components(hs, tp, int(components), rng, gamma)
    zeta = amp * np.exp(1j * phase)
    k = w**2 / GRAVITY
    beta = np.radians(wave_direction_deg)
    ch = zeta * _second_order(w, 2 * np.pi / heave_period, heave_damping)
    cr = zeta * k * np.sin(beta) * _second_order(w, 2 * np.pi / roll_period, roll_damping)
    cp = zeta * k * np.cos(beta) * 0.6 * _second_order(w, 2 * np.pi / pitch_period, pitch_damping)
    heave, dheave, ddheave = _synth(t, w, ch)
    acc_h = None
    if horizontal:
        _, _, ddx = _synth(t, w, -1j * ch * float(horizontal))
        wave_dir = np.radians(heading_deg + wave_direction_deg)  # propagation direction, clockwise from north
        acc_h = np.stack([np.cos(wave_dir) * ddx, np.sin(wave_dir) * ddx], axis=1)
    roll, droll, _ = _synth(t, w, cr)
    pitch, dpitch, _ = _synth(t, w, cp)
    meta = {
        "scenario_sea": "JONSWAP",
        "hs_m": hs,
        "tp_s": tp,
        "gamma": gamma,
        "significant_heave_m": round(float(4 * np.std(heave)), 4),
        "accel_noise_ug_per_rthz": accel_noise_ug,
        "accel_bias_up_mps2": accel_bias_up,
        "accel_bias_rw_mps2_per_rts": accel_bias_rw,
        "horizontal_motion": float(horizontal),
    }
    return _finish(
        t,
        heave,
        dheave,
        ddheave,
        roll,
        droll,
        pitch,
        dpitch,
        np.radians(heading_deg),
        rng,
        _accel_errors(accel_noise_ug, accel_bias_up, accel_bias_rw),
        meta,
        acc_h,
    )


def heave_platform(
    duration: float | None = None,
    rate_hz: float | None = None,
    seed: int = 0,
    period: float = 6.0,
    amplitude: float = 0.04,
    accel_noise_ug: float = HEAVE_ACCEL_NOISE_UG,
    accel_bias_up: float = HEAVE_ACCEL_BIAS_UP,
    accel_bias_rw: float = HEAVE_ACCEL_BIAS_RW,
) -> Recording:
    """The heave paper's test platform: level, pure vertical sine (period 6 s, amplitude 0.03–0.05 m).

    Defaults: 300 s at 100 Hz, amplitude 0.04 m, heave-acceleration bias −0.022 m/s² (paper §3).
    """
    duration = 300.0 if duration is None else float(duration)
    rate_hz = 100.0 if rate_hz is None else float(rate_hz)
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration * rate_hz)) + 1) / rate_hz
    w = 2 * np.pi / period
    ph = rng.uniform(0, 2 * np.pi)
    heave = amplitude * np.sin(w * t + ph)
    dheave = amplitude * w * np.cos(w * t + ph)
    ddheave = -(w**2) * heave
    z = np.zeros_like(t)
    meta = {
        "scenario_sea": "heave platform",
        "period_s": period,
        "amplitude_m": amplitude,
        "significant_heave_m": round(float(4 * np.std(heave)), 4),
        "accel_noise_ug_per_rthz": accel_noise_ug,
        "accel_bias_up_mps2": accel_bias_up,
        "accel_bias_rw_mps2_per_rts": accel_bias_rw,
    }
    return _finish(
        t,
        heave,
        dheave,
        ddheave,
        z,
        z,
        z,
        z,
        0.0,
        rng,
        _accel_errors(accel_noise_ug, accel_bias_up, accel_bias_rw),
        meta,
    )


def irregular_roll(
    duration: float = 1800.0,
    rate_hz: float = 2.0,
    seed: int = 0,
    roll_period: float = 12.0,
    roll_damping: float = 0.08,
    wave_period: float | None = None,
    significant_deg: float = 5.0,
    list_deg: float = 0.0,
    noise_deg: float = 0.03,
    quantum_deg: float = 0.01,
    components: int = 200,
    gamma: float = 3.3,
) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """Irregular roll heel (deg, + starboard) in a JONSWAP sea, with its known periods: a roll-period benchmark.

    Roll = JONSWAP wave slope (peak ``wave_period`` s, default the roll period) through a damped second-order roll
    response (natural period ``roll_period`` s, damping ratio ``roll_damping``: narrow-band for ζ ≲ 0.1), scaled to
    a significant amplitude 2σ = ``significant_deg``, plus a constant list (deg), white noise (deg, 1σ) and
    rounding to ``quantum_deg``. Returns (t s, heel deg, truth) with truth ``tz_s`` = 2π√(m0/m2) of the roll
    spectrum (the mean zero-up-crossing period), ``tp_s`` (its peak period), ``significant_deg``, ``list_deg``.
    """
    rng = np.random.default_rng(seed)
    tw = roll_period if wave_period is None else float(wave_period)
    wp = 2 * np.pi / tw
    edges = np.linspace(0.3 * wp, 4.0 * wp, int(components) + 1)
    dw = np.diff(edges)
    w = edges[:-1] + dw * rng.uniform(0.2, 0.8, dw.size)

    def spectrum(om: np.ndarray) -> np.ndarray:
        h = _second_order(om, 2 * np.pi / roll_period, roll_damping)
        return jonswap_shape(om, tw, gamma) * (om**2 / GRAVITY) ** 2 * np.abs(h) ** 2

    amp = np.sqrt(2 * spectrum(w) * dw)
    phase = rng.uniform(0, 2 * np.pi, w.size)
    t = np.arange(int(round(duration * rate_hz))) / rate_hz
    x = np.zeros_like(t)
    for a, om, ph in zip(amp, w, phase, strict=True):
        x += a * np.cos(om * t + ph)
    m0, m2 = np.sum(amp**2) / 2, np.sum(amp**2 * w**2) / 2
    x *= significant_deg / (2 * np.sqrt(m0)) if m0 > 0 else 0.0
    fine = np.linspace(0.3 * wp, 4.0 * wp, 20000)
    x = x + list_deg + rng.normal(0.0, noise_deg, t.size)
    if quantum_deg > 0:
        x = np.round(x / quantum_deg) * quantum_deg
    truth = {
        "tz_s": float(2 * np.pi * np.sqrt(m0 / m2)),
        "tp_s": float(2 * np.pi / fine[np.argmax(spectrum(fine))]),
        "significant_deg": float(significant_deg),
        "list_deg": float(list_deg),
    }
    return t, x, truth
