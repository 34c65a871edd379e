"""A ship at sea with a bridge-mounted IMU: irregular roll, pitch, heave, sway, surge, yaw, a 360° turn, GNSS.

Frames (docs/architecture.md): body FRD (x bow, y starboard, z down), world NED, quaternions scalar-first body→NED,
gravity g = +9.80665 m/s² along NED +z (down); the accelerometer measures the specific force
f = Rᵀ(a − g_ned), so it reads −g on z at rest. Angles in the options are degrees, everything inside SI.

The hull reference point O is the vessel's centre of rotation (roll centre); it carries the track, the heave
and the sway. The sensor sits at the lever arm r (body FRD, m) from O, so its specific force is

    f = Rᵀ (a_O − g_ned) + ω̇ × r + ω × (ω × r),

with a_O the NED acceleration of O (turn centripetal, sway, heave), ω the body rate and ω̇ its derivative, both
obtained analytically from the Euler angles and their first and second time derivatives (ZYX kinematics, not
the Euler rates themselves).

Sea motion: every wave-induced degree of freedom x(t) is a sum of random-phase cosines whose amplitudes follow
the response spectrum of a damped second-order system driven by white excitation,

    S(ω) ∝ 1 / ((1 − (ω/ωn)²)² + (2ζ ω/ωn)²),   ω ∈ [0.5, 1.8]·ωn,  ωn = 2π/T,

sampled at jittered frequencies (no exact repetition period), then scaled so that the largest |x| over the
simulated run equals the option's peak value (so a 60 s run and a 600 s run both reach the stated peak).
Roll uses ζ = ``roll_damping`` (narrow band around the natural roll period); pitch, heave, sway and yaw use
ζ = 0.3 (broader, wave-driven).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from formats import Recording
from formats.errors import ImutoolError
from formats.frames import euler_to_quat, quat_to_matrix
from imutool.sim.sensor import (
    GRAVITY,
    HMC5883L_MAG,
    MPU6050_ACCEL,
    MPU6050_GYRO,
    SensorErrors,
    body_rates_from_euler,
    earth_field_ned,
    imu_recording,
)

BRIDGE_LEVER_ARM = (-30.0, 0.0, -20.0)  # m, body FRD: 30 m aft of and 20 m above the roll centre
_BROAD_DAMPING = 0.3  # ζ of the pitch, heave, sway and yaw response spectra
_BAND = (0.5, 1.8)  # spectral band, multiples of the natural frequency
SPEED_SOURCES = ("gnss", "smoothed", "log", "none")  # what the ship knows of its own velocity (ship_at_sea)
GNSS_COLUMNS = ("sog_cog", "vel", "both")  # how a GNSS velocity is written: sog/cog, vel_n/vel_e, or both


def parse_lever_arm(value: object, name: str = "lever_arm") -> np.ndarray:
    """A lever arm (3,) m from a sequence or a string ``"x,y,z"`` (brackets/parentheses allowed)."""
    if isinstance(value, str):
        parts = value.strip().strip("()[]").replace(";", ",").split(",")
        try:
            vals = [float(p) for p in parts if p.strip()]
        except ValueError:
            vals = []
    else:
        try:
            vals = [float(v) for v in np.ravel(np.asarray(value, dtype=float))]
        except (TypeError, ValueError):
            vals = []
    if len(vals) != 3 or not np.all(np.isfinite(vals)):
        raise ImutoolError(f"{name}: expected three numbers x,y,z in metres (body FRD), got {value!r}")
    return np.array(vals, dtype=float)


def _spectrum_components(
    rng: np.random.Generator, period: float, damping: float, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies ω (rad/s) and complex amplitudes of a random-phase realisation of the response spectrum."""
    wn = 2 * np.pi / period
    edges = np.linspace(_BAND[0] * wn, _BAND[1] * wn, n + 1)
    dw = np.diff(edges)
    w = edges[:-1] + dw * rng.uniform(0.2, 0.8, n)
    s = 1.0 / ((1 - (w / wn) ** 2) ** 2 + (2 * damping * w / wn) ** 2)
    phase = rng.uniform(0.0, 2 * np.pi, n)
    return w, np.sqrt(2 * s * dw) * np.exp(1j * phase)


def _synthesise(t: np.ndarray, parts: list[tuple[np.ndarray, np.ndarray]], peaks: list[float]) -> np.ndarray:
    """x, ẋ, ẍ of every part as an array (3, k, N), each part scaled so that max|x| = its peak.

    x(t) = Re Σ c_k e^{iω_k t}. On a uniform grid t = t0 + (aB + j)·dt the sum factors into one matrix product,
    X[a, j] = Σ_k (c_k e^{iω_k (t0 + aB dt)}) · e^{iω_k j dt}, so only (N/B + B)·K exponentials are evaluated.
    """
    n = len(t)
    out = np.empty((3, len(parts), n))
    dt = np.diff(t)
    uniform = n > 1 and np.ptp(dt) <= 1e-9 * max(1.0, abs(t[-1]))
    blk = max(1, int(np.ceil(np.sqrt(n))))
    nb = -(-n // blk)
    for j, (w, c) in enumerate(parts):
        coefs = np.stack([c, c * 1j * w, -c * w**2])  # (3, K): x, ẋ, ẍ
        if uniform:
            start = np.exp(1j * np.outer(t[0] + np.arange(nb) * blk * dt[0], w))  # (nb, K)
            within = np.exp(1j * np.outer(np.arange(blk) * dt[0], w))  # (blk, K)
            y = ((start[None] * coefs[:, None, :]).reshape(3 * nb, -1) @ within.T).real
            out[:, j] = y.reshape(3, nb * blk)[:, :n]
        else:
            for a in range(0, n, 4096):
                out[:, j, a : a + 4096] = (coefs @ np.exp(1j * np.outer(w, t[a : a + 4096]))).real
    for j, pk in enumerate(peaks):
        m = np.max(np.abs(out[0, j])) if n else 0.0
        out[:, j] *= (pk / m) if m > 0 else 0.0
    return out


def _smootherstep(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Quintic ramp S(u) = 10u³ − 15u⁴ + 6u⁵ on [0, 1] (C², clipped outside): ∫S, S, S′, S″."""
    uc = np.clip(u, 0.0, 1.0)
    inside = (u > 0) & (u < 1)
    integ = 2.5 * uc**4 - 3 * uc**5 + uc**6 + np.maximum(u - 1.0, 0.0)
    s = 10 * uc**3 - 15 * uc**4 + 6 * uc**5
    ds = np.where(inside, 30 * uc**2 * (1 - uc) ** 2, 0.0)
    dds = np.where(inside, 60 * uc * (1 - uc) * (1 - 2 * uc), 0.0)
    return integ, s, ds, dds


@dataclass
class VoyageMotion:
    """Noise-free kinematics of the voyage at times ``t`` (s). Angles rad, NED/FRD, SI units.

    ``euler`` (3, 3, N): [roll, pitch, heading] × [value, 1st, 2nd derivative]; ``q`` (N,4) body→NED;
    ``omega``/``omega_dot`` (N,3) body rate rad/s and its derivative rad/s²; ``pos``/``vel``/``acc`` (N,3)
    NED position (m, origin: O at t = 0), velocity and acceleration of the hull reference point O;
    ``heave`` (N,) m positive up at O; ``course_rate`` (N,) rad/s, the turn's rate of turn; ``heel`` (N,) rad,
    the steady-turn heel component of the roll; ``course`` (N,) rad, the track's direction (NED, from north).
    """

    t: np.ndarray
    euler: np.ndarray
    q: np.ndarray
    omega: np.ndarray
    omega_dot: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    heave: np.ndarray
    course_rate: np.ndarray
    heel: np.ndarray
    course: np.ndarray | None = None

    def lever_accel(self, lever_arm: np.ndarray) -> np.ndarray:
        """ω̇ × r + ω × (ω × r) (N,3), body FRD m/s², for a sensor at ``lever_arm`` (m, FRD) from O."""
        r = np.broadcast_to(np.asarray(lever_arm, dtype=float), self.omega.shape)
        return np.cross(self.omega_dot, r) + np.cross(self.omega, np.cross(self.omega, r))

    def specific_force(self, lever_arm: np.ndarray, gravity: float = GRAVITY) -> np.ndarray:
        """f = Rᵀ(a_O − g_ned) + ω̇ × r + ω × (ω × r) (N,3), body FRD m/s², at the sensor."""
        rot = quat_to_matrix(self.q)
        a = self.acc - np.array([0.0, 0.0, gravity])
        return np.einsum("nji,nj->ni", rot, a) + self.lever_accel(lever_arm)

    def sensor_track(self, lever_arm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """NED position, velocity and acceleration (N,3) of the sensor: O + R r, and its derivatives."""
        rot = quat_to_matrix(self.q)
        r = np.broadcast_to(np.asarray(lever_arm, dtype=float), self.omega.shape)
        pos = self.pos + np.einsum("nij,nj->ni", rot, r)
        vel = self.vel + np.einsum("nij,nj->ni", rot, np.cross(self.omega, r))
        acc = self.acc + np.einsum("nij,nj->ni", rot, self.lever_accel(lever_arm))
        return pos, vel, acc


def voyage_motion(
    t: np.ndarray,
    seed: int = 0,
    *,
    roll_deg: float,
    roll_period: float,
    roll_damping: float,
    pitch_deg: float,
    pitch_period: float,
    heave_m: float,
    heave_period: float,
    sway_m: float,
    sway_period: float,
    surge_m: float,
    surge_period: float,
    roll_significant_deg: float,
    yaw_deg: float,
    yaw_period: float,
    severity: float,
    heading_deg: float,
    speed_mps: float,
    turn_rate_dps: float,
    turn_start: float,
    turn_angle_deg: float,
    turn_ramp: float,
    gm_m: float,
    heel_arm_m: float,
    components: int,
    rng: np.random.Generator | None = None,
) -> VoyageMotion:
    """The vessel's noise-free motion at times ``t`` (s); options as in :func:`ship_at_sea`, which holds their
    defaults (every one is given here, so they are written once).

    The random phases are drawn first from ``rng`` (or ``default_rng(seed)``), in a fixed order that does not
    depend on the option values, so runs that differ only in lever arm, turn or noise share the same sea. The
    surge's phases come from a second stream, ``default_rng([seed, 1])`` (``seed`` is then the scenario's), so a
    run with surge has the same roll, pitch, heave and sway as one without.
    """
    t = np.asarray(t, dtype=float)
    rng = np.random.default_rng(seed) if rng is None else rng
    n_roll = max(8, int(components))
    n_other = max(8, n_roll // 3)
    parts = [
        _spectrum_components(rng, roll_period, roll_damping, n_roll),
        _spectrum_components(rng, pitch_period, _BROAD_DAMPING, n_other),
        _spectrum_components(rng, yaw_period, _BROAD_DAMPING, n_other),
        _spectrum_components(rng, heave_period, _BROAD_DAMPING, n_other),
        _spectrum_components(rng, sway_period, _BROAD_DAMPING, n_other),
    ]
    k = float(severity)
    peaks = [k * np.radians(roll_deg), k * np.radians(pitch_deg), k * np.radians(yaw_deg), k * heave_m, k * sway_m]
    wave = _synthesise(t, parts, peaks)  # (deriv, dof, N)
    if roll_significant_deg > 0:  # the roll scaled to a significant amplitude 2σ instead of a peak
        sd = float(np.std(wave[0, 0]))
        wave[:, 0] *= (k * np.radians(roll_significant_deg) / (2 * sd)) if sd > 0 else 0.0
    if surge_m != 0:
        extra = np.random.default_rng([int(seed), 1])
        surge = _synthesise(t, [_spectrum_components(extra, surge_period, _BROAD_DAMPING, n_other)], [k * surge_m])
        u, du, ddu = surge[:, 0]
    else:
        u = du = ddu = None

    # the turn: rate of turn r·(S(u1) − S(u2)), quintic ramps of turn_ramp s, total heading change turn_angle_deg
    r = np.radians(turn_rate_dps)
    zero = np.zeros_like(t)
    if r != 0 and turn_angle_deg != 0:
        span = abs(np.radians(turn_angle_deg) / r)  # s between the start of the ramp-in and of the ramp-out
        ramp = min(max(turn_ramp, 1e-3), span)
        i1, s1, d1, dd1 = _smootherstep((t - turn_start) / ramp)
        i2, s2, d2, dd2 = _smootherstep((t - turn_start - span) / ramp)
        chi = r * ramp * (i1 - i2)
        chi_d = r * (s1 - s2)
        chi_dd = r / ramp * (d1 - d2)
        chi_ddd = r / ramp**2 * (dd1 - dd2)
    else:
        chi = chi_d = chi_dd = chi_ddd = zero
    # steady-turn heel, outward: tan φ = −V ψ̇ (KG − T/2) / (g GM)
    c = speed_mps * heel_arm_m / (GRAVITY * gm_m)
    x = c * chi_d
    heel = -np.arctan(x)
    heel_d = -c * chi_dd / (1 + x**2)
    heel_dd = -(c * chi_ddd / (1 + x**2) - 2 * x * (c * chi_dd) ** 2 / (1 + x**2) ** 2)

    psi0 = np.radians(heading_deg)
    euler = np.empty((3, 3, len(t)))
    euler[0] = [heel + wave[0, 0], heel_d + wave[1, 0], heel_dd + wave[2, 0]]
    euler[1] = [wave[0, 1], wave[1, 1], wave[2, 1]]
    euler[2] = [psi0 + chi + wave[0, 2], chi_d + wave[1, 2], chi_dd + wave[2, 2]]
    (ph, dph, ddph), (th, dth, ddth), (ps, dps, ddps) = euler
    q = euler_to_quat(ph, th, ps)
    omega = body_rates_from_euler(ph, th, dph, dth, dps)
    sf, cf, st, ct = np.sin(ph), np.cos(ph), np.sin(th), np.cos(th)
    omega_dot = np.stack(
        [
            ddph - ddps * st - dps * dth * ct,
            ddth * cf - dth * dph * sf + ddps * sf * ct + dps * dph * cf * ct - dps * dth * sf * st,
            -ddth * sf - dth * dph * cf + ddps * cf * ct - dps * dph * sf * ct - dps * dth * cf * st,
        ],
        axis=-1,
    )

    # hull reference point O: track along the course χ at speed V, sway s across it, heave h up
    course = psi0 + chi
    e1 = np.stack([np.cos(course), np.sin(course), zero], axis=-1)
    e2 = np.stack([-np.sin(course), np.cos(course), zero], axis=-1)
    up = np.array([0.0, 0.0, -1.0])
    h, dh, ddh = wave[:, 3]
    s, ds, dds = wave[:, 4]
    track = np.zeros((len(t), 3))
    if len(t) > 1:  # ∫ V e1 dt by the trapezoid rule on the sample grid
        seg = 0.5 * (e1[1:] + e1[:-1]) * np.diff(t)[:, None] * speed_mps
        track[1:] = np.cumsum(seg, axis=0)
    pos = track + s[:, None] * e2 + h[:, None] * up - (s[0] * e2[0] + h[0] * up)
    vel = (speed_mps - s * chi_d)[:, None] * e1 + ds[:, None] * e2 + dh[:, None] * up
    acc = (
        (-2 * ds * chi_d - s * chi_dd)[:, None] * e1
        + (speed_mps * chi_d + dds - s * chi_d**2)[:, None] * e2
        + ddh[:, None] * up
    )
    if u is not None:  # surge u along the track: d(u e1)/dt = u̇ e1 + u χ̇ e2, and again
        pos = pos + u[:, None] * e1 - u[0] * e1[0]
        vel = vel + du[:, None] * e1 + (u * chi_d)[:, None] * e2
        acc = acc + (ddu - u * chi_d**2)[:, None] * e1 + (2 * du * chi_d + u * chi_dd)[:, None] * e2
    return VoyageMotion(t, euler, q, omega, omega_dot, pos, vel, acc, h, chi_d, heel, course)


def ship_at_sea(
    duration: float | None = None,
    rate_hz: float | None = None,
    seed: int = 0,
    *,
    lever_arm: object = BRIDGE_LEVER_ARM,
    roll_deg: float = 19.0,
    roll_period: float = 12.0,
    roll_damping: float = 0.1,
    pitch_deg: float = 3.0,
    pitch_period: float = 8.0,
    heave_m: float = 2.0,
    heave_period: float = 8.0,
    sway_m: float = 0.5,
    sway_period: float = 10.0,
    surge_m: float = 0.0,
    surge_period: float = 10.0,
    roll_significant_deg: float = 0.0,
    yaw_deg: float = 1.5,
    yaw_period: float = 12.0,
    severity: float = 1.0,
    heading_deg: float = 30.0,
    speed_mps: float = 8.0,
    turn_rate_dps: float = 3.0,
    turn_start: float = 120.0,
    turn_angle_deg: float = 360.0,
    turn_ramp: float = 10.0,
    gm_m: float = 2.0,
    heel_arm_m: float = 3.0,
    components: int = 96,
    noise: int = 1,
    gyro_noise_deg_s_rthz: float = 0.005,
    gyro_bias_deg_s: float = 0.5,
    gyro_bias_rw_deg_s: float = 0.002,
    accel_noise_ug: float = 400.0,
    accel_bias_mg: float = 2.0,
    accel_bias_rw: float = 1e-5,
    mag: int = 1,
    mag_inclination_deg: float = 60.0,
    mag_declination_deg: float = 0.0,
    gnss_rate_hz: float = 1.0,
    gnss_vel_noise_mps: float = 0.05,
    speed_source: str = "gnss",
    gnss_columns: str = "sog_cog",
    antenna_arm: object = None,
) -> Recording:
    """A vessel at sea with the IMU on the bridge: the MSC.363(92) inclinometer's hard case, with truth.

    Defaults: 600 s at 100 Hz. Sensor at ``lever_arm`` = (−30, 0, −20) m body FRD from the roll centre O (30 m
    aft, 20 m above; a string ``"x,y,z"`` works with ``--set``). Sea (module docstring for the spectrum; each
    peak is the largest |value| of the wave-induced motion over the run, all multiplied by ``severity``):
    roll peak ``roll_deg`` 19° around ``roll_period`` 12 s with ζ = ``roll_damping`` 0.1; pitch 3° / 8 s;
    yaw oscillation 1.5° / 12 s; heave ±2 m / 8 s at O; sway 0.5 m / 10 s (across the track); ζ = 0.3 for all
    but roll; ``components`` 96 for roll, a third of that for each of the others.

    Track: O runs at ``speed_mps`` 8 m/s from heading ``heading_deg`` 30° (course = heading without the yaw
    oscillation; no drift angle). At ``turn_start`` 120 s it turns ``turn_angle_deg`` 360° at
    ``turn_rate_dps`` 3 °/s (+ = to starboard; 0 disables), eased in and out over ``turn_ramp`` 10 s with a
    quintic ramp (C² rates, so ω̇ is continuous); a full turn at 3 °/s spans 120 s + one ramp. Turn heel
    (outward, from the hull's lateral force acting below the centre of gravity): tan φ = −V ψ̇ (KG − T/2) /
    (g GM) with GM = ``gm_m`` 2 m and KG − T/2 = ``heel_arm_m`` 3 m → −3.7° at 8 m/s and 3 °/s. Centripetal
    acceleration at O: V ψ̇ = 0.42 m/s².

    Sensors (``noise=0`` makes all of them, and the GNSS, error-free): gyro white noise
    ``gyro_noise_deg_s_rthz`` 0.005 °/s/√Hz, constant bias uniform in ±``gyro_bias_deg_s`` 0.5 °/s per axis plus
    a random walk ``gyro_bias_rw_deg_s`` 0.002 °/s/√s, 16-bit ±250 °/s; accelerometer white noise
    ``accel_noise_ug`` 400 µg/√Hz, constant bias uniform in ±``accel_bias_mg`` 2 mg per axis (a lateral bias
    b is a tilt error b/g no filter can remove: 2 mg ≈ 0.11°) plus a random walk ``accel_bias_rw`` 1e-5
    m/s²/√s, 16-bit ±4 g; magnetometer (``mag=1``) HMC5883L class in a 50 µT Earth field, inclination 60°,
    declination 0°. GNSS: ``sog`` (m/s) and ``cog`` (deg) of O's horizontal velocity (sway included; as from
    a receiver with lever-arm compensation), fixes at ``gnss_rate_hz`` 1 Hz held until the next fix, with
    white noise of ``gnss_vel_noise_mps`` 0.05 m/s on the north and east velocity.

    More of the sea (all off by default; the defaults' output is unchanged): ``surge_m`` (peak, m) at
    ``surge_period`` (s), a translation of O along the track (its phases from a second random stream, so the
    rest of the sea stays the same); ``roll_significant_deg`` > 0 scales the wave roll to that significant
    amplitude 2σ (deg) instead of the peak ``roll_deg`` (``meta["roll_peak_deg"]`` then gives the peak).
    The ship's own speed, ``speed_source``: ``gnss`` (above), ``smoothed`` (the receiver's track: the ship's
    speed ``speed_mps`` along the course, no sway, surge or yaw in it, same fix rate and noise), ``log`` (no
    GNSS columns; ``meta["log_speed_mps"]`` is the log's constant speed through the water) or ``none``.
    ``gnss_columns``: ``sog_cog`` (default), ``vel`` (``vel_n``, ``vel_e`` m/s, NED, held like sog/cog) or
    ``both``. ``antenna_arm`` "x,y,z" (m, body FRD from O): the GNSS velocity is the antenna's, O's plus
    R (ω × r_a) — what a receiver without lever-arm compensation reports; default: O's.

    Truth: ``ref_roll/ref_pitch/ref_heading`` (deg), ``ref_q`` (body→NED), ``ref_gyro`` (rad/s),
    ``ref_gyro_bias``, ``ref_accel`` (error-free specific force at the sensor), ``ref_mag``, ``ref_sog``
    (m/s), ``ref_cog`` (deg), ``ref_rate_of_turn`` (deg/s, heading rate), ``ref_heave`` (m, up, at O),
    ``ref_pos``/``ref_vel`` (NED m, m/s, of the sensor; origin O at t = 0) and ``ref_lever_accel``
    (ω̇ × r + ω × (ω × r), body m/s²). ``meta["lever_arm_m"]`` = r (frame body FRD, from O).
    """
    duration = 600.0 if duration is None else float(duration)
    rate_hz = 100.0 if rate_hz is None else float(rate_hz)
    if duration <= 0 or rate_hz <= 0:
        raise ImutoolError("ship-at-sea: duration and rate must be positive")
    if gm_m <= 0:
        raise ImutoolError(f"ship-at-sea: gm_m must be positive (metacentric height, m), got {gm_m}")
    lever = parse_lever_arm(lever_arm)
    if speed_source not in SPEED_SOURCES:
        raise ImutoolError(f"ship-at-sea: speed_source {speed_source!r}: expected one of {', '.join(SPEED_SOURCES)}")
    if gnss_columns not in GNSS_COLUMNS:
        raise ImutoolError(f"ship-at-sea: gnss_columns {gnss_columns!r}: expected one of {', '.join(GNSS_COLUMNS)}")
    antenna = None if antenna_arm is None or antenna_arm == "" else parse_lever_arm(antenna_arm, "antenna_arm")
    for name, period in (("sway_period", sway_period), ("surge_period", surge_period)):
        if not period > 0:
            raise ImutoolError(f"ship-at-sea: {name} must be positive (s), got {period}")
    if not (np.isfinite(roll_significant_deg) and roll_significant_deg >= 0):
        raise ImutoolError(
            f"ship-at-sea: roll_significant_deg must be ≥ 0 (deg; 0 = use roll_deg), got {roll_significant_deg}"
        )
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration * rate_hz)) + 1) / rate_hz
    mo = voyage_motion(
        t,
        seed,
        rng=rng,
        roll_deg=roll_deg,
        roll_period=roll_period,
        roll_damping=roll_damping,
        pitch_deg=pitch_deg,
        pitch_period=pitch_period,
        heave_m=heave_m,
        heave_period=heave_period,
        sway_m=sway_m,
        sway_period=sway_period,
        surge_m=surge_m,
        surge_period=surge_period,
        roll_significant_deg=roll_significant_deg,
        yaw_deg=yaw_deg,
        yaw_period=yaw_period,
        severity=severity,
        heading_deg=heading_deg,
        speed_mps=speed_mps,
        turn_rate_dps=turn_rate_dps,
        turn_start=turn_start,
        turn_angle_deg=turn_angle_deg,
        turn_ramp=turn_ramp,
        gm_m=gm_m,
        heel_arm_m=heel_arm_m,
        components=components,
    )
    pos_s, vel_s, acc_s = mo.sensor_track(lever)

    # sensor error models: bias draws happen whether or not noise is on, so the sea stays the same
    gbias = np.radians(rng.uniform(-gyro_bias_deg_s, gyro_bias_deg_s, 3))
    abias = rng.uniform(-1.0, 1.0, 3) * accel_bias_mg * 1e-3 * GRAVITY
    if noise:
        gerr = SensorErrors(**{**MPU6050_GYRO.__dict__})
        gerr.bias, gerr.bias_rw = gbias, np.radians(gyro_bias_rw_deg_s)
        gerr.noise_density = np.radians(gyro_noise_deg_s_rthz)
        aerr = SensorErrors(**{**MPU6050_ACCEL.__dict__})
        aerr.full_range = 4 * GRAVITY
        aerr.quantum = 2 * aerr.full_range / 65536
        aerr.noise_density = accel_noise_ug * 1e-6 * GRAVITY
        aerr.bias, aerr.bias_rw = abias, accel_bias_rw
        merr = HMC5883L_MAG
    else:
        gerr, aerr, merr = SensorErrors(), SensorErrors(), SensorErrors()
    fld = earth_field_ned(50.0, mag_inclination_deg, mag_declination_deg)
    c = speed_mps * heel_arm_m / (GRAVITY * gm_m)
    meta = {
        "scenario": "ship-at-sea",
        "lever_arm_m": lever.tolist(),
        "lever_arm_frame": "body FRD, sensor relative to the hull reference point (centre of rotation), m",
        "sea_spectrum": f"2nd-order response to white excitation, band {_BAND[0]}-{_BAND[1]} wn; "
        f"roll zeta {roll_damping}, others {_BROAD_DAMPING}; peaks scaled to the options",
        "roll_peak_deg": roll_deg * severity,
        "roll_period_s": roll_period,
        "roll_significant_amplitude_deg": round(float(2 * np.degrees(np.std(mo.euler[0, 0] - mo.heel))), 3),
        "pitch_peak_deg": pitch_deg * severity,
        "heave_peak_m": heave_m * severity,
        "sway_peak_m": sway_m * severity,
        "yaw_peak_deg": yaw_deg * severity,
        "speed_mps": speed_mps,
        "turn_rate_dps": turn_rate_dps,
        "turn_start_s": turn_start,
        "turn_angle_deg": turn_angle_deg,
        "turn_heel_deg": round(float(np.degrees(-np.arctan(c * np.radians(turn_rate_dps)))), 3),
        "centripetal_m_s2": round(float(speed_mps * abs(np.radians(turn_rate_dps))), 4),
        "noise": int(bool(noise)),
        "gyro_bias_rad_s": np.asarray(gerr.bias, dtype=float).tolist() if noise else [0.0, 0.0, 0.0],
        "accel_bias_m_s2": np.asarray(aerr.bias, dtype=float).tolist() if noise else [0.0, 0.0, 0.0],
        "mag_field_ned_uT": fld.tolist(),
        "gnss": f"sog/cog of the hull reference point at {gnss_rate_hz} Hz, held between fixes",
        "ref_pos_origin": "hull reference point at t=0 (NED, m); ref_pos/ref_vel are the sensor's",
    }
    # options away from their defaults are recorded; the defaults' metadata stays as it was
    if surge_m != 0:
        meta["surge_peak_m"] = surge_m * severity
        meta["surge_period_s"] = surge_period
    if roll_significant_deg > 0:
        meta["roll_significant_target_deg"] = roll_significant_deg * severity
        meta["roll_peak_deg"] = round(float(np.degrees(np.abs(mo.euler[0, 0] - mo.heel).max())), 3)
    if speed_source != "gnss" or gnss_columns != "sog_cog" or antenna is not None:
        meta["speed_source"] = speed_source
        meta["gnss"] = {
            "gnss": f"velocity of the {'antenna' if antenna is not None else 'hull reference point'} at "
            f"{gnss_rate_hz} Hz, held between fixes, columns {gnss_columns}",
            "smoothed": f"the receiver's track (speed_mps along the course, no sway or surge) at {gnss_rate_hz} Hz, "
            f"held between fixes, columns {gnss_columns}",
            "log": f"no GNSS; the log's constant speed through the water, log_speed_mps = {speed_mps}",
            "none": "no GNSS and no log: the ship's velocity is unknown",
        }[speed_source]
        if antenna is not None:
            meta["antenna_arm_m"] = antenna.tolist()
        if speed_source == "log":
            meta["log_speed_mps"] = speed_mps
    rec = imu_recording(
        t,
        mo.q,
        acc_s,
        rng,
        gyro_errors=gerr,
        accel_errors=aerr,
        mag_errors=merr if mag else None,
        field_ned=fld,
        gyro_true=mo.omega,
        meta=meta,
    )

    # GNSS: fixes at k / gnss_rate_hz, zero-order hold until the next fix
    vh = mo.vel[:, :2]  # O's horizontal velocity: ref_sog / ref_cog
    if gnss_rate_hz > 0:
        fix = np.searchsorted(t, np.floor(t * gnss_rate_hz + 1e-9) / gnss_rate_hz - 1e-9, side="left")
    else:
        fix = np.zeros(len(t), dtype=int)
    if speed_source == "smoothed":  # the receiver's track: along the course at the ship's speed, no sway or surge
        va = speed_mps * np.stack([np.cos(mo.course), np.sin(mo.course)], axis=1)
    elif antenna is not None:  # the antenna's own velocity, O's plus R (ω × r_a)
        va = mo.sensor_track(antenna)[1][:, :2]
    else:
        va = vh
    vf = va + (rng.normal(0.0, gnss_vel_noise_mps, va.shape) if noise and gnss_vel_noise_mps > 0 else 0.0)
    if speed_source in ("gnss", "smoothed") and gnss_columns in ("sog_cog", "both"):
        rec.add("sog", np.hypot(vf[:, 0], vf[:, 1])[fix], "m/s")
        rec.add("cog", np.mod(np.degrees(np.arctan2(vf[:, 1], vf[:, 0])), 360.0)[fix], "deg")
    if speed_source in ("gnss", "smoothed") and gnss_columns in ("vel", "both"):
        rec.add("vel_n", vf[fix, 0], "m/s")
        rec.add("vel_e", vf[fix, 1], "m/s")
    rec.add("ref_sog", np.hypot(vh[:, 0], vh[:, 1]), "m/s")
    rec.add("ref_cog", np.mod(np.degrees(np.arctan2(vh[:, 1], vh[:, 0])), 360.0), "deg")
    rec.add("ref_rate_of_turn", np.degrees(mo.euler[2, 1]), "deg/s")
    rec.add("ref_heave", mo.heave, "m")
    rec.add("ref_pos", pos_s, "m")
    rec.add("ref_vel", vel_s, "m/s")
    rec.add("ref_lever_accel", mo.lever_accel(lever), "m/s^2")
    rec.meta["heave_convention"] = "ref_heave m positive UP at the hull reference point"
    return rec
