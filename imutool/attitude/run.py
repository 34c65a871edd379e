"""Running the EKF over arrays: initial state, chunks, the result (:func:`run_ekf`, :class:`AttitudeResult`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from formats.errors import ImutoolError
from formats.frames import euler_to_quat, quat_rotate, quat_to_euler, quat_to_matrix
from imutool.attitude.kernel import ekf_kernel
from imutool.attitude.layout import (
    S_B,
    S_BIASMAX,
    S_DQ,
    S_HLAST,
    S_MNORM,
    S_MREF,
    S_MREF_N,
    S_NAREJ,
    S_NGAPS,
    S_NGNAN,
    S_NHINC,
    S_NHREJ,
    S_NINC,
    S_NMNEW,
    S_NMREJ,
    S_NREST,
    S_NTILT,
    S_NUPD,
    S_P,
    S_Q,
    S_QI,
    S_TILTMAX,
    S_VA_LAST,
    STATE_SIZE,
)
from imutool.attitude.params import EkfCoefficients, EkfParams
from imutool.progress import Progress, chunk_ranges

# ================================================ Python API ================================================


@dataclass
class AttitudeResult:
    """Per-sample EKF output (SI: q body→NED, bias rad/s, σ rad) and the run summary."""

    time: np.ndarray
    q: np.ndarray
    bias: np.ndarray
    std: np.ndarray  # (N,3) roll/pitch/heading σ, rad
    flags: np.ndarray  # (N,) bit mask F_*
    summary: dict = field(default_factory=dict)
    cov: np.ndarray | None = None  # (N,6,6) posterior P when kept (smoother input)
    force: np.ndarray | None = None  # (N,3) compensated specific force fed to the low-pass, m/s² body (smoother input)

    def euler_deg(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r, p, h = quat_to_euler(self.q)
        return np.degrees(r), np.degrees(p), np.degrees(h)


def _first_finite_row(*arrays: np.ndarray) -> int:
    """Index of the first row finite in every array (−1: none), scanning in growing blocks (O(1) on good data)."""
    n = min(len(a) for a in arrays)
    i0, step = 0, 1024
    while i0 < n:
        i1 = min(n, i0 + step)
        ok = np.ones(i1 - i0, bool)
        for a in arrays:
            ok &= np.isfinite(a[i0:i1]).reshape(i1 - i0, -1).all(axis=1)
        hit = np.flatnonzero(ok)
        if hit.size:
            return i0 + int(hit[0])
        i0, step = i1, step * 4
    return -1


def nominal_dt(t: np.ndarray) -> float:
    """Median positive time step (s) — over at most ~200 000 evenly spread steps (exact for shorter series)."""
    i = np.arange(0, len(t) - 1, max(1, (len(t) - 1) // 200_000))
    d = t[i + 1] - t[i]
    d = d[d > 0]
    return float(np.median(d)) if d.size else 0.01


def mag_interval(t: np.ndarray, mag: np.ndarray | None) -> float | None:
    """The magnetometer's own sample interval (s) from the steps between its finite rows (a magnetometer slower than
    the IMU leaves NaN rows between its samples): their median, or where more than a tenth of them differ from it
    (a rate that does not divide the IMU's) their mean without gaps (steps over 3× the median); over the first
    block of rows that has some (4096 rows, then 4× larger blocks: cheap on a day of samples); None where it has
    fewer than two finite rows."""
    if mag is None:
        return None
    i0, step, n = 0, 4096, len(t)
    while i0 < n:
        i1 = min(n, i0 + step)
        ok = np.flatnonzero(np.isfinite(mag[i0:i1]).all(axis=1))
        if ok.size >= 2:
            d = np.diff(np.asarray(t[i0:i1])[ok])
            d = d[d > 0]
            if d.size:
                med = float(np.median(d))
                # steps of mixed lengths (a 70 Hz magnetometer on 100 Hz rows steps 0.01 and 0.02 s): their mean
                # without gaps; else the median, exact whatever a lost row (so a stream's first chunk gives the
                # same as the whole file)
                mixed = np.mean(np.abs(d - med) > 0.01 * med) > 0.1
                return float(np.mean(d[d <= 3.0 * med])) if mixed else med
        i0, step = i1, step * 4
    return None


def initial_state(
    accel: np.ndarray, mag: np.ndarray | None, params: EkfParams, heading: float | None = None
) -> np.ndarray:
    """State vector from the first valid accel (roll/pitch) and mag (heading, reference field) samples; an
    external true ``heading`` (rad) instead of the magnetometer's (σ ``init_heading_sigma_deg`` either way)."""
    st = np.zeros(STATE_SIZE)
    i_acc = _first_finite_row(accel)
    if i_acc < 0:
        raise ImutoolError("no valid accelerometer sample to initialise the attitude")
    a = accel[i_acc]
    if not np.any(np.linalg.norm(accel[i_acc : i_acc + 100_000], axis=1) > 0):
        raise ImutoolError("the accelerometer reads exactly zero: no specific force to level the attitude with")
    roll = np.arctan2(-a[1], -a[2])
    pitch = np.arctan2(a[0], np.hypot(a[1], a[2]))
    heading_mag = 0.0
    mref = np.array([np.cos(np.radians(60)), 0.0, np.sin(np.radians(60))])
    mnorm = 0.0
    if mag is not None:
        i = _first_finite_row(mag, accel)
        if i >= 0:
            a = accel[i]
            roll = np.arctan2(-a[1], -a[2])
            pitch = np.arctan2(a[0], np.hypot(a[1], a[2]))

            m = mag[i]
            mw = quat_rotate(euler_to_quat(roll, pitch, 0.0), m)
            heading_mag = np.arctan2(-mw[1], mw[0])
            mnorm = float(np.linalg.norm(m))
            hor = np.hypot(mw[0], mw[1])
            if mnorm > 0:
                mref = np.array([hor, 0.0, mw[2]]) / mnorm
            else:  # a zero field: no heading, no reference (the updates skip a zero-norm field)
                heading_mag, mnorm = 0.0, 0.0
    st[S_Q : S_Q + 4] = euler_to_quat(roll, pitch, heading_mag if heading is None else float(heading))
    st[S_B : S_B + 3] = params.init_bias
    P = np.zeros((6, 6))
    rp = np.radians(params.init_roll_pitch_sigma_deg) ** 2
    P[0, 0] = P[1, 1] = rp
    P[2, 2] = np.radians(params.init_heading_sigma_deg) ** 2  # a first fix may be a glitch: the filter stays open
    # express the NED-axis σ in body axes (heading σ is about the world vertical)
    Rm = quat_to_matrix(st[S_Q : S_Q + 4])
    P[:3, :3] = Rm.T @ P[:3, :3] @ Rm
    P[3:, 3:] = np.eye(3) * params.init_bias_sigma**2
    st[S_P : S_P + 36] = P.ravel()
    st[S_MREF : S_MREF + 3] = mref
    st[S_MNORM] = mnorm
    st[S_MREF_N] = 1.0 if mnorm > 0 else 0.0
    st[S_DQ] = 1.0
    st[S_QI] = 1.0
    st[S_HLAST] = -np.inf
    st[S_VA_LAST], st[S_VA_LAST + 1] = np.nan, np.nan  # the first finite velocity is a fix
    return st


def _gnss_arrays(
    time: np.ndarray, sog: np.ndarray | None, cog_deg: np.ndarray | None, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    if sog is None:
        z = np.full(n, np.nan)
        return z, z, z, False
    sog = np.asarray(sog, float)
    cog = np.full(n, np.nan) if cog_deg is None else np.radians(np.asarray(cog_deg, float))
    # tangential acceleration: derivative of SOG across GNSS fixes (held values: use the change points)
    ok = np.isfinite(sog)
    sogdot = np.zeros(n)
    if ok.sum() > 2:
        ts, vs = time[ok], sog[ok]
        chg = np.concatenate([[True], np.diff(vs) != 0])
        if chg.sum() > 2:
            tf, vf = ts[chg], vs[chg]
            sogdot = np.interp(time, tf, np.gradient(vf, tf))
    return sog, cog, sogdot, True


def _arms(lever_arm: np.ndarray | None, antenna_arm: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The lever arm (3,) m body FRD of the sensor from the centre of rotation, and the sensor's position from the
    GNSS antenna's (lever − antenna arm); zeros where not given."""
    lever = np.zeros(3) if lever_arm is None else np.asarray(lever_arm, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(lever)):
        raise ImutoolError("the lever arm must be three finite numbers (m, body FRD)")
    ant = np.zeros(3) if antenna_arm is None else np.asarray(antenna_arm, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(ant)):
        raise ImutoolError("the antenna arm must be three finite numbers (m, body FRD)")
    return lever, lever - ant


def _summary(st: np.ndarray, n: int, every: int, gnss: bool, aiding: bool, heading_input: bool) -> dict:
    """The run's counts from the state's counters (layout.py S_N*), as :attr:`AttitudeResult.summary` has them."""
    summary = {
        "samples": n,
        "updates": int(st[S_NUPD]),
        "update_every": every,
        "accel_rejected": int(st[S_NAREJ]),
        "mag_rejected": int(st[S_NMREJ]),
        "mag_new_field": int(st[S_NMNEW]),
        "rest_samples": int(st[S_NREST]),
        "gaps": int(st[S_NGAPS]),
        "gyro_nan_samples": int(st[S_NGNAN]),
        "gnss_compensation": gnss,
        "velocity_aiding": aiding,
        "inconsistent_samples": int(st[S_NINC]),
        "heading_inconsistent_samples": int(st[S_NHINC]),
        "tilt_check_samples": int(st[S_NTILT]),
        "tilt_check_max_deg": round(float(np.degrees(np.arctan(np.sqrt(st[S_TILTMAX])))), 2),
    }
    if heading_input:
        summary["heading_input_rejected"] = int(st[S_NHREJ])
    return summary


def _rows(x: np.ndarray | None, n: int, k: int, name: str) -> np.ndarray:
    """An optional (n, k) float64 input of the kernel, contiguous; (0, k) where not given."""
    if x is None:
        return np.empty((0, k))
    x = np.ascontiguousarray(x, dtype=np.float64)
    if x.shape != (n, k):
        raise ImutoolError(f"{name} must be ({n}, {k}), not {x.shape}")
    return x


def _start_state(
    state: np.ndarray | None, accel: np.ndarray, mag: np.ndarray | None, hdg: np.ndarray, params: EkfParams
) -> np.ndarray:
    """The state the kernel starts from (a copy): ``state`` carried from a previous chunk, or :func:`initial_state`."""
    if state is None:  # the initial heading: a fix within 100 samples of the first valid accelerometer row (the
        # same in memory and streamed); later fixes pull the heading in through the filter's updates
        i_acc = _first_finite_row(accel)
        near = hdg[max(i_acc, 0) : max(i_acc, 0) + 100] if len(hdg) else hdg
        first = np.flatnonzero(np.isfinite(near))
        state = initial_state(accel, mag, params, float(near[first[0]]) if len(first) else None)
    st = np.array(state, dtype=np.float64)
    if st.shape != (STATE_SIZE,):  # the kernel indexes it unchecked
        raise ImutoolError(f"an EKF state must have {STATE_SIZE} entries, not {st.shape} (from another release?)")
    return st


class EkfStepper:
    """The EKF advanced block by block with its state carried and its set-up done once: the one code path of
    :func:`run_ekf` (one block), the streamed ``filter`` (a block per chunk) and ``imutool live`` (a block of a
    few samples). Fed the same rows in any blocks it gives the same output to the last bit, provided the sample
    intervals are fixed up front (``dt_nominal``, ``dt_mag``: given, or taken from the first block) and the
    SOG derivative (the turn's tangential term) is not differentiated across blocks (it is taken within each
    block, as a stream always did; pass ``sogdot`` to supply it).

    ``heading_held`` (None: decided per block from its rows, as :func:`run_ekf` does) fixes whether a heading is
    held (a magnetometer or an external heading), which lets the GNSS velocity be turned into body axes.
    ``state`` continues a previous run. Units as :func:`run_ekf`.
    """

    def __init__(
        self,
        params: EkfParams | None = None,
        *,
        dt_nominal: float | None = None,
        dt_mag: float | None = None,
        lever_arm: np.ndarray | None = None,
        antenna_arm: np.ndarray | None = None,
        state: np.ndarray | None = None,
        keep_cov: bool = False,
        keep_force: bool = False,
        cov_every_sample: bool | None = None,
        heading_held: bool | None = None,
    ) -> None:
        self.params = params or EkfParams()
        self.dt_nominal, self.dt_mag = dt_nominal, dt_mag
        self.lever, self.arm_sa = _arms(lever_arm, antenna_arm)
        self.state = None if state is None else np.array(state, dtype=np.float64)
        self.keep_cov, self.keep_f = keep_cov, keep_cov or keep_force
        self.cov_each = keep_cov if cov_every_sample is None else cov_every_sample
        self.heading_held = heading_held
        self.samples = 0
        self._coef: tuple | None = None  # (every, prm, mag mode code) once the intervals are known
        self._flags = (False, False, False)  # gnss, aiding, heading input: the summary's

    def _setup(self, t: np.ndarray, m: np.ndarray, use_mag: bool) -> tuple:
        if use_mag and self.dt_mag is None:  # the magnetometer's interval from the first block that has one
            self.dt_mag = mag_interval(t, m)
            self._coef = None if self.dt_mag is not None else self._coef
        if self._coef is None:
            if self.dt_nominal is None:
                self.dt_nominal = nominal_dt(t)
            coef = EkfCoefficients.derive(self.params, self.dt_nominal, self.dt_mag)  # once per run
            self._coef = (coef.samples_per_update, coef.kernel_vector(self.params), coef.mag_mode_code)
        return self._coef

    def step(
        self,
        time: np.ndarray,
        gyro: np.ndarray,
        accel: np.ndarray,
        mag: np.ndarray | None = None,
        sog: np.ndarray | None = None,
        cog_deg: np.ndarray | None = None,
        *,
        heading_deg: np.ndarray | None = None,
        velocity_ne: np.ndarray | None = None,
        accel_measurement: np.ndarray | None = None,
        progress: Progress | None = None,
    ) -> AttitudeResult:
        """Advance over one block of rows (SI, as :func:`run_ekf`); returns the block's per-sample output with the
        run's counters so far in its summary. The state is carried in ``self.state``."""
        params = self.params
        t = np.ascontiguousarray(time, dtype=np.float64)
        n = len(t)
        g = np.ascontiguousarray(gyro, dtype=np.float64)
        a = np.ascontiguousarray(accel, dtype=np.float64)
        if heading_deg is None:
            hdg = np.empty(0)
        else:
            hdg = np.radians(np.asarray(heading_deg, dtype=np.float64))
            if hdg.shape != (n,):
                raise ImutoolError(f"heading_deg must be ({n},), not {hdg.shape}")
            mag = None  # a gyrocompass heading, not the magnetometer's
        use_mag = mag is not None and params.mag_mode != "off"
        m = np.ascontiguousarray(mag, dtype=np.float64) if mag is not None else np.full((n, 3), np.nan)
        if self.state is None:
            self.state = _start_state(None, a, m if use_mag else None, hdg, params)
            self.state[S_BIASMAX] = params.bias_max
        elif self.state.shape != (STATE_SIZE,):  # the kernel indexes it unchecked
            raise ImutoolError(
                f"an EKF state must have {STATE_SIZE} entries, not {self.state.shape} (from another release?)"
            )
        every, prm, mode = self._setup(t, m, use_mag)
        mode = mode if use_mag else 0
        st = self.state
        st[S_BIASMAX] = params.bias_max
        sg, cg, sd, use_gnss = _gnss_arrays(t, sog, cog_deg, n)
        held = self.heading_held
        if held is None:  # a heading held in this block (magnetometer or external)
            held = bool(len(hdg) and np.isfinite(hdg).any()) or bool(use_mag and np.isfinite(m).all(axis=1).any())
        # a speed without a course (the log's, --speed) is along the bow too
        gnss_code = np.int64(0 if not use_gnss else (1 if held and cog_deg is not None else 2))
        vel = _rows(velocity_ne if held else None, n, 2, "velocity_ne")
        q_out = np.empty((n, 4))
        b_out = np.empty((n, 3))
        std_out = np.empty((n, 3))
        flags = np.zeros(n, dtype=np.uint16)
        keep_cov, keep_f = self.keep_cov, self.keep_f
        p_store = np.empty((n, 6, 6)) if keep_cov else np.empty((0, 6, 6))
        f_out = np.full((n, 3), np.nan) if keep_f else np.empty((0, 3))
        meas = _rows(accel_measurement, n, 3, "accel_measurement")
        cov_flag = bool(self.cov_each or every == 1)
        # one kernel call, or blocks of ~0.26 M samples when progress is reported (the state carries over exactly)
        for i0, i1 in [(0, n)] if progress is None else chunk_ranges(n, 1 << 18, progress):
            ekf_kernel(  # None for an input not given: its section is not compiled in (kernel.py)
                t[i0:i1], g[i0:i1], a[i0:i1], m[i0:i1], sg[i0:i1] if gnss_code else None, cg[i0:i1], sd[i0:i1],
                vel[i0:i1] if len(vel) else None, prm, every, mode, cov_flag, gnss_code, self.lever, self.arm_sa, st,
                q_out[i0:i1], b_out[i0:i1], std_out[i0:i1], flags[i0:i1], p_store[i0:i1] if keep_cov else p_store,
                meas[i0:i1] if len(meas) else meas, f_out[i0:i1] if keep_f else f_out, hdg[i0:i1] if len(hdg) else None,
            )  # fmt: skip
        self.samples += n
        self._flags = (
            self._flags[0] or bool(use_gnss or len(vel)),
            self._flags[1] or bool(len(vel)),
            self._flags[2] or bool(len(hdg)),
        )
        summary = _summary(st, self.samples, every, *self._flags)
        return AttitudeResult(
            t, q_out, b_out, std_out, flags, summary, p_store if keep_cov else None, f_out if keep_f else None
        )

    def counters(self) -> dict:
        """The run's counters so far (updates, rejections, gaps, self-check samples...)."""
        if self.state is None or self._coef is None:
            return {"samples": self.samples}
        return _summary(self.state, self.samples, self._coef[0], *self._flags)


def run_ekf(
    time: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    mag: np.ndarray | None = None,
    params: EkfParams | None = None,
    sog: np.ndarray | None = None,
    cog_deg: np.ndarray | None = None,
    state: np.ndarray | None = None,
    keep_cov: bool = False,
    dt_nominal: float | None = None,
    cov_every_sample: bool | None = None,
    lever_arm: np.ndarray | None = None,
    progress: Progress | None = None,
    accel_measurement: np.ndarray | None = None,
    keep_force: bool = False,
    heading_deg: np.ndarray | None = None,
    dt_mag: float | None = None,
    velocity_ne: np.ndarray | None = None,
    antenna_arm: np.ndarray | None = None,
) -> tuple[AttitudeResult, np.ndarray]:
    """Run the EKF over arrays (SI units, see module docstring). Returns (result, state for the next chunk).
    One block of an :class:`EkfStepper`.

    ``state`` continues a previous chunk (streaming). ``keep_cov`` stores P per sample (needed by
    :func:`rts_smooth`; 288 bytes/sample) and the compensated specific force (:func:`zero_lag_smooth`; 24
    bytes/sample); ``keep_force`` keeps the force alone (:mod:`imutool.gyro_check`). GNSS compensation is used when
    ``sog`` (m/s) and ``cog_deg`` are given; ``sog`` alone (a log's speed through the water) is taken along the bow
    (the turn's centripetal acceleration, speed × the gyro's rate about the vertical).
    ``accel_measurement`` (N,3) m/s² body replaces the filter's causal low-pass as the accelerometer measurement
    (:func:`zero_lag_smooth`'s second pass).
    ``heading_deg`` (N,) an external true heading (gyrocompass; deg, NaN where none): when given, it is the
    heading measurement and the magnetometer is not used.
    ``velocity_ne`` (N,2) m/s: the GNSS antenna's north/east velocity (held, interpolated or NaN between fixes;
    a fix is a row where it changes), for velocity aiding: the low-pass then takes the force of each interval
    between fixes less the velocity's change, which removes sway, surge and turn alike; ``antenna_arm`` (3,) m
    body FRD, the antenna's position from the centre of rotation (default: the velocity is the centre's, as a
    receiver with lever-arm compensation gives it).
    ``dt_mag`` (s) the magnetometer's own sample interval, which sets its σ per sample from
    ``mag_heading_density`` (default: :func:`mag_interval` of these rows; a stream passes its first chunk's).
    """
    stepper = EkfStepper(
        params,
        dt_nominal=dt_nominal,
        dt_mag=dt_mag,
        lever_arm=lever_arm,
        antenna_arm=antenna_arm,
        state=None if state is None else _checked_state(state),
        keep_cov=keep_cov,
        keep_force=keep_force,
        cov_every_sample=cov_every_sample,
    )
    res = stepper.step(
        time, gyro, accel, mag, sog, cog_deg, heading_deg=heading_deg, velocity_ne=velocity_ne,
        accel_measurement=accel_measurement, progress=progress,
    )  # fmt: skip
    res.summary["samples"] = len(res.time)
    return res, stepper.state


def _checked_state(state: np.ndarray) -> np.ndarray:
    st = np.array(state, dtype=np.float64)
    if st.shape != (STATE_SIZE,):  # the kernel indexes it unchecked
        raise ImutoolError(f"an EKF state must have {STATE_SIZE} entries, not {st.shape} (from another release?)")
    return st


def euler_std(q: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Roll/pitch/heading σ (N,3) rad from body-frame attitude covariances P[:, :3, :3] (δ(φ,θ,ψ) = E δθ)."""
    roll, pitch, _ = quat_to_euler(q)
    cp = np.maximum(np.cos(pitch), 1e-6)
    sr, cr, tp = np.sin(roll), np.cos(roll), np.tan(pitch)
    E = np.zeros((len(q), 3, 3))
    E[:, 0, 0] = 1.0
    E[:, 0, 1] = sr * tp
    E[:, 0, 2] = cr * tp
    E[:, 1, 1] = cr
    E[:, 1, 2] = -sr
    E[:, 2, 1] = sr / cp
    E[:, 2, 2] = cr / cp
    C = np.einsum("nij,njk,nlk->nil", E, P[:, :3, :3], E)
    return np.sqrt(np.maximum(np.stack([C[:, 0, 0], C[:, 1, 1], C[:, 2, 2]], axis=1), 0.0))
