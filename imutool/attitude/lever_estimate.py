"""The sensor's lever arm from the centre of rotation, estimated from a ship's own motion when nobody gave it.

A sensor at r (m, body FRD) from the point the ship rotates about feels, besides gravity and the hull's
translation, the rotation's own acceleration

    a_r = ω̇ × r + ω × (ω × r) = ([ω̇]× + [ω]×²) r = K(ω, ω̇) r        (rigid body kinematics)

— on a bridge 20 m above the roll axis, rolling 20° at 12 s, about 2 m/s², 10° of false tilt. It is linear in r.
The filter's attitude gives the specific force gravity alone would produce, f_g = Rᵀ(0, 0, −g); the rest of the
measured force f is a_r + the hull's translation + noise. So r is the least-squares solution of

    HP(f − f_g) = HP(K) r                                              (3 equations per sample)

where HP subtracts a centred triangular moving average ``HIGHPASS_S`` long (zero phase): it leaves the wave
band, where a_r lives, and removes what is constant or slow (accelerometer bias, a turn's centripetal
acceleration, the filter's slow tilt error). The translation is at the wave periods too, but not locked to ω̇ the
way a_r is; what of it does follow the rotation (heave in step with pitch, sway with roll) is taken into the arm,
so the estimate is the arm that explains the acceleration following the rotation, not a survey of the sensor's
position (on the simulator's bridge x came out −7.8 m against −12 m; the roll it gives is within 0.02° of the
true arm's).

The attitude f_g is taken from: the filter's, run once on the span with no arm, is itself bent by the arm it was not
told of — a share c < 1 of a_r (what passes its low-pass) goes into its tilt, so a regression on it comes out short
by that share. Until issue 52 the filter was re-run told each estimate and the regression repeated (three runs: the
error shrinks by c each time). Now the wave band of the vertical is the gyro's own (:func:`gyro_vertical`): the
gyro, integrated from the filter's attitude with the filter's bias, carries the rotation at wave periods without
any share of the accelerometer, and the filter keeps only what is slow (the filter's vertical seen in the gyro's
frame, low-passed by the complement of the same HP: a heading jump of the filter does not enter). One filter run,
one regression. On 44 simulated ships (the distribution below; arms 0 and 20 m above and below the roll centre among
them) the arm moved from the three runs' by a median of 0.01–0.04 σ per axis, 90 % within 0.5 σ, the largest 1.3 σ
(y on a 300-s record at 25° roll; both within 2σ of the truth); |error| ≤ 2σ for the same 94 % of the components,
the σ alike (tests/test_lever_estimate.py). On 2 M rows at 200 Hz the estimate's CPU fell from ~0.47 s to ~0.17 s.

Used on ship motion only, when no lever arm is given (``lever_arm_estimate``), on the first ``ANALYSIS_MAX_S``
(the span the motion model judges; a stream holds it back), at ~``ANALYSIS_HZ``. Each direction of r (the
singular vectors of HP(K)) is kept only where the data determine it: its coefficient ≥ ``MIN_T`` standard errors
(the least-squares error inflated for the residual's correlation, AR(1)); a direction the motion does not excite
produces no acceleration and is left at zero. An arm longer than ``MAX_ARM_M`` is not a ship's: refused.

The error claimed (``sd_m``, issue 48): the residual (the hull's translation, the filter's tilt error) and the
columns are both narrow-band at the wave periods, and their chance correlation over the span is what errs; the
AR(1) figure above claimed the bridge's x (4.1 m off) as ±1.0 m. The claimed σ is the Newey–West covariance of the
scores Dᵀe (lags up to ``HAC_LAG_S``, Bartlett weights) × ``SD_FACTOR``; along a direction left at zero, its
coefficient + its error is added; never less than the AR(1) figure (which still decides what is kept and refused,
so the arm itself is unchanged). Measured with 175 simulated ships (300/600 s; roll 5–30°, heave 0.5–4 m at 5–12 s,
sway 0.2–1.5 m, accelerometer bias 0.5–10 mg, arms x −25…10, y ±5, z −35…−3 m): |error| ≤ 2σ for 95 % of the
components of the 114 it was set on and 94 % of 58 fresh ones (each axis ≥ 91 %), against 44 % before. A refusal is
always said (``message``), also a span too short or too still to estimate from.

A gyro whose scale is wrong (a wrong range or unit) also bends the tilt in step with the roll, and on a narrow-band
roll a lever arm could absorb it and hide the fault from the gyro check. So one more unknown is fitted beside r: a
scale error ε common to the gyro's axes (as a wrong range or unit is), whose column is f_g × (ε · the gyro's high-
passed angle). The two differ in frequency (a_r grows as ω², the scale error's force does not), which an irregular
sea separates. The one regression on the gyro's wave band finds only part of a large error (the columns are the
measured rates': ×1.5 on a 30-m bridge gives −25 % and half the arm), so where it finds |ε| > ``SCALE_NOTE`` the
filter is told the arm and the regression repeated twice (``FALLBACK_RUNS``, the iteration of before issue 52; 4 of
the 44 intact ships above, |ε| up to 0.19 there). Where the last regression finds |ε| > ``MAX_SCALE_ERROR`` and ≥
``MIN_T`` standard errors, the estimate is refused, the filter runs without an arm and the warning names the gyro;
above ``SCALE_NOTE`` the arm is used and the message says what was found. On ship-roll with the gyro ×2, ×0.5 or an
axis reversed: ε −50 %, +113 %, −229 % / +47 %, refused; ×1.5 on a 30-m bridge (−33 %), refused. A smaller error on
one axis is partly absorbed (x ×1.1: ε −10 %, said; x ×1.2: −17 %, said, the roll 3.8° off). On 30 intact ship
simulations (seeds 4–8, 200 s and 600 s) |ε| ≤ 0.08 at 600 s and ≤ 0.23 at 200 s, none refused.

Blocks are by time, not by row: a gap leaves its blocks empty, and the blocks within an edge of a gyro gap are
left out (the integrated angle and the moving averages bridge it).

On ``imutool simulate ship-at-sea`` (bridge (−12, 0, −20) m, 1 m sway, GNSS): estimated (−7.7, 0.2, −19.7) m;
roll RMSE 0.12° (0.10° with the true arm, 1.13° with none).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from formats.frames import quat_conjugate, quat_multiply, quat_to_matrix
from imutool.attitude.motion import ANALYSIS_HZ, ANALYSIS_MAX_S

HIGHPASS_S = 30.0  # s: the high-pass's moving average (two boxes of half this; gain ½ at a period of ~40 s)
EDGE_S = 30.0  # s: left out at both ends of the span (where the moving average is one-sided)
MIN_SPAN_S = 180.0  # s: the shortest span estimated from (two edges and two minutes: ten roll periods)
FALLBACK_RUNS = 2  # filter runs told the arm where one regression finds a gyro scale error above SCALE_NOTE
MIN_T = 3.0  # a direction of r is kept when its coefficient is ≥ this many standard errors
HAC_LAG_S = 20.0  # s: the lags the standard errors count correlated scores over (Newey–West, Bartlett weights)
SD_FACTOR = 1.25  # the Newey–West σ × this: what the residual's narrow band still hides (measured, docstring)
MAX_ARM_M = 150.0  # m: longer is not a sensor on a ship; refused
SCALE_NOTE = 0.1  # a gyro scale error (fraction) the estimate's message points out (the arm is still used)
MAX_SCALE_ERROR = 0.3  # a gyro scale error (fraction) beyond which the estimate is refused (see the docstring)
GRAVITY = 9.80665  # m/s²


@dataclass(frozen=True)
class LeverArmEstimate:
    """The estimated lever arm ``arm_m`` (m, body FRD; None when not determined), its standard errors ``sd_m``
    (m, the least-squares error inflated for correlated residuals), the span it was estimated on ``span_s`` (s),
    the share of the span's residual force variance the arm explains ``explained``, ``reason`` when refused, and
    the gyro scale error fitted beside the arm ``scale_error`` (fraction, common to the axes; beyond
    MAX_SCALE_ERROR: refused)."""

    arm_m: np.ndarray | None
    sd_m: np.ndarray
    span_s: float
    explained: float
    reason: str = ""
    scale_error: float = np.nan  # the gyro's scale error fitted beside the arm (fraction, every axis)
    warn: bool = False  # a refusal the user is told of (the data contradict an arm), not a span too short or still

    def summary(self) -> dict:
        """The summary's and the output metadata's ``lever_arm_estimate`` entry."""
        out: dict = {"span_s": round(self.span_s, 1)}
        if self.arm_m is not None:
            out["lever_arm_m"] = [round(float(x), 2) for x in self.arm_m]
            out["sd_m"] = [round(float(x), 2) for x in self.sd_m]
            out["explained_share"] = round(self.explained, 3)
            out["gyro_scale_error"] = round(self.scale_error, 3)
        else:
            out["refused"] = self.reason
        return out

    def message(self) -> str | None:
        """The one line a user is told (a warning on stderr, in the JSON and the output's metadata): the arm used,
        or why none was (a refusal is never only in the summary)."""
        if self.arm_m is None and not self.warn:  # a span too short or too still: said, not alarming (issue 48)
            return (
                f"no lever arm given and none estimated ({self.reason}): the rotation's own acceleration at the "
                "sensor, if any, is taken for tilt; give --lever-arm X,Y,Z (m, body FRD) on a ship away from its "
                "roll centre"
            )
        if self.arm_m is None:
            return (
                f"no lever arm given and none could be estimated ({self.reason}): the rotation's own acceleration at "
                "the sensor is taken for tilt; give --lever-arm X,Y,Z (m, body FRD, from the roll centre)"
            )
        arm = ", ".join(f"{x:.1f}" for x in self.arm_m)
        sd = ", ".join(f"{x:.1f}" for x in self.sd_m)
        text = (
            f"no lever arm given: estimated from the first {self.span_s:.0f} s of ship motion as ({arm}) ± ({sd}) m, "
            "body FRD, and used; give the measured one with --lever-arm X,Y,Z (--lever-arm 0,0,0: the sensor is at "
            "the centre of rotation)"
        )
        if abs(self.scale_error) > SCALE_NOTE:
            text += (
                f"; the same fit finds a gyro scale error of {100 * self.scale_error:+.0f} %, which an arm may have "
                "absorbed: check the gyro's range, unit and axes"
            )
        return text


def analysis_span(time: np.ndarray) -> np.ndarray:
    """Mask of the rows the estimate is made on: the first ANALYSIS_MAX_S (s) of ``time``."""
    t = np.asarray(time, dtype=np.float64)
    return t - t[0] <= ANALYSIS_MAX_S if len(t) else np.zeros(0, bool)


def _skew(v: np.ndarray) -> np.ndarray:
    """(N,3,3) cross-product matrices [v]× of (N,3) vectors."""
    z = np.zeros(len(v))
    x, y, w = v[:, 0], v[:, 1], v[:, 2]
    return np.stack([np.stack([z, -w, y], 1), np.stack([w, z, -x], 1), np.stack([-y, x, z], 1)], 1)


def _highpass(a: np.ndarray, n: int) -> np.ndarray:
    """``a`` (M, k) less its centred moving average, a box of ``n`` samples run twice (triangle, zero phase);
    the ends take the mean of the samples there are."""
    out = a.copy()
    for _ in range(2):
        c = np.concatenate([np.zeros((1, a.shape[1])), np.cumsum(out, axis=0)])
        i = np.arange(len(out))
        lo, hi = np.maximum(i - n // 2, 0), np.minimum(i + n - n // 2, len(out))
        out = (c[hi] - c[lo]) / (hi - lo)[:, None]
    return a - out


def _fill_nan(a: np.ndarray) -> np.ndarray:
    """Columns of ``a`` (M, k) with NaN rows linearly interpolated (for the filter; those rows are not fitted)."""
    out = a.copy()
    bad = ~np.isfinite(out).all(axis=1)
    if bad.any() and (~bad).sum() >= 2:
        idx = np.arange(len(out))
        for j in range(out.shape[1]):
            out[bad, j] = np.interp(idx[bad], idx[~bad], out[~bad, j])
    return out


def lever_arm_regression(
    time: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    q: np.ndarray,
    bias: np.ndarray,
    judge_scale: bool = True,
    wave_from_gyro: bool = False,
) -> LeverArmEstimate:
    """One least-squares solution of HP(f − Rᵀ(0,0,−g)) = HP([ω̇]× + [ω]×²) r (module docstring).

    ``time`` s, ``gyro`` rad/s and ``accel`` m/s² (N,3) body FRD, ``q`` (N,4) the filter's body→NED attitude,
    ``bias`` (N,3) its gyro bias (rad/s). Rows are averaged in blocks to ~ANALYSIS_HZ first. ``wave_from_gyro``: R
    with the gyro's wave band (:func:`gyro_vertical`), so that a filter not told the arm gives the arm in one
    regression; otherwise ``q`` as it is (a filter told the arm)."""
    t = np.asarray(time, dtype=np.float64)
    span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    no = np.full(3, np.nan)
    if span < MIN_SPAN_S:
        return LeverArmEstimate(None, no, span, np.nan, f"{span:.0f} s of data, {MIN_SPAN_S:.0f} s needed")
    dt = float(np.median(np.diff(t)))
    step = max(1, int(round(1.0 / (ANALYSIS_HZ * dt))))
    h = dt * step  # s between block means
    # blocks by time, not by row: a gap leaves its blocks empty (NaN) instead of joining the rows across it
    idx = np.minimum(((t - t[0]) / h).astype(np.int64), int((t[-1] - t[0]) / h))
    m = int(idx[-1]) + 1
    count = np.bincount(idx, minlength=m)

    def blocks(a: np.ndarray) -> np.ndarray:
        a = np.asarray(a, dtype=np.float64)
        sums = np.stack([np.bincount(idx, weights=a[:, j], minlength=m) for j in range(3)], axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where((count >= max(1, step // 2))[:, None], sums / count[:, None], np.nan)

    w = blocks(np.asarray(gyro) - np.asarray(bias))
    box = max(1, int(round(0.5 * HIGHPASS_S / h)))
    rot = quat_to_matrix(np.asarray(q))
    if wave_from_gyro and m > 1:
        # gravity's force with the gyro's wave band (gyro_vertical): −g Rᵀm, m the block's vertical in the NED frame
        vertical = gyro_vertical(_block_quats(np.asarray(q), idx, m), _fill_nan(w), h, box)
        f_g = np.einsum("nji,nj->ni", rot, -GRAVITY * vertical[idx])  # per row, its block's vertical
    else:
        f_g = np.einsum("nji,j->ni", rot, np.array([0.0, 0.0, -GRAVITY]))
    y = blocks(accel) - blocks(f_g)
    k = _skew(np.gradient(w, h, axis=0)) + _skew(w) @ _skew(w)
    ok = np.isfinite(y).all(axis=1) & np.isfinite(k.reshape(m, 9)).all(axis=1)
    edge = int(round(EDGE_S / h))
    ok[:edge] = False
    ok[m - edge :] = False
    # across a gap of the gyro the integrated angle and the moving averages are bridged, not measured: the
    # blocks within an edge of it are left out (a single missing block, e.g. a clipped sample, costs only itself)
    gap = ~np.isfinite(w).all(axis=1)
    if gap.any():
        runs = np.flatnonzero(np.diff(np.concatenate([[0], gap.astype(np.int8), [0]])))
        for a, b in zip(runs[::2], runs[1::2], strict=True):
            reach = edge if b - a > 1 else 1
            ok[max(0, a - reach) : b + reach] = False
    if ok.sum() < 10 * 3:
        return LeverArmEstimate(None, no, span, np.nan, "too few valid samples")
    # the column of a gyro scale error ε (one for every axis, as a wrong range or unit is): the filter's tilt off
    # by ε × the angle the gyro turned (high-passed), so the force gravity gives is off by f_g × δθ
    angle = _highpass(np.cumsum(_fill_nan(w), axis=0) * h, box)
    scale_col = np.cross(blocks(f_g), angle)
    columns = np.concatenate([k.reshape(m, 9), scale_col], axis=1)
    design = _highpass(_fill_nan(columns), box)
    design = np.concatenate([design[:, :9].reshape(m, 3, 3), design[:, 9:].reshape(m, 3, 1)], axis=2)[ok]
    design, target = design.reshape(-1, 4), _highpass(_fill_nan(y), box)[ok].reshape(-1)
    u, s, vt = np.linalg.svd(design, full_matrices=False)
    if not s[0] > 0:
        return LeverArmEstimate(None, no, span, np.nan, "no rotation")
    live = s > 1e-9 * s[0]  # a direction the motion does not excite at all has no coefficient
    s = np.where(live, s, 1.0)
    coef = np.where(live, (u.T @ target) / s, 0.0)  # (r, ε) in the singular directions
    resid = target - design @ (vt.T @ coef)
    sigma2 = float(resid @ resid) / max(1, len(target) - 4)
    r3 = resid.reshape(-1, 3)
    rho = np.nanmean([_lag1(r3[:, j]) for j in range(3)])
    inflate = np.sqrt((1 + rho) / (1 - rho)) if rho > 0 else 1.0  # AR(1): correlated residuals carry less
    coef_sd = np.sqrt(sigma2) / s * inflate
    keep = live & (np.abs(coef) >= MIN_T * coef_sd)
    if not keep.any():
        reason = "the motion does not determine it (too little rotation: in port?)"
        return LeverArmEstimate(None, no, span, np.nan, reason, warn=True)
    x = vt.T @ np.where(keep, coef, 0.0)
    # the error claimed: the residual (the hull's translation, the filter's tilt error) and the columns are both
    # narrow-band at the wave periods, and their chance correlation over the span is what errs — the AR(1) factor
    # alone claimed 4σ errors as ±1σ (issue 48). Newey–West covariance of the scores Dᵀe over HAC_LAG_S, × SD_FACTOR,
    # over the kept directions; a direction left at zero is unknown by about its coefficient and its error, and
    # that much is added along it; never less than the AR(1) figure
    cov = _hac_coef_cov(design.reshape(-1, 3, 4), r3, vt, s, live, max(1, int(round(HAC_LAG_S / h)))) * SD_FACTOR**2
    hac_sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    vk, drop = vt.T[:, keep], live & ~keep
    x_var = np.diag(vk @ cov[np.ix_(keep, keep)] @ vk.T)
    x_var = x_var + (vt.T[:, drop] ** 2) @ ((np.abs(coef) + np.maximum(coef_sd, hac_sd))[drop] ** 2)
    ar1_sd = np.sqrt((vt.T**2) @ np.where(keep, coef_sd, 0.0) ** 2)  # what decides (kept directions, the gyro)
    x_sd = np.sqrt(np.maximum(x_var, ar1_sd**2))
    arm, sd, eps = x[:3], x_sd[:3], float(x[3])
    if judge_scale and abs(eps) > MAX_SCALE_ERROR and abs(eps) >= MIN_T * ar1_sd[3]:
        reason = (
            f"the tilt follows the gyro's angle as a gyro scale error of {100 * eps:+.0f} % would, not as a lever "
            "arm: check the gyro's range and unit, and its axes"
        )
        return LeverArmEstimate(None, no, span, np.nan, reason, warn=True)
    if np.linalg.norm(arm) > MAX_ARM_M:
        reason = f"{np.linalg.norm(arm):.0f} m is not a lever arm on a ship: another acceleration follows the rotation"
        return LeverArmEstimate(None, no, span, np.nan, reason, warn=True)
    fitted = design[:, :3] @ arm
    explained = 1.0 - float(np.sum((target - fitted) ** 2)) / max(float(target @ target), 1e-300)
    return LeverArmEstimate(arm, sd, span, explained, scale_error=eps)


def _hac_coef_cov(
    design: np.ndarray, resid: np.ndarray, vt: np.ndarray, s: np.ndarray, live: np.ndarray, lags: int
) -> np.ndarray:
    """Newey–West covariance of the least-squares coefficients in the singular directions: ``design`` (M, 3, k)
    and ``resid`` (M, 3) per block, scores gₜ = Σ_axes Dₜᵀeₜ, S = Γ₀ + Σ_{j ≤ lags} (1 − j/(lags+1))(Γⱼ + Γⱼᵀ),
    Cov = Σ⁻²Vᵀ S V Σ⁻² (``vt``, ``s``: the design's SVD; dead directions 0)."""
    g = np.einsum("mak,ma->mk", design, resid)
    sm = g.T @ g
    for j in range(1, min(lags, len(g) - 1) + 1):
        gj = g[j:].T @ g[:-j]
        sm += (1.0 - j / (lags + 1.0)) * (gj + gj.T)
    inv = np.where(live, 1.0 / s**2, 0.0)
    return (inv[:, None] * (vt @ sm @ vt.T)) * inv[None, :]


def _lag1(x: np.ndarray) -> float:
    x = x - x.mean()
    d = float(x @ x)
    return float(x[:-1] @ x[1:]) / d if d > 0 else 0.0


def estimate_lever_arm(
    time: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    run: Callable[[np.ndarray | None], tuple[np.ndarray, np.ndarray]],
) -> LeverArmEstimate:
    """The lever arm of the span ``time``/``gyro``/``accel`` (as :func:`lever_arm_regression`): ``run(arm)`` runs
    the filter on the same span with that lever arm (None: none) and returns its (q, gyro bias). One run with no arm
    and one regression on its attitude with the gyro's wave band (:func:`gyro_vertical`; module docstring); only
    where that finds a gyro scale error above SCALE_NOTE, FALLBACK_RUNS more runs told the arm (the iteration of
    before issue 52), on which the refusal of a wrong gyro rests."""
    q, bias = run(None)
    est = lever_arm_regression(time, gyro, accel, q, bias, wave_from_gyro=True)
    if est.arm_m is None or abs(est.scale_error) <= SCALE_NOTE:
        return est
    # a gyro scale error and an arm are confounded (the columns K are the measured rates'), and one regression
    # finds only part of the error (×1.5 on a 30-m bridge: −25 % with half the arm): the filter is told the arm
    # found and the regression repeated, as before issue 52 (FALLBACK_RUNS more runs), which the refusal rests on
    arm = est.arm_m
    for i in range(FALLBACK_RUNS):
        q, bias = run(arm)
        est = lever_arm_regression(time, gyro, accel, q, bias, judge_scale=i == FALLBACK_RUNS - 1)
        if est.arm_m is None:
            return est
        arm = est.arm_m
    return est


def _block_quats(q: np.ndarray, idx: np.ndarray, m: int) -> np.ndarray:
    """(m,4) the attitude ``q`` (N,4) at each block's middle row (rows in blocks ``idx``, sorted), of one sign
    from block to block; an empty block's interpolated between its neighbours (the fit leaves those out)."""
    first = np.searchsorted(idx, np.arange(m))
    last = np.searchsorted(idx, np.arange(m), side="right")
    out = np.full((m, 4), np.nan)
    full = last > first
    out[full] = q[(first[full] + last[full] - 1) // 2]
    good = np.flatnonzero(full)
    flip = np.concatenate([[False], np.einsum("ij,ij->i", out[good[1:]], out[good[:-1]]) < 0])
    out[good] *= np.where(np.cumsum(flip) % 2 == 1, -1.0, 1.0)[:, None]
    out = _fill_nan(out)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _quat_exp(rv: np.ndarray) -> np.ndarray:
    """(M,4) unit quaternions [w,x,y,z] of the rotation vectors ``rv`` (M,3) rad."""
    a = np.linalg.norm(rv, axis=1)
    s = np.where(a > 1e-12, np.sin(0.5 * a) / np.maximum(a, 1e-300), 0.5)
    return np.concatenate([np.cos(0.5 * a)[:, None], rv * s[:, None]], axis=1)


def _quat_scan(d: np.ndarray) -> np.ndarray:
    """Prefix products d₀ ⊗ d₁ ⊗ … ⊗ dₖ of (M,4) quaternions, in log₂ M vectorised steps (Hillis–Steele)."""
    p = d.copy()
    k = 1
    while k < len(p):
        p[k:] = quat_multiply(p[:-k], p[k:])
        k *= 2
    return p


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(M,3) the vectors ``v`` (M,3) turned by the unit quaternions ``q`` (M,4): R(q) v."""
    u, w = q[:, 1:], q[:, :1]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def gyro_vertical(q_blocks: np.ndarray, rate_blocks: np.ndarray, h: float, box: int) -> np.ndarray:
    """The vertical (M,3), a unit vector in the filter's NED frame, whose body-frame direction Rᵀm is the gyro's at
    wave periods and the filter's below: ``q_blocks`` (M,4) the filter's body→NED attitude per block,
    ``rate_blocks`` (M,3) rad/s its bias-corrected body rate per block (gaps filled), ``h`` s between blocks,
    ``box`` the high-pass's box (blocks).

    The gyro is integrated from the first block's attitude (centre to centre, the mean of two blocks' rates):
    R_g = D R_true, D the integration's error (slow: the start's and the bias's), and the filter's R_f = F R_true.
    In the gyro's frame the filter's vertical is b = R_g R_fᵀ ẑ = D Fᵀ ẑ: the true vertical D ẑ (slow) turned by the
    filter's tilt error only (Fᵀ ẑ: a heading error or jump of the filter, a magnet's, does not move it). Its slow
    part (b less the regression's high-pass, normalised) is the vertical the gyro's attitude is held to; turned back
    into the filter's frame, m = R_f R_gᵀ that."""
    steps = 0.5 * (rate_blocks[1:] + rate_blocks[:-1]) * h
    q_g = _quat_scan(np.concatenate([q_blocks[:1], _quat_exp(steps)]))
    e = quat_multiply(q_g, quat_conjugate(q_blocks))  # R_g R_fᵀ
    b = _rotate(e, np.tile([0.0, 0.0, 1.0], (len(e), 1)))
    n = b - _highpass(b, box)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return _rotate(quat_conjugate(e), n)
