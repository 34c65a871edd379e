"""Heave from acceleration: the Kalman multi-step observer of the heave paper, a real-time output with its phase
lead cancelled per harmonic, a delayed zero-phase output, and the two baselines the paper compares against.

Conventions: heave in metres, **positive UP**; heave rate m/s positive up; vertical acceleration m/s² positive
up (gravity and its constant part removed; any constant residue is treated as accelerometer bias). Body frame
FRD, world NED (so heave = −down). Times in s, frequencies in Hz unless named ``omega`` (rad/s).

Methods (``estimate_heave(method=...)``):

- ``bandpass`` (causal baseline): G(s) = HPₙ(s)/s², an n-th order Butterworth high-pass (cut-off f_c) merged with
  the double integrator, discretised bilinearly. Drift-free but with the phase lead of the high-pass.
- ``envelope`` (the paper's "traditional" method, offline): low-pass, double integration, then the drift trend
  = mid-line of the upper/lower envelopes (splines through maxima/minima) is subtracted.
- ``paper`` (heave paper §2): dominant frequencies from the spectrum of the double-integrated displacement
  (Hann-windowed FFT on a sliding window, causal, re-estimated every ``hop_s``); state
  x = [h₁, ḣ₁, …, hₙ, ḣₙ, Δh], F = blockdiag([[0, 1], [−ωᵢ², 0]], 0) (eq. 5), H = [1 0 1 0 … 1], Φ = e^{FT}
  (eq. 6, scipy.linalg.expm), standard Kalman filter on the band-passed displacement, and the multi-step
  observation X(k+m) = F^m X̂(k) with m = φ/(ωT) (§2.2) where φ is the phase lead of the band-pass at the
  dominant frequency. Note on the paper: a *lead* is cancelled by stepping *back* (m = −φ/(ωT), equivalently
  forward by (2π − φ)/(ωT)); §2.2 writes m = φ/(ωT) with a forward step, which would double the lead. The lead
  here is computed from the known filter response, not from the reference (the paper compared with the laser).
- ``harmonic`` (this project's refinement of ``paper``; the real-time default before issue 17): oscillator
  frequencies at the energy centroids of the tracked spectrum, the residual Δh not output (it carries the drift),
  and each harmonic rotated and re-scaled by its own exact filter response: X̂ᵢ ← e^{Fᵢ(−φᵢ/ωᵢ)} X̂ᵢ / |G(ωᵢ)|.
- ``realtime`` (default): a bank of phase-corrected double integrators (:func:`corrected_integrator`: gain and
  phase error O((f_c/f)ⁿ⁻²) instead of a high-pass's O(f_c/f) lead), blended at the corner that follows the tracked
  heave frequency (:func:`heave_realtime`); on a line spectrum (regular waves, spread ν ≤ 0.08) the ``harmonic``
  KF instead. ≤ 5 % of Hs RMS over Hs 1–4 m × Tp 5–15 s (docs/heave.md).
- delayed heave (every method): zero-phase — X(f) = −A(f)·W(f)/(2πf)² with W a zero-phase Butterworth
  high-pass magnitude — exact phase, only gain |W| ≈ 1 in the wave band; its latency is the time the non-causal
  impulse response needs to decay below 1 % (reported as ``delayed_latency_s``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import signal
from scipy.interpolate import CubicSpline
from scipy.linalg import expm

import formats
import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats import Recording
from formats.errors import ImutoolError
from formats.frames import quat_to_matrix
from formats.jit.decorators import njit
from formats.jit.warm import Entry
from imutool.loading import input_notes
from imutool.metrics import best_lag, error_stats, interp_to

GRAVITY = 9.80665
METHODS = ("realtime", "harmonic", "paper", "bandpass", "envelope")
GNSS_METHOD = "gnss"  # run_heave only: the detrended GNSS height (imutool.gnss_heave), no accelerometer
ROUTE_METHODS = METHODS + (GNSS_METHOD,)
CUTOFF_METHODS = ("bandpass", "paper", "harmonic")  # the methods with a causal band-pass at ``cutoff``
TILT_GAIN = 0.07  # 1/s: tilt-filter gain (+ integral gyro-bias term gain²/4: a critically damped PI loop)
RT_ORDER = 6  # real-time corrected integrator: order,
RT_RATIO = 0.3  # corner as a fraction of the tracked dominant frequency,
RT_SMOOTH_PERIODS = 5.0  # smoothing of the corner (time constant in tracked periods),
RT_WINDOW_S = 240.0  # s, frequency-tracking window of the real-time method,
RT_SHORT_WINDOW_S = 90.0  # s, the quick look for a change of sea,
RT_CHANGE = 0.4  # relative disagreement of the two looks that marks a change of sea,
RT_SPREAD = (0.08, 0.10)  # spectral spread ν: ≤ first → harmonic KF (line spectrum), ≥ second → bank,
RT_SHAPE = "butterworth"  # and pole pattern (chosen on the whole benchmark grid, see docs/heave.md)
# honest `settled` of the real-time heave (issue 48, docs/heave.md "settled and heave_std"):
RT_STD_CORNER = 2**0.5  # the check integrator runs at the corner / this (its error (1/√2)^(n−2) of the output's),
RT_STD_PERIODS = 2.0  # heave_std = RMS of (output − check) over this many periods (causal, exponential),
RT_SIGNAL_PERIODS = 10.0  # the signal it is compared with: 4 × the RMS heave over this many periods,
SETTLE_FRACTION = 0.1  # settled only while heave_std ≤ this × that significant heave (``settle_fraction``),
RT_ONSET = 3.0  # a one-period acceleration RMS this many times its level at the last frequency estimate: an onset
PLAUSIBILITY = 2.0  # two heaves disagreeing (RMS) beyond this × their stated σ: warned
ATTITUDES = ("auto", "q", "ekf", "tilt", "ref")  # where the vertical comes from (run_heave's attitude)
AUTO_USES_EKF = False  # --attitude auto: q columns, else the tilt filter (the EKF on request: same heave, slower)


# ------------------------------------------------------------------------------------------------------------------
# Vertical acceleration
# ------------------------------------------------------------------------------------------------------------------
@njit(cache=True)
def _complementary_kernel(dt, gyro, accel, gain, bias_gain):  # pragma: no cover - numba
    """Quaternion (body→NED) from gyro integration with a proportional-integral tilt correction toward −f
    (gravity); the integral term (``bias_gain``, 1/s²) estimates the roll/pitch gyro bias, so a constant or
    slowly drifting gyro bias leaves no standing tilt error (which would leak g·δ²/2 into the vertical)."""
    n = gyro.shape[0]
    q = np.zeros((n, 4))
    # initial roll/pitch from the first accelerometer sample (FRD reads −g on z when level)
    fx, fy, fz = accel[0, 0], accel[0, 1], accel[0, 2]
    roll = np.arctan2(-fy, -fz)
    pitch = np.arctan2(fx, np.sqrt(fy * fy + fz * fz))
    cr, sr, cp, sp = np.cos(roll / 2), np.sin(roll / 2), np.cos(pitch / 2), np.sin(pitch / 2)
    w, x, y, z = cr * cp, sr * cp, cr * sp, -sr * sp
    bx = by = bz = 0.0
    for k in range(n):
        if k > 0:
            # gravity direction predicted in body axes: "up" = third row of R(q) (down) negated
            dx = 2 * (x * z - w * y)
            dy = 2 * (y * z + w * x)
            dz = w * w - x * x - y * y + z * z
            fx, fy, fz = accel[k, 0], accel[k, 1], accel[k, 2]
            nf = np.sqrt(fx * fx + fy * fy + fz * fz)
            ex = ey = ez = 0.0
            if nf > 0.5 * 9.80665 and nf < 1.5 * 9.80665:
                # measured "down" is −f/|f|; correction = measured × predicted
                mx, my, mz = -fx / nf, -fy / nf, -fz / nf
                ex = my * dz - mz * dy
                ey = mz * dx - mx * dz
                ez = mx * dy - my * dx
            bx -= bias_gain * ex * dt[k]
            by -= bias_gain * ey * dt[k]
            bz -= bias_gain * ez * dt[k]
            # rate over the interval: mean of its end samples (a ship's roll at a few Hz sampling would
            # otherwise leave a motion-rectified tilt drift), rotation applied exactly: q ⊗ exp(ω·dt/2)
            gx = 0.5 * (gyro[k, 0] + gyro[k - 1, 0]) - bx + gain * ex
            gy = 0.5 * (gyro[k, 1] + gyro[k - 1, 1]) - by + gain * ey
            gz = 0.5 * (gyro[k, 2] + gyro[k - 1, 2]) - bz + gain * ez
            ang = np.sqrt(gx * gx + gy * gy + gz * gz) * 0.5 * dt[k]
            c = np.cos(ang)
            sc = np.sin(ang) / ang * 0.5 * dt[k] if ang > 1e-12 else 0.5 * dt[k]
            w2 = c * w - sc * (x * gx + y * gy + z * gz)
            x2 = c * x + sc * (w * gx + y * gz - z * gy)
            y2 = c * y + sc * (w * gy - x * gz + z * gx)
            z2 = c * z + sc * (w * gz + x * gy - y * gx)
            nq = np.sqrt(w2 * w2 + x2 * x2 + y2 * y2 + z2 * z2)
            w, x, y, z = w2 / nq, x2 / nq, y2 / nq, z2 / nq
        q[k, 0], q[k, 1], q[k, 2], q[k, 3] = w, x, y, z
    return q


def complementary_attitude(
    t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, gain: float = TILT_GAIN, bias_gain: float | None = None
) -> np.ndarray:
    """Simple tilt estimate q (N,4) body→NED: gyro (rad/s, FRD) integration + gravity correction (gain 1/s)
    with an integral gyro-bias term (``bias_gain`` 1/s²; default gain²/4, a critically damped loop; 0 =
    proportional only)."""
    if bias_gain is None:
        bias_gain = gain * gain / 4.0
    dt = np.diff(t, prepend=t[0])
    return _complementary_kernel(
        dt, np.ascontiguousarray(gyro, float), np.ascontiguousarray(accel, float), float(gain), float(bias_gain)
    )


def usable_orientation(q: np.ndarray) -> np.ndarray:
    """Rows of q (N, 4) that are an orientation: finite and of unit norm within 10 % (four zeros, the value of a
    driver that has none, are not)."""
    q = np.asarray(q, float)
    with np.errstate(invalid="ignore"):
        n = np.sqrt(np.sum(q * q, axis=1))
        return np.isfinite(n) & (np.abs(n - 1.0) < 0.1)


def _attitude_for(rec: Recording, attitude: str, tilt_gain: float) -> tuple[np.ndarray, str]:
    if attitude == "ref":
        if "ref_q" not in rec:
            raise ImutoolError("--attitude ref needs ref_qw..ref_qz columns")
        return rec["ref_q"], "ref_q (truth channel)"
    has_q = "q" in rec and isinstance(rec["q"], np.ndarray) and rec["q"].ndim == 2 and rec["q"].shape[1] == 4
    if attitude in ("auto", "q") and has_q:
        ok = usable_orientation(rec["q"])
        if ok.any():
            return rec["q"], "q channel of the input"
        if attitude == "q":  # all zeros (or NaN): not an orientation, whatever the columns are called
            zero = bool(np.all(np.nan_to_num(rec["q"]) == 0))
            raise ImutoolError(
                "--attitude q: the orientation (qw..qz) is "
                + ("all zeros" if zero else "nowhere a unit quaternion")
                + " — not an orientation; use --attitude auto (the tilt filter) or ekf"
            )
    if attitude == "q":
        bag = rec.meta.get("bag")
        notes = bag.get("notes") or [] if isinstance(bag, dict) else []
        if any("[0, 0, 0, 0]" in str(n) and "not read" in str(n) for n in notes):
            raise ImutoolError(
                "--attitude q: the bag's orientation field is all zeros (not filled by the driver) — not an "
                "orientation; use --attitude auto (the tilt filter) or ekf"
            )
        raise ImutoolError("--attitude q needs qw..qz columns")
    if "gyro" not in rec:
        raise ImutoolError("the vertical needs an attitude: give q columns, gyro_x..z, or --vertical COLUMN")
    if attitude == "ekf" or (attitude == "auto" and AUTO_USES_EKF):
        try:  # the attitude EKF (imutool.attitude), when present in this build
            from imutool.attitude import ekf_recording  # noqa: PLC0415

            out, _ = ekf_recording(rec)
            q = np.asarray(out["q"], float)
            if q.shape == (len(rec), 4):
                return q, "imutool.attitude EKF"
        except (ImportError, ImutoolError, KeyError) as e:
            if attitude == "ekf":
                raise ImutoolError(f"attitude EKF not usable here: {e}") from None
    return complementary_attitude(
        rec.time, rec["gyro"], rec["accel"], tilt_gain
    ), f"complementary PI tilt filter (gain {tilt_gain} 1/s, bias gain {tilt_gain**2 / 4:.3g} 1/s²)"


def vertical_acceleration(
    rec: Recording,
    columns: list[str] | None = None,
    sign: str = "up",
    attitude: str = "auto",
    lever_arm: np.ndarray | None = None,
    tilt_gain: float = TILT_GAIN,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Vertical acceleration (m/s², positive up; constant part still included) and a description.

    ``columns``: channel names of single vertical accelerometers (averaged; ``sign`` 'up' or 'down' says where
    their positive axis points). Otherwise the 3-axis ``accel`` (specific force, body FRD) is rotated to NED
    with the attitude and gravity removed: a_up = −(R f)_d − g. ``lever_arm`` (m, body FRD, from the IMU to a
    monitoring point) transfers the specific force with the rigid-body relation f_P = f + ω̇×r + ω×(ω×r) using
    the gyro rates (ω̇ by central differences).
    """
    info: dict[str, Any] = {}
    if columns:
        arrs = []
        for c in columns:
            if c not in rec:
                raise ImutoolError(f"vertical accelerometer column {c!r} not found (has {', '.join(rec.channels)})")
            a = rec[c]
            if a.ndim != 1:
                raise ImutoolError(f"vertical accelerometer {c!r} must be a single column")
            arrs.append(a)
        a = np.mean(arrs, axis=0)
        if sign not in ("up", "down"):
            raise ImutoolError(f"vertical sign must be 'up' or 'down', got {sign!r}")
        a = a if sign == "up" else -a
        if lever_arm is not None and np.any(lever_arm != 0):
            raise ImutoolError("--lever-arm needs the 3-axis IMU (accel + gyro), not single vertical columns")
        info["vertical"] = f"mean of {', '.join(columns)} (positive {sign})"
        return a, info
    if "accel" not in rec:
        raise ImutoolError("needs accel_x..accel_z (or --vertical COLUMN for a single vertical accelerometer)")
    q, how = _attitude_for(rec, attitude, tilt_gain)
    f = np.asarray(rec["accel"], float)
    if lever_arm is not None and np.any(lever_arm != 0):
        if "gyro" not in rec:
            raise ImutoolError("--lever-arm needs gyro_x..gyro_z (angular rates)")
        w = np.asarray(rec["gyro"], float)
        wdot = np.gradient(w, rec.time, axis=0)
        r = np.asarray(lever_arm, float)
        f = f + np.cross(wdot, r) + np.cross(w, np.cross(w, r))
        info["lever_arm_m"] = [float(v) for v in r]

    rm = quat_to_matrix(q)
    f_down = np.einsum("nj,nj->n", rm[:, 2, :], f)
    info["vertical"] = f"accel rotated to NED with {how}, gravity removed"
    return -(f_down + GRAVITY), info


# ------------------------------------------------------------------------------------------------------------------
# Spectra and frequency tracking
# ------------------------------------------------------------------------------------------------------------------
def displacement_spectrum(
    a: np.ndarray, fs: float, fmin: float, fmax: float, pad: int = 4
) -> tuple[np.ndarray, np.ndarray]:
    """One Hann-windowed, zero-padded periodogram of the displacement implied by acceleration a (m/s²):
    S_h(f) = S_a(f)/(2πf)⁴ for fmin ≤ f ≤ fmax (arbitrary scale). Returns (f Hz, S)."""
    x = np.asarray(a, float)
    x = x - x.mean()
    n = len(x)
    nfft = int(2 ** np.ceil(np.log2(max(16, n * pad))))
    spec = np.abs(np.fft.rfft(x * np.hanning(n), nfft)) ** 2
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    band = (f >= fmin) & (f <= fmax)
    return f[band], spec[band] / (2 * np.pi * f[band]) ** 4


def dominant_frequency(a: np.ndarray, fs: float, fmin: float = 0.03, fmax: float = 2.0) -> float | None:
    """Dominant heave frequency (Hz) of a whole record: the acceleration-spectrum peak locates the wave band
    (low-frequency accelerometer drift must not win), then the displacement-spectrum peak above 0.35 × it."""
    dec = max(1, int(fs // (5 * fmax)))
    fw, sw = displacement_spectrum(np.asarray(a, float)[::dec], fs / dec, fmin, fmax, pad=1)
    if len(fw) <= 4:
        return None
    fv = float(fw[int(np.argmax(sw * (2 * np.pi * fw) ** 4))])
    inb = fw >= 0.35 * fv
    return float(fw[inb][int(np.argmax(sw[inb]))])


def _peaks(f: np.ndarray, s: np.ndarray, n: int, min_rel: float = 0.05) -> np.ndarray:
    """The n strongest local maxima (parabolic refinement), at least 5 % of the largest, ascending."""
    if len(s) < 3:
        return np.array([f[int(np.argmax(s))]]) if len(s) else np.array([])
    idx, _ = signal.find_peaks(s)
    if len(idx) == 0:
        idx = np.array([int(np.argmax(s))])
    idx = idx[np.argsort(s[idx])[::-1]]
    idx = idx[s[idx] >= min_rel * s[idx[0]]][:n]
    out = []
    df = f[1] - f[0]
    for i in idx:
        fi = f[i]
        if 0 < i < len(s) - 1:
            y0, y1, y2 = np.log(s[i - 1] + 1e-300), np.log(s[i] + 1e-300), np.log(s[i + 1] + 1e-300)
            den = y0 - 2 * y1 + y2
            if den < 0:
                fi += 0.5 * df * (y0 - y2) / den
        out.append(fi)
    return np.sort(np.array(out))


def _centroids(f: np.ndarray, s: np.ndarray, n: int, resolution: float) -> np.ndarray:
    """Energy centroids of n equal-energy bands of the spectrum around its peak; merged when closer than
    ``resolution`` Hz (a line spectrum collapses to one frequency)."""
    if len(s) == 0:
        return np.array([])
    # keep the part of the spectrum above 2 % of the peak: the noise floor must not pull the centroids
    keep = s >= 0.02 * s.max()
    f, s = f[keep], s[keep]
    c = np.cumsum(s)
    c /= c[-1]
    edges = np.searchsorted(c, np.arange(1, n) / n, side="right")
    fs_ = np.cumsum(f * s)
    ss = np.cumsum(s)
    bounds = np.concatenate([[0], edges, [len(s)]])
    out = []
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        if hi <= lo:
            continue
        wsum = ss[hi - 1] - (ss[lo - 1] if lo > 0 else 0.0)
        fsum = fs_[hi - 1] - (fs_[lo - 1] if lo > 0 else 0.0)
        if wsum > 0:
            out.append(float(fsum / wsum))
    out = sorted(out)
    merged: list[float] = []
    for v in out:
        if merged and v - merged[-1] < resolution:
            merged[-1] = 0.5 * (merged[-1] + v)
        else:
            merged.append(v)
    return np.array(merged)


@dataclass
class Tracking:
    """Frequencies in force from sample ``start[k]`` on (Hz, NaN-padded to n columns), and the data span used."""

    start: np.ndarray
    freqs: np.ndarray
    dominant: np.ndarray
    window_s: np.ndarray = field(default_factory=lambda: np.array([]))
    median: np.ndarray = field(default_factory=lambda: np.array([]))  # Hz: half the heave energy lies below
    spread: np.ndarray = field(default_factory=lambda: np.array([]))  # ν = √(m₀m₂/m₁² − 1) of the heave band


def track_frequencies(
    t: np.ndarray,
    a: np.ndarray,
    n: int,
    window_s: float = 120.0,
    hop_s: float = 10.0,
    min_window_s: float = 10.0,
    fmin: float = 0.03,
    fmax: float = 2.0,
    mode: str = "peaks",
    min_periods: float = 8.0,
    min_concentration: float = 0.4,
) -> Tracking:
    """Causal sliding-window tracking of the n dominant heave frequencies.

    At t_k = min_window_s + k·hop_s the spectrum of a(t) over [t_k − window_s, t_k] (growing window at the start)
    gives the frequencies used from t_k on; estimates are accepted once the window holds ``min_periods``
    periods of its own dominant frequency and ``min_concentration`` of the velocity-spectrum energy lies within
    0.6–1.6 × that frequency (a wave peak, not noise). ``mode`` 'peaks' (paper: the n strongest spectral lines) or
    'centroids' (energy centroids of n equal-energy bands: a better basis for a broad sea spectrum).
    """
    t = np.asarray(t, float)
    fs = 1.0 / float(np.median(np.diff(t)))
    # block-mean decimation to ≥ 4·fmax for speed (the band of interest is far below)
    dec = max(1, int(fs // (5 * fmax)))
    nd = len(a) // dec
    ad = np.asarray(a[: nd * dec], float).reshape(nd, dec).mean(1)
    td = t[: nd * dec].reshape(nd, dec).mean(1)
    fsd = fs / dec
    starts, freqs, dom, wins, med, spr = [], [], [], [], [], []
    tk = t[0] + min_window_s
    while tk <= t[-1] + 1e-9:
        lo = np.searchsorted(td, tk - window_s)
        hi = np.searchsorted(td, tk, side="right")
        seg = ad[lo:hi]
        if len(seg) >= 16:
            f, s = displacement_spectrum(seg, fsd, fmin, fmax)
            if len(f) > 4:
                # the wave peak is found in the acceleration spectrum (S_h·ω⁴): low-frequency accelerometer
                # drift, hugely amplified by 1/ω⁴, must not win; the heave band is then [0.35, ∞) × that peak
                sv = s * (2 * np.pi * f) ** 4
                fv = float(f[int(np.argmax(sv))])
                near = (f >= 0.6 * fv) & (f <= 1.6 * fv)
                conc = float(sv[near].sum() / max(sv.sum(), 1e-300))
                band = f >= 0.35 * fv
                f, s = f[band], s[band]
                fdom = float(f[int(np.argmax(s))])
                if ((hi - lo) / fsd * fdom < min_periods or conc < min_concentration) and tk + hop_s <= t[-1]:
                    tk += hop_s  # not yet a trustworthy spectrum: too few periods, or no clear wave peak
                    continue
                res = 1.0 / max(1e-9, (hi - lo) / fsd)
                fr = _peaks(f, s, n) if mode == "peaks" else _centroids(f, s, n, res)
                row = np.full(n, np.nan)
                row[: len(fr)] = fr
                starts.append(int(np.searchsorted(t, tk)))
                freqs.append(row)
                dom.append(fdom)
                wins.append((hi - lo) / fsd)
                cs = np.cumsum(s)
                med.append(float(f[min(len(f) - 1, int(np.searchsorted(cs, 0.5 * cs[-1])))]))
                m0, m1, m2 = float(s.sum()), float((f * s).sum()), float((f * f * s).sum())
                spr.append(float(np.sqrt(max(0.0, m0 * m2 / max(m1 * m1, 1e-300) - 1.0))))
        tk += hop_s
    if not starts:
        raise ImutoolError(
            f"recording too short for frequency tracking: {t[-1] - t[0]:.1f} s < --min-window {min_window_s:g} s"
        )
    return Tracking(np.array(starts), np.array(freqs), np.array(dom), np.array(wins), np.array(med), np.array(spr))


# ------------------------------------------------------------------------------------------------------------------
# Filters
# ------------------------------------------------------------------------------------------------------------------
def bandpass_integrator(fs: float, cutoff: float, order: int = 3) -> np.ndarray:
    """SOS of G(s) = HPₙ(s)/s² (Butterworth high-pass, n ≥ 3, merged with the double integrator), bilinear."""
    if order < 3:
        raise ImutoolError("the band-pass double integrator needs high-pass order ≥ 3 to reject a constant bias")
    if not 0 < cutoff < fs / 2:
        raise ImutoolError(f"cut-off {cutoff} Hz must be in (0, {fs / 2}) Hz")
    z, p, k = signal.butter(order, 2 * np.pi * cutoff, "highpass", analog=True, output="zpk")
    z = np.asarray(z)[2:]  # two of the n zeros at s = 0 cancel the double integrator 1/s²
    zd, pd, kd = signal.bilinear_zpk(z, p, k, fs)
    return signal.zpk2sos(zd, pd, kd)


def integrator_response(sos: np.ndarray, fs: float, f: np.ndarray) -> np.ndarray:
    """G(f)/(−1/(2πf)²): the band-pass integrator relative to the ideal double integrator (complex; its angle
    is the phase lead φ, its modulus the gain)."""
    f = np.atleast_1d(np.asarray(f, float))
    _, h = signal.sosfreqz(sos, worN=f, fs=fs)
    return h * -((2 * np.pi * f) ** 2)


def heave_bandpass(a: np.ndarray, fs: float, cutoff: float, order: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Causal baseline: heave (m) and heave rate (m/s) from vertical acceleration through HPₙ/s²."""
    sos = bandpass_integrator(fs, cutoff, order)
    a0 = np.asarray(a, float) - a[0]
    h = signal.sosfilt(sos, a0)
    v = np.gradient(h) * fs
    return h, v


def _hp_weight(f: np.ndarray, cutoff: float, order: int) -> np.ndarray:
    """|Butterworth high-pass|² = (f/f_c)^{2n} / (1 + (f/f_c)^{2n}), computed without overflow."""
    r = (np.asarray(f, float) / cutoff) ** (2 * order)
    return r / (1.0 + r)


def heave_delayed(
    a: np.ndarray, fs: float, cutoff: float, order: int = 4, lowpass: float | None = None
) -> tuple[np.ndarray, np.ndarray, float]:
    """Zero-phase heave and heave rate: X(f) = −A(f)·W(f)/(2πf)², V(f) = A(f)·W(f)/(j2πf), with
    W(f) = 1/(1 + (f_c/f)^{2n}) (a squared-magnitude Butterworth high-pass; optional low-pass too).
    Zero-padded to 2N (no wrap-around). Returns (heave, rate, latency s), latency = the half-width containing
    99 % of the non-causal impulse response's absolute area. A cut-off at or above the Nyquist frequency (it
    would remove every frequency there is) is an ImutoolError."""
    if not 0 < cutoff < fs / 2:
        raise ImutoolError(
            f"zero-phase heave cut-off {cutoff:g} Hz must be in (0, {fs / 2:g}) Hz (the Nyquist frequency)"
        )
    x = np.asarray(a, float)
    n = len(x)
    x = x - x.mean()
    nfft = int(2 ** np.ceil(np.log2(2 * n)))
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    wgt = _hp_weight(f, cutoff, order)
    if lowpass:
        wgt = wgt / (1.0 + (f / lowpass) ** 8)
    om = 2 * np.pi * f
    om[0] = 1.0
    spec = np.fft.rfft(x, nfft)
    h = np.fft.irfft(-spec * wgt / om**2, nfft)[:n]
    v = np.fft.irfft(spec * wgt / (1j * om), nfft)[:n]
    # latency: impulse response of the heave path
    m = int(min(nfft, 2 ** np.ceil(np.log2(max(64.0, 40.0 * fs / cutoff)))))
    fi = np.fft.rfftfreq(m, 1.0 / fs)
    wi = _hp_weight(fi, cutoff, order)
    omi = 2 * np.pi * fi
    omi[0] = 1.0
    ir = np.abs(np.fft.fftshift(np.fft.irfft(-wi / omi**2, m)))
    c = np.cumsum(ir[m // 2 :] + ir[m // 2 - 1 :: -1][: m - m // 2]) if m > 1 else np.array([1.0])
    c = c / c[-1]
    latency = float(np.searchsorted(c, 0.99) / fs)
    return h, v, latency


def heave_zero_phase_bandpass(a: np.ndarray, fs: float, low: float, high: float, order: int = 2) -> np.ndarray:
    """Reference baseline for the NTNU comparison: a zero-phase (forward–backward) 2nd-order Butterworth
    band-pass [low, high] Hz applied to the acceleration, the velocity and the displacement of a trapezoidal
    double integration. Offline."""
    sos = signal.butter(order, [low, high], "bandpass", fs=fs, output="sos")
    x = signal.sosfiltfilt(sos, np.asarray(a, float) - np.mean(a))
    v = signal.sosfiltfilt(sos, np.concatenate([[0.0], np.cumsum(0.5 * (x[1:] + x[:-1]))]) / fs)
    return signal.sosfiltfilt(sos, np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]))]) / fs)


def heave_envelope(a: np.ndarray, fs: float, period: float, lowpass: float | None = None) -> np.ndarray:
    """The "traditional" method: (low-pass), bias (mean) removal, double integration, then the drift trend
    = mid-line of the upper/lower envelopes is subtracted. Offline.

    Envelopes are cubic splines through the maxima/minima of the integrated displacement (at least 0.6 dominant
    periods apart). A bias random walk makes the double integral wander by metres, so that the oscillation has
    no extrema at all; the wander is first reduced by a cubic spline through the means of consecutive
    two-period blocks (a coarse trend the envelopes then refine)."""
    x = np.asarray(a, float) - np.mean(a)
    if lowpass:
        x = signal.sosfiltfilt(signal.butter(4, lowpass, "lowpass", fs=fs, output="sos"), x)
    v = np.concatenate([[0.0], np.cumsum(0.5 * (x[1:] + x[:-1]))]) / fs
    d = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]))]) / fs
    idx = np.arange(len(d))
    blk = max(4, int(round(2 * period * fs)))
    nb = len(d) // blk
    if nb >= 4:
        centres = (np.arange(nb) + 0.5) * blk
        means = d[: nb * blk].reshape(nb, blk).mean(1)
        d = d - CubicSpline(centres, means)(idx)
    dist = max(1, int(0.6 * period * fs))
    up, _ = signal.find_peaks(d, distance=dist)
    lo, _ = signal.find_peaks(-d, distance=dist)
    if len(up) < 2 or len(lo) < 2:
        return d - np.polyval(np.polyfit(idx, d, 2), idx)
    upper = CubicSpline(up, d[up])(idx)
    lower = CubicSpline(lo, d[lo])(idx)
    return d - 0.5 * (upper + lower)


# ------------------------------------------------------------------------------------------------------------------
# The Kalman multi-step observer (heave paper §2)
# ------------------------------------------------------------------------------------------------------------------
def oscillator_matrix(omegas: np.ndarray, residual: bool = True) -> np.ndarray:
    """Continuous-time F (paper eq. 5): blockdiag([[0, 1], [−ωᵢ², 0]]) (+ a 0 for the residual Δh)."""
    n = len(omegas)
    s = 2 * n + (1 if residual else 0)
    f = np.zeros((s, s))
    for i, w in enumerate(omegas):
        f[2 * i, 2 * i + 1] = 1.0
        f[2 * i + 1, 2 * i] = -(w**2)
    return f


def discretise(f: np.ndarray, qc: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Φ = e^{F·T} (paper eq. 6) and the discrete process noise Q_d (Van Loan: both from one expm)."""
    s = f.shape[0]
    m = np.zeros((2 * s, 2 * s))
    m[:s, :s] = -f
    m[:s, s:] = qc
    m[s:, s:] = f.T
    e = expm(m * dt)
    phi = e[s:, s:].T
    qd = phi @ e[:s, s:]
    return phi, 0.5 * (qd + qd.T)


@njit(cache=True)
def _kf_kernel(z, seg, phis, qds, hs, r, outs, x0, p0, q):  # pragma: no cover - numba
    """Linear KF with a scalar measurement, run every q-th sample with model k = seg[i]. The outputs of the q
    samples up to the next update are model predictions (causal): y[i + j] = outs[k, j] @ x̂(i)."""
    n = z.shape[0]
    s = x0.shape[0]
    nout = outs.shape[2]
    x = x0.copy()
    p = p0.copy()
    y = np.empty((n, nout))
    ph = np.empty(s)
    xn = np.empty(s)
    tmp = np.empty((s, s))
    for i in range(0, n, q):
        k = seg[i]
        if i > 0:
            f = phis[k]
            for a in range(s):
                acc = 0.0
                for b in range(s):
                    acc += f[a, b] * x[b]
                xn[a] = acc
            x[:] = xn
            for a in range(s):
                for b in range(s):
                    acc = 0.0
                    for c in range(s):
                        acc += f[a, c] * p[c, b]
                    tmp[a, b] = acc
            for a in range(s):
                for b in range(a, s):
                    acc = qds[k, a, b]
                    for c in range(s):
                        acc += tmp[a, c] * f[b, c]
                    p[a, b] = acc
                    p[b, a] = acc
        h = hs[k]
        for a in range(s):
            ph[a] = 0.0
            for b in range(s):
                ph[a] += p[a, b] * h[b]
        sv = r
        innov = z[i]
        for a in range(s):
            sv += h[a] * ph[a]
            innov -= h[a] * x[a]
        for a in range(s):
            x[a] += ph[a] * innov / sv
        for a in range(s):
            for b in range(a, s):
                v = p[a, b] - ph[a] * ph[b] / sv
                p[a, b] = v
                p[b, a] = v
        for j in range(q):
            if i + j >= n:
                break
            for o in range(nout):
                acc = 0.0
                for a in range(s):
                    acc += outs[k, j, o, a] * x[a]
                y[i + j, o] = acc
    return y


@dataclass
class HeaveResult:
    """Heave (m, up), rate (m/s, up), dominant period (s), settled flag, delayed heave/rate and a summary."""

    heave: np.ndarray
    heave_rate: np.ndarray
    period: np.ndarray
    settled: np.ndarray
    heave_delayed: np.ndarray
    heave_rate_delayed: np.ndarray
    settled_delayed: np.ndarray
    summary: dict[str, Any]
    heave_std: np.ndarray | None = None  # m, one-sigma error bound of ``heave`` (realtime method; None otherwise)


def _segment_model(fr, good, fd, sig, bandwidth, residual_noise, dt, sos, fs, per_harmonic, output_residual, q=1):
    """Φ, Q_d (update interval q·dt), H and the output rows (heave, rate) for each of the q samples up to the
    next update (the rows composed with e^{F·j·dt}) of one set of oscillator frequencies."""
    nmax = len(fr)
    s = 2 * nmax + 1
    om = np.where(good, 2 * np.pi * np.nan_to_num(fr, nan=1.0), 2 * np.pi)
    fmat = oscillator_matrix(om)
    qc = np.zeros((s, s))
    ng = max(1, int(good.sum()))
    for i in range(nmax):
        if good[i]:
            qc[2 * i + 1, 2 * i + 1] = 4 * bandwidth * om[i] ** 3 * sig**2 / ng
    qc[-1, -1] = (residual_noise * sig) ** 2
    phi, qd = discretise(fmat, qc, dt * q)
    h = np.zeros(s)
    h[0 : 2 * nmax : 2] = good.astype(float)
    h[-1] = 1.0
    if per_harmonic:
        g = integrator_response(sos, fs, np.where(good, fr, 1.0))
        out_h = np.zeros(s)
        out_v = np.zeros(s)
        for i in range(nmax):
            if not good[i]:
                continue
            lead_i = float(np.angle(g[i]))
            rot = expm(oscillator_matrix(om[i : i + 1], residual=False) * (-lead_i / om[i])) / abs(g[i])
            out_h[2 * i : 2 * i + 2] = rot[0]
            out_v[2 * i : 2 * i + 2] = rot[1]
        lead = float(np.angle(integrator_response(sos, fs, [fd if fd > 0 else fr[good][0]])[0]))
        if output_residual:
            out_h[-1] = 1.0
    else:
        # paper: a single step count from the lead at the dominant line, applied to the whole state
        lead = float(np.angle(integrator_response(sos, fs, [fd])[0]))
        m = -lead / (2 * np.pi * fd * dt)
        fm = expm(fmat * (round(m) * dt))
        out_h = h @ fm
        out_v = np.zeros(s)
        out_v[1 : 2 * nmax : 2] = good.astype(float)
        out_v = out_v @ fm
    outs = np.empty((q, 2, s))
    step = expm(fmat * dt)
    acc = np.eye(s)
    for j in range(q):
        outs[j, 0], outs[j, 1] = out_h @ acc, out_v @ acc
        acc = step @ acc
    return phi, qd, h, outs, lead


def kalman_multistep(
    d: np.ndarray,
    fs: float,
    tracking: Tracking,
    sos: np.ndarray,
    per_harmonic: bool,
    bandwidth: float = 0.03,
    meas_noise: float = 0.002,
    residual_noise: float = 0.02,
    output_residual: bool = False,
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Run the harmonic-oscillator KF on the band-passed displacement d (m) and apply the multi-step
    observation. Returns (heave, heave rate, info).

    Tuning (all relative to the signal): process noise on each ḣᵢ with intensity qᵢ = 4·ζ·ωᵢ³·σ² (the intensity
    that keeps a damped oscillator of relative bandwidth ζ = ``bandwidth`` at variance σ² = var(d) / n);
    residual Δh random walk ``residual_noise``·σ per √s; measurement noise std ``meas_noise``·σ_d (+ 1 mm).
    ``per_harmonic``: rotate each harmonic by its own lead φᵢ and rescale by 1/|G(ωᵢ)| (realtime method);
    otherwise the paper's single m = −φ(ω₁)/(ω₁T) applied as F^m to the whole state (ω₁ = strongest line).
    """
    dt = 1.0 / fs
    nseg = len(tracking.start)
    nmax = tracking.freqs.shape[1]
    s = 2 * nmax + 1
    first = int(tracking.start[0])
    sig = float(np.std(d[:first])) if first > 10 else float(np.std(d))  # causal: the data before the 1st update
    sig = max(sig, 1e-4)
    phis = np.zeros((nseg, s, s))
    qds = np.zeros((nseg, s, s))
    hs = np.zeros((nseg, s))
    # the KF runs at ≥ 20 × the highest tracked frequency (and ≥ 5 Hz); the samples in between are
    # model predictions from the last update (causal, exact for the model)
    fhi = float(np.nanmax(tracking.freqs))
    q = max(1, int(fs / max(5.0, 20.0 * fhi)))
    outs = np.zeros((nseg, q, 2, s))
    leads = []
    cache: dict[tuple, tuple] = {}
    for k in range(nseg):
        fr = tracking.freqs[k]
        good = np.isfinite(fr)
        # frequencies quantised to 0.25 % steps: identical models are discretised once (expm is the cost)
        fq = np.where(good, np.exp(np.round(np.log(np.where(good, fr, 1.0)) / 0.0025) * 0.0025), np.nan)
        fd = float(np.exp(np.round(np.log(tracking.dominant[k]) / 0.0025) * 0.0025))
        key = (tuple(np.nan_to_num(fq, nan=-1.0)), fd if not per_harmonic else 0.0)
        if key not in cache:
            cache[key] = _segment_model(
                fq, good, fd, sig, bandwidth, residual_noise, dt, sos, fs, per_harmonic, output_residual, q
            )
        phis[k], qds[k], hs[k], outs[k], lead = cache[key]
        leads.append(lead)
    seg = np.zeros(len(d), dtype=np.int64)
    seg[tracking.start] = 1
    seg = np.cumsum(seg) - 1
    seg[seg < 0] = 0
    x0 = np.zeros(s)
    p0 = np.eye(s) * sig**2
    p0[1 : 2 * nmax : 2, 1 : 2 * nmax : 2] *= (2 * np.pi * np.nanmax(tracking.freqs[0])) ** 2
    r = (meas_noise * sig + 1e-3) ** 2
    y = _kf_kernel(np.ascontiguousarray(d, float), seg, phis, qds, hs, float(r), outs, x0, p0, q)
    info = {
        "phase_lead_deg_median": float(np.degrees(np.median(leads))) if leads else float("nan"),
        "kf_update_hz": round(fs / q, 3),
    }
    return y[:, 0], y[:, 1], info


# ------------------------------------------------------------------------------------------------------------------
# Real-time heave: a bank of phase-corrected (complementary) double integrators
# ------------------------------------------------------------------------------------------------------------------
def _denominator(n: int, shape: str) -> np.ndarray:
    """Monic D(s) = sⁿ + p₁sⁿ⁻¹ + … + pₙ for a unit corner: 'binomial' (s + 1)ⁿ or 'butterworth'."""
    if shape == "binomial":
        return np.poly(-np.ones(n))
    if shape == "butterworth":
        _, p, _ = signal.butter(n, 1.0, analog=True, output="zpk")
        return np.real(np.poly(p))
    raise ImutoolError(f"unknown filter shape {shape!r} (binomial or butterworth)")


def corrected_integrator(
    n: int, wc: float, shape: str = "binomial"
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Continuous state-space (A, B, C heave, C rate) of the phase-corrected double integrator of order n ≥ 4 at
    corner ωc (rad/s), input vertical acceleration (m/s², up), output heave (m, up) and heave rate (m/s).

    Transfer: y/a = H(s)/s² with H(s) = (sⁿ + p₁sⁿ⁻¹ + … + pₙ₋₃s³)/D(s): the high-pass H keeps three zeros at s = 0
    (a constant accelerometer bias gives no heave, a bias ramp a bounded offset) and 1 − H = (pₙ₋₂s² + pₙ₋₁s +
    pₙ)/D(s) falls as (ωc/ω)ⁿ⁻², so gain and phase error in the wave band are O((ωc/ω)ⁿ⁻²) instead of the
    O(ωc/ω) phase lead of a plain high-pass. Realisation with physical states, so a bank of such filters can be
    blended and a corner changed without corrupting the state: x = [h, ḣ, I₁, …, Iₙ₋₃, b] with Iⱼ the j-th
    integral of h and b the accelerometer-bias estimate:
    ḣ = v, v̇ = a − b − p₁v − p₂h − Σ pⱼ₊₂Iⱼ, İ₁ = h, İⱼ = Iⱼ₋₁, ḃ = pₙIₙ₋₃; heave y = h + Σⱼ₌₁ⁿ⁻³ pⱼIⱼ.
    """
    if n < 4:
        raise ImutoolError(f"the corrected integrator needs order ≥ 4, got {n}")
    p = _denominator(n, shape) * wc ** np.arange(n + 1)
    a = np.zeros((n, n))
    b = np.zeros(n)
    a[0, 1] = 1.0
    b[1] = 1.0
    a[1, 0], a[1, 1], a[1, n - 1] = -p[2], -p[1], -1.0
    for j in range(1, n - 2):  # I_j at index 1 + j
        a[1, 1 + j] = -p[j + 2]
        a[1 + j, 0 if j == 1 else j] = 1.0
    a[n - 1, n - 2] = p[n]
    c = np.zeros(n)
    c[0] = 1.0
    for j in range(1, n - 2):
        c[1 + j] = p[j]
    cv = c @ a  # ẏ = C A x (C B = 0)
    return a, b, c, cv


@njit(cache=True)
def _bank_kernel(a, ads, bds, cs, cvs, idx, frac, shift):  # pragma: no cover - numba
    """Run K discretised filters (trapezoidal, input linear between samples) on a; output at sample i the blend
    (1 − frac)·filter idx + frac·filter idx+1 (heave, rate), and the same blend ``shift`` corners lower (heave)."""
    n = a.shape[0]
    k_all, s = bds.shape
    x = np.zeros((k_all, s))
    xn = np.zeros(s)
    y = np.empty(n)
    v = np.empty(n)
    ylo = np.empty(n)
    for i in range(n):
        if i > 0:
            u = 0.5 * (a[i - 1] + a[i])
            for k in range(k_all):
                for r in range(s):
                    acc = bds[k, r] * u
                    for c in range(s):
                        acc += ads[k, r, c] * x[k, c]
                    xn[r] = acc
                for r in range(s):
                    x[k, r] = xn[r]
        k0 = idx[i]
        k1 = min(k0 + 1, k_all - 1)
        w1 = frac[i]
        y0 = y1 = v0 = v1 = 0.0
        for r in range(s):
            y0 += cs[k0, r] * x[k0, r]
            y1 += cs[k1, r] * x[k1, r]
            v0 += cvs[k0, r] * x[k0, r]
            v1 += cvs[k1, r] * x[k1, r]
        y[i] = (1.0 - w1) * y0 + w1 * y1
        v[i] = (1.0 - w1) * v0 + w1 * v1
        j0 = max(k0 - shift, 0)
        j1 = max(k1 - shift, 0)
        z0 = z1 = 0.0
        for r in range(s):
            z0 += cs[j0, r] * x[j0, r]
            z1 += cs[j1, r] * x[j1, r]
        ylo[i] = (1.0 - w1) * z0 + w1 * z1
    return y, v, ylo


def filter_settle_time(n: int, wc: float, shape: str = "binomial", tol: float = 0.01) -> float:
    """Start-up time (s) of the corrected integrator: after it the response to the initial state (the motion
    already under way when the filter starts from rest) has decayed below ``tol`` of its peak (slowest mode)."""
    a, _, c, _ = corrected_integrator(n, 1.0, shape)
    tt = np.linspace(0, 60, 1201)
    env = np.zeros_like(tt)
    for j in range(n):
        x0 = np.zeros(n)
        x0[j] = 1.0
        _, y = signal.impulse((a, x0[:, None], c[None, :], np.zeros((1, 1))), T=tt)
        env = np.maximum(env, np.abs(y) / max(1e-300, np.abs(y).max()))
    # last time the envelope exceeds tol (unit corner), scaled to ωc
    over = np.nonzero(env > tol)[0]
    return float(tt[over[-1]] if len(over) else 0.0) / wc


def wave_onset(t: np.ndarray, a: np.ndarray, i_first: int, f: float, level: float = 0.3) -> float:
    """Time (s) the wave motion began, from the data before sample ``i_first`` only: the first time the
    one-period moving RMS of the acceleration (mean removed) exceeded ``level`` × its value at ``i_first``."""
    fs = 1.0 / float(np.median(np.diff(t)))
    w = max(2, int(round(fs / f)))
    x = np.asarray(a[: i_first + 1], float)
    if len(x) <= w:
        return float(t[0])
    x = x - np.mean(x[-min(len(x), 8 * w) :])
    c = np.concatenate([[0.0], np.cumsum(x * x)])
    rms = np.sqrt((c[w:] - c[:-w]) / w)  # rms[j]: samples j .. j + w − 1
    above = np.nonzero(rms >= level * rms[-1])[0]
    return float(t[above[0]]) if len(above) else float(t[0])


def spread_weight(t: np.ndarray, tracking: Tracking, smooth_periods: float = RT_SMOOTH_PERIODS) -> np.ndarray:
    """Per-sample share (0–1) of the corrected-integrator bank in the real-time output: 1 for a broad sea
    spectrum (spread ν ≥ RT_SPREAD[1]), 0 for a line spectrum (ν ≤ RT_SPREAD[0]), linear between; 1 before the
    first estimate; first-order lag of ``smooth_periods`` tracked periods between updates (causal)."""
    lo, hi = RT_SPREAD
    goal = np.clip((np.asarray(tracking.spread, float) - lo) / (hi - lo), 0.0, 1.0)
    w = np.ones(len(t))
    ends = np.append(tracking.start[1:], len(t))
    cur = goal[0]
    for k, (i0, i1) in enumerate(zip(tracking.start, ends, strict=True)):
        if k == 0:
            w[i0:i1] = cur
            continue
        tau = smooth_periods / tracking.dominant[k]
        w[i0:i1] = goal[k] + (cur - goal[k]) * np.exp(-(t[i0:i1] - t[i0]) / tau)
        cur = float(w[i1 - 1])
    return w


def heave_realtime(
    t: np.ndarray,
    a: np.ndarray,
    tracking: Tracking,
    ratio: float = RT_RATIO,
    order: int = RT_ORDER,
    shape: str = RT_SHAPE,
    default_hz: float = 0.1,
    smooth_periods: float = RT_SMOOTH_PERIODS,
    step: float = 2**0.25,
    basis: str = "median",
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Causal heave (m, up) and rate (m/s) from vertical acceleration a (m/s², up): a bank of corrected
    integrators (:func:`corrected_integrator`) with corners ``step`` apart, all run from the start, blended at
    each sample by the corner ``ratio`` × the tracked heave frequency (``basis`` 'median': half the tracked
    displacement energy lies below it — steadier than the spectral peak; or 'dominant': the peak), log-
    interpolated and smoothed with a time constant of ``smooth_periods`` periods; before the first frequency
    estimate the corner is ``ratio`` × ``default_hz``."""
    fs = 1.0 / float(np.median(np.diff(t)))
    dt = 1.0 / fs
    seg = np.zeros(len(t), dtype=np.int64)
    seg[tracking.start] = 1
    seg = np.cumsum(seg) - 1
    fref = tracking.median if basis == "median" and len(tracking.median) else tracking.dominant
    # corner (log Hz) per sample: the default until the first estimate, then a first-order lag (time constant
    # ``smooth_periods`` tracked periods) toward ratio × the latest estimate, in closed form per hop
    lsm = np.full(len(t), np.log(ratio * default_hz))
    ends = np.append(tracking.start[1:], len(t))
    cur = np.log(ratio * fref[0])
    for k, (i0, i1) in enumerate(zip(tracking.start, ends, strict=True)):
        goal = np.log(ratio * fref[k])
        if k > 0:
            decay = np.exp(-(t[i0:i1] - t[i0]) * fref[k] / smooth_periods)
            lsm[i0:i1] = goal + (cur - goal) * decay
            cur = goal + (cur - goal) * np.exp(-(t[i1 - 1] + dt - t[i0]) * fref[k] / smooth_periods)
        else:
            lsm[i0:i1] = goal
            cur = goal
    lo, hi = float(lsm.min()), float(lsm.max())
    base = np.log(step)
    shift = max(1, int(round(np.log(RT_STD_CORNER) / base)))  # the check filter: this many corners lower
    k0 = int(np.floor(lo / base)) - shift
    k1 = int(np.ceil(hi / base))
    corners = np.exp(base * np.arange(k0, max(k1, k0 + 1) + 1))
    corners = corners[corners < 0.45 * fs / 2]
    kk = len(corners)
    ads = np.zeros((kk, order, order))
    bds = np.zeros((kk, order))
    cs = np.zeros((kk, order))
    cvs = np.zeros((kk, order))
    eye = np.eye(order)
    for k, fcr in enumerate(corners):
        am, bm, cm, cvm = corrected_integrator(order, 2 * np.pi * fcr, shape)
        mi = np.linalg.inv(eye - am * dt / 2)
        ads[k] = mi @ (eye + am * dt / 2)
        bds[k] = mi @ bm * dt
        cs[k], cvs[k] = cm, cvm
    pos = np.clip((lsm - base * k0) / base, 0.0, kk - 1.0)
    idx = np.minimum(np.floor(pos).astype(np.int64), kk - 1)
    frac = pos - idx
    a0 = np.ascontiguousarray(np.asarray(a, float) - a[0])
    y, v, ylo = _bank_kernel(a0, ads, bds, cs, cvs, idx, np.ascontiguousarray(frac), shift)
    info = {
        "realtime_filter": f"corrected double integrator, order {order} ({shape}), corner {ratio:g} × dominant",
        "realtime_corners_hz": [round(float(c), 5) for c in corners],
        "corner_hz": np.exp(lsm),
        "heave_check": ylo,
    }
    return y, v, info


def _ema(x: np.ndarray, fs: float, tau_s: float) -> np.ndarray:
    """Causal exponential moving average of x (time constant ``tau_s`` s, from a zero state)."""
    alpha = 1.0 - np.exp(-1.0 / (fs * max(tau_s, 1e-9)))
    return signal.lfilter([alpha], [1.0, alpha - 1.0], x)


def realtime_error_bound(
    t: np.ndarray, heave: np.ndarray, check: np.ndarray, f: float, order: int = RT_ORDER
) -> tuple[np.ndarray, np.ndarray]:
    """(heave_std m, significant heave m) per sample, causal. ``check`` is the same corrected-integrator bank run
    RT_STD_CORNER (r) times lower (:func:`heave_realtime`): its gain/phase error is r^−(n−2) of the output's (n =
    ``order``) and its start-up transient is longer, so output − check measures the output's error from a corner
    too close to the waves (a wrong frequency track, a new sea), from a start-up or onset transient, and from
    low-frequency drift — the errors the integrator itself makes (not the sensor's: both filters see the same
    input). heave_std = RMS of that difference over RT_STD_PERIODS periods of ``f`` (Hz) / (1 − r^−(n−2)) (the
    share of the output's error the difference holds); significant heave = 4 × the RMS heave over
    RT_SIGNAL_PERIODS periods."""
    fs = 1.0 / float(np.median(np.diff(t)))
    d = np.asarray(heave, float) - np.asarray(check, float)
    share = 1.0 - RT_STD_CORNER ** -(order - 2)
    std = np.sqrt(np.maximum(_ema(d * d, fs, RT_STD_PERIODS / f), 0.0)) / share
    # the signal is the heave less its error: a transient or a drift is not a sea that would excuse it
    w = max(1, int(round(RT_SIGNAL_PERIODS * fs / f)))
    c = np.concatenate([[0.0], np.cumsum(np.asarray(heave, float) ** 2 - (d / share) ** 2)])
    i = np.arange(1, len(d) + 1)
    power = (c[i] - c[np.maximum(i - w, 0)]) / w  # the last w samples only: a start-up leaves the window
    return std, 4.0 * np.sqrt(np.maximum(power, 0.0))


def _moving_rms(x: np.ndarray, w: int) -> np.ndarray:
    """Causal RMS about the window mean over the last ``w`` samples (fewer at the start)."""
    c1 = np.concatenate([[0.0], np.cumsum(x)])
    c2 = np.concatenate([[0.0], np.cumsum(x * x)])
    i = np.arange(1, len(x) + 1)
    lo = np.maximum(i - w, 0)
    n = i - lo
    m = (c1[i] - c1[lo]) / n
    return np.sqrt(np.maximum((c2[i] - c2[lo]) / n - m * m, 0.0))


def onset_unsettled(
    t: np.ndarray, a: np.ndarray, tr: Tracking, f_first: float, settle_periods: float, periods: float = 2.0
) -> np.ndarray:
    """Samples (bool) a wave onset leaves unsettled, causal: where the RMS vertical acceleration of the last
    ``periods`` periods exceeds RT_ONSET × its RMS over the 8 periods before the frequency estimate in force (still
    water → waves, a sudden sea), the frequency track and the corner no longer describe the motion: unsettled from
    there until a frequency estimate made ≥ 4 of its own periods after the onset, plus ``settle_periods``."""
    fs = 1.0 / float(np.median(np.diff(t)))
    a = np.asarray(a, float)
    short = _moving_rms(a, max(2, int(round(periods * fs / f_first))))
    ref = _moving_rms(a, max(2, int(round(8.0 * fs / f_first))))
    out = np.zeros(len(t), bool)
    starts = list(tr.start) + [len(t)]
    k = 0
    while k < len(tr.start):
        i0, i1 = int(starts[k]), int(starts[k + 1])
        level = max(float(ref[i0]), 1e-9)
        above = np.flatnonzero(short[i0:i1] > RT_ONSET * level)
        if not len(above):
            k += 1
            continue
        j = i0 + int(above[0])
        kk = k + 1
        while kk < len(tr.start) and t[tr.start[kk]] < t[j] + 4.0 / tr.dominant[kk]:
            kk += 1
        end = t[tr.start[kk]] + settle_periods / tr.dominant[kk] if kk < len(tr.start) else np.inf
        out[(t >= t[j]) & (t < end)] = True
        k = kk
    return out


def _plausibility(
    h: np.ndarray, std: np.ndarray, settled: np.ndarray, hd: np.ndarray, settled_d: np.ndarray
) -> dict[str, Any]:
    """Real-time heave against the delayed (zero-phase) heave on the samples both call settled: RMS difference
    (m) against the RMS heave_std the real-time output claims; ``consistent`` while ≤ PLAUSIBILITY × it."""
    m = (settled > 0.5) & (settled_d > 0.5)
    if m.sum() < 10:
        return {"compared": "real-time vs delayed heave", "samples": int(m.sum())}
    diff = float(np.sqrt(np.mean((h - hd)[m] ** 2)))
    sig = float(np.sqrt(np.mean(std[m] ** 2)))
    return {
        "compared": "real-time vs delayed heave",
        "samples": int(m.sum()),
        "rms_difference_m": diff,
        "rms_heave_std_m": sig,
        "consistent": bool(diff <= PLAUSIBILITY * sig),
    }


def realtime_warnings(
    h: np.ndarray, std: np.ndarray, settled: np.ndarray, hd: np.ndarray, settled_d: np.ndarray, fraction: float
) -> list[str]:
    """The real-time heave's warnings: nothing settled (with the drift, if it drifts), and a disagreement with the
    delayed heave beyond the stated σ."""
    out = []
    if not np.any(settled > 0.5):
        i = int(np.nanargmax(np.abs(h)))
        hd_max = float(np.nanmax(np.abs(hd)))
        text = (
            f"real-time heave: no sample settled — its error bound heave_std never fell below {fraction:g} × the "
            f"recent significant heave (median heave_std {float(np.nanmedian(std)):.3g} m); the heave column is not "
            "to be used"
        )
        if abs(h[i]) > 3.0 * hd_max:
            text += (
                f"; it drifts to {h[i]:+.2f} m where the zero-phase delayed heave stays within ±{hd_max:.2f} m "
                "(too short a record, no waves, or an accelerometer/attitude not fit for heave)"
            )
        out.append(text)
        return out
    p = _plausibility(h, std, settled, hd, settled_d)
    if p.get("consistent") is False:
        out.append(
            f"real-time heave disagrees with the delayed heave by {1000 * p['rms_difference_m']:.1f} mm RMS on its "
            f"settled samples, beyond {PLAUSIBILITY:g} × its stated σ ({1000 * p['rms_heave_std_m']:.1f} mm RMS)"
        )
    return out


# ------------------------------------------------------------------------------------------------------------------
# Driver
# ------------------------------------------------------------------------------------------------------------------
def refuse_unused_cutoff(method: str, cutoff: float | None) -> None:
    """A band-pass ``cutoff`` (Hz, ``--cutoff``) given for a method without that band-pass would be silently
    unused: refused (ImutoolError naming --cutoff and --method)."""
    if cutoff is None or method in CUTOFF_METHODS:
        return
    why = {
        "realtime": "its corner follows the tracked sea: set it with --cutoff-ratio",
        "envelope": "the envelope detrend has no band-pass",
        GNSS_METHOD: "the GNSS height is detrended over --height-window",
    }.get(method, "it has no band-pass")
    raise ImutoolError(
        f"--cutoff {cutoff:g} does not apply to --method {method} ({why}); --cutoff is the band-pass corner of "
        f"--method {', '.join(CUTOFF_METHODS)}"
    )


def estimate_heave(
    t: np.ndarray,
    a_up: np.ndarray,
    method: str = "realtime",
    harmonics: int | None = None,
    cutoff: float | None = None,
    order: int | None = None,
    window_s: float | None = None,
    hop_s: float = 10.0,
    min_window_s: float = 10.0,
    fmin: float = 0.03,
    fmax: float = 2.0,
    bandwidth: float = 0.03,
    meas_noise: float = 0.002,
    residual_noise: float = 0.02,
    delayed_cutoff: float | None = None,
    lowpass: float | None = None,
    settle_periods: float = 4.0,
    cutoff_ratio: float | None = None,
    lowpass_ratio: float = 4.0,
    shape: str | None = None,
    smooth_periods: float | None = None,
    settle_fraction: float = SETTLE_FRACTION,
) -> HeaveResult:
    """Heave (m, positive up) from vertical acceleration a_up (m/s², positive up) sampled at times t (s).

    ``harmonics``: oscillators in the model (default 3 for ``paper``, 5 for ``harmonic``/``realtime``).
    ``cutoff`` (Hz) of the causal band-pass (``bandpass``, ``paper``, ``harmonic``): default ``cutoff_ratio``
    (0.2) × the first tracked dominant frequency (the value known after ``min_window_s``; the filter is fixed from
    then on). ``realtime``: ``order`` (RT_ORDER), ``shape`` (RT_SHAPE) and ``cutoff_ratio`` (RT_RATIO, × the
    tracked median heave frequency) of the corrected-integrator bank, ``window_s`` default RT_WINDOW_S, corner
    smoothing ``smooth_periods``; ``cutoff`` is not used; its ``settled`` needs the error bound ``heave_std`` ≤
    ``settle_fraction`` × the recent significant heave (:func:`realtime_error_bound`). ``delayed_cutoff`` default
    0.35 × the whole-record dominant frequency (the delayed output is offline anyway); its zero-phase low-pass
    ``lowpass`` Hz defaults to ``lowpass_ratio`` (4) × that frequency.
    """
    if method not in METHODS:
        raise ImutoolError(f"unknown heave method {method!r}; choose one of {', '.join(METHODS)}")
    refuse_unused_cutoff(method, cutoff)
    if harmonics is None:
        harmonics = 3 if method == "paper" else 5
    if cutoff_ratio is None:
        cutoff_ratio = RT_RATIO if method == "realtime" else 0.2
    if order is None:
        order = RT_ORDER if method == "realtime" else 3
    if window_s is None:  # the bank's corner wants a steadier frequency than the KF's lines
        window_s = RT_WINDOW_S if method == "realtime" else 120.0
    if not 0 < settle_fraction:
        raise ImutoolError(f"--settle-fraction must be > 0, got {settle_fraction:g}")
    if harmonics < 1 or harmonics > 8:
        raise ImutoolError(f"--harmonics must be 1..8, got {harmonics}")
    t = np.asarray(t, float)
    a = np.asarray(a_up, float)
    if len(t) < 32:
        raise ImutoolError(f"too few samples for heave ({len(t)})")
    if not np.isfinite(a).any():
        raise ImutoolError("no finite vertical acceleration sample")
    if not np.all(np.isfinite(a)):
        bad = int((~np.isfinite(a)).sum())
        good = np.isfinite(a)
        a = np.interp(t, t[good], a[good])
        nan_filled = bad
    else:
        nan_filled = 0
    fs = 1.0 / float(np.median(np.diff(t)))
    if not np.isfinite(fs) or fs < 0.5:
        raise ImutoolError(f"sample rate {fs:.3g} Hz is too low for heave (needs ≥ 0.5 Hz; check the time column)")
    span = float(t[-1] - t[0])
    if not np.isfinite(span) or span / hop_s > 5e6:
        raise ImutoolError(
            f"the time column spans {span:.3g} s (a gap or a wrong time unit?); heave tracks "
            f"the sea every {hop_s:g} s and refuses more than 5e6 updates"
        )
    mode = "peaks" if method == "paper" else "centroids"
    tr = track_frequencies(t, a, harmonics, window_s, hop_s, min_window_s, fmin, fmax, mode)
    f_first = float(tr.dominant[0])
    fc = float(cutoff) if cutoff else cutoff_ratio * f_first
    # delayed output: whole-record dominant frequency
    f_rec = dominant_frequency(a, fs, fmin, fmax) or f_first
    fcd = float(delayed_cutoff) if delayed_cutoff else 0.35 * f_rec
    lp = lowpass if lowpass else min(lowpass_ratio * f_rec, 0.45 * fs)
    # the zero-phase path runs on block means at ≥ 10 × its low-pass (≥ 5 Hz), then back to every sample
    qd = max(1, int(fs / max(5.0, 10.0 * lp)))
    if qd > 1:
        nb = len(a) // qd
        ab = a[: nb * qd].reshape(nb, qd).mean(1)
        tb = t[: nb * qd].reshape(nb, qd).mean(1)
        hb, vb, lat_d = heave_delayed(ab, fs / qd, fcd, lowpass=lp)
        hd, vd = np.interp(t, tb, hb), np.interp(t, tb, vb)
    else:
        hd, vd, lat_d = heave_delayed(a, fs, fcd, lowpass=lp)
    if method != "realtime":
        sos = bandpass_integrator(fs, fc, order)
        d = signal.sosfilt(sos, a - a[0])
    period = np.full(len(t), np.nan)
    seg = np.zeros(len(t), dtype=np.int64)
    seg[tr.start] = 1
    seg = np.cumsum(seg) - 1
    ok = seg >= 0
    period[ok] = 1.0 / tr.dominant[seg[ok]]
    info: dict[str, Any] = {}
    bank_settle = None
    if method == "realtime":
        shape = shape or RT_SHAPE
        sp = RT_SMOOTH_PERIODS if smooth_periods is None else smooth_periods
        # a quick look (RT_SHORT_WINDOW_S) beside the steady long window: a longer period showing up (a new
        # swell, a turn that lowers the encounter frequency) lowers the corner at once — a corner too low costs
        # only noise, one too high costs phase and gain — and a disagreement of the two marks a change of sea
        trs = track_frequencies(
            t, a, 1, RT_SHORT_WINDOW_S, hop_s, min_window_s, fmin, fmax, "centroids", min_periods=4.0
        )
        j = np.searchsorted(trs.start, tr.start, side="right") - 1
        f_short = np.where(j >= 0, trs.median[np.maximum(j, 0)], tr.median)
        off = np.abs(f_short / tr.median - 1.0) > RT_CHANGE
        change = off & np.concatenate([[False], off[:-1]])  # two updates in a row: not one noisy short look
        tr_bank = Tracking(tr.start, tr.freqs, tr.dominant, tr.window_s, np.minimum(tr.median, f_short), tr.spread)
        h, v, info = heave_realtime(t, a, tr_bank, ratio=cutoff_ratio, order=order, shape=shape, smooth_periods=sp)
        corner = info.pop("corner_hz")
        h_check = info.pop("heave_check")
        fc = float(corner[tr.start[0]])
        # start-up of the bank: its transient after the motion began (the first sample, or a later onset of
        # waves found causally in the data before the first frequency estimate) must have died out
        bank_settle = wave_onset(t, a, int(tr.start[0]), f_first) + filter_settle_time(order, 2 * np.pi * fc, shape)
        # a line spectrum (regular waves, swell: spread ν ≤ RT_SPREAD[0]) is followed by the harmonic KF with
        # exact per-line phase correction instead (faster to settle, rejects the off-line noise), blended
        # linearly up to ν = RT_SPREAD[1]; weights smoothed like the corner
        w_bank = spread_weight(t, tr, sp)
        if np.any(w_bank < 1.0):
            fc_h = 0.2 * f_first
            sos = bandpass_integrator(fs, fc_h, 3)
            d = signal.sosfilt(sos, a - a[0])
            hk, vk, kinfo = kalman_multistep(
                d,
                fs,
                tr,
                sos,
                per_harmonic=True,
                bandwidth=bandwidth,
                meas_noise=meas_noise,
                residual_noise=residual_noise,
            )
            h = w_bank * h + (1.0 - w_bank) * hk
            v = w_bank * v + (1.0 - w_bank) * vk
            info.update(kinfo)
        info["realtime_bank_share"] = round(float(np.mean(w_bank[tr.start[0] :])), 3)
        latency = "0 s (causal; phase-corrected double integrator bank, or the harmonic KF on line spectra)"
    elif method == "bandpass":
        h = d
        v = np.gradient(d) * fs
        latency = "0 s (causal; phase lead of the high-pass)"
    elif method == "envelope":
        h = heave_envelope(a, fs, 1.0 / f_rec, lowpass)
        v = np.gradient(h) * fs
        latency = "offline (whole record)"
    else:
        h, v, info = kalman_multistep(
            d,
            fs,
            tr,
            sos,
            per_harmonic=(method == "harmonic"),
            bandwidth=bandwidth,
            meas_noise=meas_noise,
            residual_noise=residual_noise,
        )
        latency = "0 s (causal; phase lead cancelled by multi-step prediction)"
    # settled: after the first frequency estimate + settle_periods, outside the start-up of the band-pass
    settled = np.zeros(len(t), dtype=float)
    t_settle = t[tr.start[0]] + settle_periods / f_first
    if method == "envelope":
        t_settle = t[0] + 2.0 / f_rec
    settled[t >= t_settle] = 1.0
    # a change of sea: dominant frequency moving by > 20 % restarts the settling clock
    for k in range(1, len(tr.start)):
        if abs(tr.dominant[k] / tr.dominant[k - 1] - 1) > 0.2:
            i0 = tr.start[k]
            settled[(t >= t[i0]) & (t < t[i0] + settle_periods / tr.dominant[k])] = 0.0
    if method == "envelope":
        settled[t > t[-1] - 2.0 / f_rec] = 0.0
    if bank_settle is not None:  # the bank's share of the output must be past its start-up
        settled[(t < bank_settle) & (w_bank > 0.0)] = 0.0
        # a change of sea in progress (short and long looks disagree), and settle_periods after it
        for k in np.nonzero(change)[0]:
            i0 = tr.start[k]
            i1 = tr.start[k + 1] if k + 1 < len(tr.start) else len(t)
            settled[(t >= t[i0]) & (t < t[i1 - 1] + settle_periods / min(f_short[k], tr.median[k]))] = 0.0
    # the delayed output needs data on both sides: its first and last 1/f_c seconds are start-up/run-out
    settled_d = ((t >= t[0] + 1.0 / fcd) & (t <= t[-1] - 1.0 / fcd)).astype(float)
    heave_std = None
    warnings: list[str] = []
    if bank_settle is not None:
        heave_std, hs_now = realtime_error_bound(t, h, h_check, f_first, order)
        settled[~(heave_std <= settle_fraction * hs_now)] = 0.0
        settled[onset_unsettled(t, a, tr, f_first, settle_periods)] = 0.0
        t_settle = float(t[np.argmax(settled > 0.5)]) if np.any(settled > 0.5) else float(t[-1])
        warnings = realtime_warnings(h, heave_std, settled, hd, settled_d, settle_fraction)
    summary = {
        "method": method,
        "heave_convention": "m, positive UP",
        "harmonics": harmonics,
        "sample_rate_hz": round(fs, 3),
        "cutoff_hz": round(fc, 5),
        "order": order,
        "dominant_period_s_first": round(1.0 / f_first, 3),
        "dominant_period_s_record": round(1.0 / f_rec, 3),
        "latency": latency,
        "delayed_cutoff_hz": round(fcd, 5),
        "delayed_latency_s": round(lat_d, 2),
        "delayed_lowpass_hz": round(float(lp), 4),
        "settle_time_s": round(float(t_settle - t[0]), 2),
        "frequency_updates": int(len(tr.start)),
        "nan_samples_filled": nan_filled,
        **info,
    }
    if heave_std is not None:
        summary["settle_rule"] = (
            f"heave_std ≤ {settle_fraction:g} × the significant heave of the last {RT_SIGNAL_PERIODS:g} periods"
        )
        summary["settled_share"] = round(float(np.mean(settled > 0.5)), 3)
        ok = settled > 0.5
        summary["heave_std_median_settled_m"] = float(np.median(heave_std[ok])) if ok.any() else None
        summary["plausibility"] = _plausibility(h, heave_std, settled, hd, settled_d)
    if warnings:
        summary["warnings"] = warnings
    return HeaveResult(h, v, period, settled, hd, vd, settled_d, summary, heave_std)


def heave_recording(
    rec: Recording,
    method: str = "realtime",
    vertical: list[str] | None = None,
    vertical_sign: str = "up",
    attitude: str = "auto",
    lever_arm: np.ndarray | None = None,
    tilt_gain: float = TILT_GAIN,
    **options: Any,
) -> tuple[Recording, dict[str, Any]]:
    """Heave of a recording: columns time, heave, heave_rate, heave_delayed, heave_rate_delayed, period,
    settled (+ ref_heave / ref_heave_rate copied when present). Returns (recording, summary)."""
    a, vinfo = vertical_acceleration(rec, vertical, vertical_sign, attitude, lever_arm, tilt_gain)
    if not np.isfinite(a).any():
        raise ImutoolError(
            f"no finite vertical acceleration sample ({_why_no_vertical(rec, vertical, vinfo)})",
            path=str(rec.meta.get("source") or "") or None,
        )
    res = estimate_heave(rec.time, a, method=method, **options)
    out = Recording(rec.time.copy())
    out.add("heave", res.heave, "m")
    if res.heave_std is not None:
        out.add("heave_std", res.heave_std, "m")
    out.add("heave_rate", res.heave_rate, "m/s")
    out.add("heave_delayed", res.heave_delayed, "m")
    out.add("heave_rate_delayed", res.heave_rate_delayed, "m/s")
    out.add("period", res.period, "s")
    out.add("settled", res.settled, "1")
    out.add("settled_delayed", res.settled_delayed, "1")
    for name in ("ref_heave", "ref_heave_rate"):
        if name in rec:
            out.add(name, rec[name], rec.units.get(name))
    summary = {**res.summary, **vinfo}
    if vertical and len(vertical) >= 2 and res.heave_std is not None:
        pair = _accelerometer_pair(rec, vertical, vertical_sign, method, options)
        summary["plausibility_accelerometers"] = pair
        if pair.get("consistent") is False:
            summary["warnings"] = [*summary.get("warnings", []), pair["warning"]]
    out.meta.update(
        {
            "heave": f"m, positive UP (heave_delayed: zero-phase, latency {res.summary['delayed_latency_s']} s)",
            "heave_method": method,
            "heave_latency": res.summary["latency"],
            "source": rec.meta.get("source", ""),
            **input_notes(rec.meta),
        }
    )
    if res.heave_std is not None:
        out.meta["heave_std"] = "m, one-sigma error bound of heave (the integrator's own; not the sensor's)"
        out.meta["settled"] = summary["settle_rule"]
    if summary.get("warnings"):
        out.meta["warnings"] = list(summary["warnings"])
    return out, summary


def _accelerometer_pair(
    rec: Recording, columns: list[str], sign: str, method: str, options: dict[str, Any]
) -> dict[str, Any]:
    """Two vertical accelerometers (the first two of ``columns``): the real-time heave of each, compared (RMS
    difference, m) on the samples both call settled, against the σ the two claim together
    (√(σ₁² + σ₂²), RMS); ``consistent`` while ≤ PLAUSIBILITY × it, else ``warning``."""
    s = 1.0 if sign == "up" else -1.0
    one = [estimate_heave(rec.time, s * np.asarray(rec[c], float), method=method, **options) for c in columns[:2]]
    m = (one[0].settled > 0.5) & (one[1].settled > 0.5)
    out: dict[str, Any] = {"compared": f"real-time heave of {columns[0]} vs {columns[1]}", "samples": int(m.sum())}
    if m.sum() < 10 or one[0].heave_std is None or one[1].heave_std is None:
        return out
    diff = float(np.sqrt(np.mean((one[0].heave - one[1].heave)[m] ** 2)))
    sig = float(np.sqrt(np.mean((one[0].heave_std ** 2 + one[1].heave_std ** 2)[m])))
    out.update({"rms_difference_m": diff, "rms_heave_std_m": sig, "consistent": bool(diff <= PLAUSIBILITY * sig)})
    if not out["consistent"]:
        out["warning"] = (
            f"the real-time heaves of {columns[0]} and {columns[1]} differ by {1000 * diff:.1f} mm RMS on the settled "
            f"samples, beyond {PLAUSIBILITY:g} × the σ they claim ({1000 * sig:.1f} mm): a sensor's gain, axis or "
            "lever (roll × its offset) is not what the heave assumes"
        )
    return out


def _why_no_vertical(rec: Recording, vertical: list[str] | None, vinfo: dict[str, Any]) -> str:
    """What made every vertical acceleration sample NaN: the accelerometer, or the attitude that rotated it."""
    if vertical:
        return f"every value of {', '.join(vertical)} is missing"
    if "accel" in rec and not np.any(np.all(np.isfinite(rec["accel"]), axis=1)):
        return "all accelerometer values missing"
    return f"the accelerometer has values; the attitude has none: {vinfo.get('vertical', 'attitude')}"


HEAVE_CHANNELS = ("heave", "heave_delayed", "heave_rate", "heave_rate_delayed", "ref_heave", "ref_heave_rate")


# the heave kernels as the command calls them, for the second process of a cold run (formats.jit.warm; argument
# types in numba's signature syntax, checked against a real cold compile by tests/test_kernel_warm.py)
HEAVE_KERNELS: tuple[Entry, ...] = (
    ("imutool.heave", "_complementary_kernel", "float64[::1], float64[:, ::1], float64[:, ::1], float64, float64"),
    (
        "imutool.heave",
        "_bank_kernel",
        "float64[::1], float64[:, :, ::1], float64[:, ::1], float64[:, ::1], float64[:, ::1], int64[::1], "
        "float64[::1], int64",
    ),
)


# ------------------------------------------------------------------------------------------------------------------
# Evaluation
# ------------------------------------------------------------------------------------------------------------------
def _evaluate_at_reference(
    est: Recording, ref_t: np.ndarray, rh: np.ndarray, what: str, max_lag_s: float
) -> dict[str, Any]:
    """evaluate_heave at the reference's own times: error = est(τ + lag) − ref(τ), the estimate (unsettled rows
    NaN) interpolated onto the reference times τ."""
    sig = 4 * np.nanstd(rh)
    out: dict[str, Any] = {
        "unit": "m",
        "max_lag_s": max_lag_s,
        "reference_heave": what,
        "compared_at": "the reference's own times",
        "significant_heave_ref_m": float(sig),
    }
    for ch, flag in (("heave", "settled"), ("heave_delayed", "settled_delayed")):
        if ch not in est:
            continue
        mask = np.asarray(est[flag]) > 0.5 if flag in est else np.ones(len(est), bool)
        x = np.where(mask, np.asarray(est[ch], float), np.nan)
        if mask.sum() < 10:  # e.g. a real-time heave that never met its error bound (heave_std): said, not judged
            out[ch] = _unjudged(int(mask.sum()), len(est))
            continue
        lag = 0.0
        if max_lag_s > 0:
            step = min(float(np.median(np.diff(est.time))), max_lag_s / 10)
            lag, _ = best_lag(ref_t, rh, est.time, x, max_lag_s, step_s=step)
            lag = -lag  # best_lag moved the estimate against the reference: the estimate's lag is the opposite
        st = error_stats(interp_to(ref_t + lag, est.time, x) - rh)
        st["lag_s"] = float(lag)
        st["excluded_unsettled"] = int((~mask).sum())
        st["rmse_pct_of_significant"] = float(100 * st["rmse"] / sig) if sig > 0 else float("nan")
        out[ch] = st
    return _judged(out)


def _unjudged(n_settled: int, n: int) -> dict[str, Any]:
    """The entry of an output with fewer than 10 settled samples: not evaluated, and why."""
    return {
        "n": 0,
        "settled_samples": n_settled,
        "excluded_unsettled": n - n_settled,
        "not_evaluated": (
            f"{n_settled} settled sample(s) of {n}: too few (< 10) to evaluate; the estimate never met its error bound"
        ),
    }


def _judged(out: dict[str, Any]) -> dict[str, Any]:
    """Refuse an evaluation in which no heave output had settled samples to compare."""
    done = [k for k in ("heave", "heave_delayed") if k in out and "not_evaluated" not in out[k]]
    if not done:
        raise ImutoolError("too few settled samples to evaluate heave (no output settled for 10 samples)")
    return out


def _ref_heave(ref: Recording) -> tuple[np.ndarray, np.ndarray, str]:
    """(times, heave m + up, what it is) of a reference: ref_heave or heave, else the detrended gnss_height."""
    for name in ("ref_heave", "heave", "Heave"):
        if name in ref:
            return ref.time, np.asarray(ref[name], float), name
    if "gnss_height" in ref.channels:
        from imutool.gnss_heave import reference_heave  # noqa: PLC0415

        return reference_heave(ref)
    raise ImutoolError(
        f"reference has no heave channel (ref_heave, heave or gnss_height); has {', '.join(ref.channels)}"
    )


def evaluate_heave(est: Recording, ref: Recording, max_lag_s: float = 0.1) -> dict[str, Any]:
    """Heave error statistics (m) of ``est`` (channels heave and, if present, heave_delayed) against the
    reference heave (``ref_heave`` or ``heave``; positive up; else the detrended ``gnss_height``), after the best
    constant lag within ±max_lag_s. Samples with ``settled`` = 0 are excluded (counted). Positive lag: the
    estimate lags the reference. A reference sampled more sparsely than the estimate (a 1 Hz GNSS height
    against a 50 Hz estimate) is compared at its own times, the estimate interpolated there."""
    ref_t, rh, what = _ref_heave(ref)
    sparse = len(est) > 1 and len(ref_t) > 1 and np.median(np.diff(ref_t)) > 1.5 * np.median(np.diff(est.time))
    if sparse and what not in ("ref_heave", "heave", "Heave"):
        return _evaluate_at_reference(est, ref_t, rh, what, max_lag_s)
    out: dict[str, Any] = {"unit": "m", "max_lag_s": max_lag_s, "reference_heave": what}
    sig = 4 * np.nanstd(rh)
    out["significant_heave_ref_m"] = float(sig)
    for ch, flag in (("heave", "settled"), ("heave_delayed", "settled_delayed")):
        if ch not in est:
            continue
        mask = np.ones(len(est), bool)
        if flag in est:
            mask = np.asarray(est[flag]) > 0.5
        x = np.asarray(est[ch], float)
        tt, xx = est.time[mask], x[mask]
        if len(tt) < 10:
            out[ch] = _unjudged(len(tt), len(est))
            continue
        if max_lag_s > 0:
            # a lag grid finer than the sample interval (at 10 Hz a ±0.1 s search would have three points)
            step = min(float(np.median(np.diff(tt))), max_lag_s / 10)
            lag, _ = best_lag(tt, xx, ref_t, rh, max_lag_s, step_s=step)
        else:
            lag = 0.0
        r = interp_to(tt - lag, ref_t, rh)
        st = error_stats(xx - r)
        st["lag_s"] = float(lag)
        st["excluded_unsettled"] = int((~mask).sum())
        st["rmse_pct_of_significant"] = float(100 * st["rmse"] / sig) if sig > 0 else float("nan")
        out[ch] = st
    return _judged(out)
