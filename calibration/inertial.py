"""Gyro and accelerometer calibration in port: rest detection, gyro bias (+ temperature slope, + scale and
misalignment from known turns), accelerometer bias/scale/misalignment from many static poses against |g|.

Models (as applied by :class:`calibration.file.Calibration`):
  gyro   ω = S (ω_meas − b − k (T − T_ref))      rad/s; k rad/s/°C; S 3×3 (scale + misalignment)
  accel  f = T (f_meas − b)                      m/s²; T 3×3 upper-triangular (scale + non-orthogonality)
Local gravity from latitude: WGS-84 normal gravity (Somigliana), γ(φ) = γe (1 + k sin²φ) / √(1 − e² sin²φ),
γe = 9.7803253359 m/s², k = 0.00193185265241, e² = 0.00669437999013, minus 3.086e-6·h (free air).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from formats.errors import ImutoolError


def normal_gravity(latitude_deg: float, height_m: float = 0.0) -> float:
    """WGS-84 normal gravity (m/s²) at geodetic latitude (deg) and ellipsoidal height (m)."""
    s2 = np.sin(np.radians(latitude_deg)) ** 2
    g = 9.7803253359 * (1 + 0.00193185265241 * s2) / np.sqrt(1 - 0.00669437999013 * s2)
    return float(g - 3.086e-6 * height_m)


def _moving_std(x: np.ndarray, w: int) -> np.ndarray:
    """Centred moving standard deviation (N,) of each column of x (N,k) over w samples; max over columns."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    n = len(x)
    w = max(2, min(w, n))
    x0 = x - np.nanmean(x, axis=0)
    c1 = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x0, axis=0)])
    c2 = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x0 * x0, axis=0)])
    lo = np.clip(np.arange(n) - w // 2, 0, n - w)
    hi = lo + w
    s1 = c1[hi] - c1[lo]
    s2 = c2[hi] - c2[lo]
    var = np.clip(s2 / w - (s1 / w) ** 2, 0, None)
    return np.sqrt(var).max(axis=1)


def detect_rest(
    time: np.ndarray,
    gyro: np.ndarray | None,
    accel: np.ndarray | None,
    *,
    window_s: float = 1.0,
    gyro_std: float = np.radians(0.5),
    accel_std: float = 0.1,
    min_rest_s: float = 2.0,
    trim_s: float = 0.25,
) -> list[tuple[int, int]]:
    """Rest intervals [(start, stop) index pairs, stop exclusive]: moving std (window_s) of every gyro axis below
    gyro_std (rad/s) and of every accel axis below accel_std (m/s²), at least min_rest_s long; trim_s cut from
    both ends."""
    t = np.asarray(time, dtype=float)
    if len(t) < 4:
        raise ImutoolError("too few samples to detect rest")
    fs = (len(t) - 1) / float(t[-1] - t[0])  # mean rate: host timestamps of buffered sensors come in bursts
    w = max(3, int(round(window_s * fs)))
    still = np.ones(len(t), dtype=bool)
    if gyro is not None:
        still &= _moving_std(gyro, w) < gyro_std
    if accel is not None:
        still &= _moving_std(accel, w) < accel_std
    if gyro is None and accel is None:
        raise ImutoolError("rest detection needs gyro or accel")
    edges = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    trim = int(round(trim_s * fs))
    out = []
    for a, b in zip(starts, stops, strict=True):
        a2, b2 = a + trim, b - trim
        if b2 > a2 and t[b2 - 1] - t[a2] >= min_rest_s:
            out.append((int(a2), int(b2)))
    return out


@dataclass
class GyroCal:
    """Gyro calibration: ω = S (ω_meas − b − k (T − T_ref))."""

    bias: np.ndarray
    temp_slope: np.ndarray | None = None
    temp_ref: float | None = None
    scale: np.ndarray | None = None
    n_rest: int = 0
    rest_s: float = 0.0
    quality: dict[str, Any] = field(default_factory=dict)

    def to_section(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "model": "w = S (w_meas - b - k (T - T_ref))",
            "units": "b: rad/s; k: rad/s/degC; T_ref: degC; S: 1",
            "bias": self.bias.tolist(),
            "bias_deg_s": np.degrees(self.bias).tolist(),
        }
        if self.temp_slope is not None:
            out["temp_slope"] = self.temp_slope.tolist()
            out["temp_ref"] = float(self.temp_ref or 0.0)
        if self.scale is not None:
            out["scale"] = self.scale.tolist()
        return out


def calibrate_gyro(
    time: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray | None = None,
    temp: np.ndarray | None = None,
    *,
    min_temp_range: float = 1.0,
    turns_deg: float | None = None,
    **rest_opts: Any,
) -> GyroCal:
    """Static gyro bias = mean over the detected rest intervals (rad/s); a temperature slope (least squares
    ω = b + k (T − T_ref)) when ``temp`` spans ≥ min_temp_range °C over the rest samples; with ``turns_deg``,
    every motion between two rests is taken as a turn of that many degrees about one sensor axis and
    S (3×3, scale + misalignment) is the least-squares solution of S ∫(ω − b) dt = θ·axis (needs ≥ 3 turns
    about different axes)."""
    t = np.asarray(time, dtype=float)
    g = np.asarray(gyro, dtype=float)
    rests = detect_rest(t, g, accel, **rest_opts)
    if not rests:
        raise ImutoolError(
            "no rest interval found (lower the thresholds, e.g. --gyro-std, or keep the sensor still for a few seconds)"
        )
    idx = np.concatenate([np.arange(a, b) for a, b in rests])
    gr = g[idx]
    ok = np.all(np.isfinite(gr), axis=1)
    idx, gr = idx[ok], gr[ok]
    bias = gr.mean(axis=0)
    cal = GyroCal(bias=bias, n_rest=len(rests), rest_s=float(sum(t[b - 1] - t[a] for a, b in rests)))
    cal.quality = {
        "rest_intervals": len(rests),
        "rest_seconds": cal.rest_s,
        "rest_std_rad_s": gr.std(axis=0).tolist(),
        "bias_std_rad_s": (gr.std(axis=0) / np.sqrt(max(1, len(rests)))).tolist(),
    }
    if temp is not None:
        tc = np.asarray(temp, dtype=float)[idx]
        good = np.isfinite(tc)
        # a slope needs a temperature that varies, whatever min_temp_range allows (0 °C: a constant temperature
        # would give a singular fit); the span must also exceed the float rounding of the values
        span = float(np.ptp(tc[good])) if good.any() else 0.0
        varies = span > 1e-6 * max(1.0, float(np.max(np.abs(tc[good])))) if good.any() else False
        if good.sum() > 10 and span >= min_temp_range and varies:
            tref = float(np.mean(tc[good]))
            x = np.column_stack([np.ones(good.sum()), tc[good] - tref])
            coef, *_ = np.linalg.lstsq(x, gr[good], rcond=None)
            cal.bias, cal.temp_slope, cal.temp_ref = coef[0], coef[1], tref
            cal.quality["temp_range_degC"] = float(np.ptp(tc[good]))
        elif not varies:
            cal.quality["temp_note"] = "temperature constant over the rests: no slope fitted (not determined)"
        else:
            cal.quality["temp_note"] = f"temperature range {span:.2f} °C < {min_temp_range} °C: no slope fitted"
    if turns_deg is not None:
        cal.scale, info = _gyro_scale(t, g - cal.bias, rests, np.radians(turns_deg))
        cal.quality.update(info)
    return cal


def _gyro_scale(
    t: np.ndarray, w: np.ndarray, rests: list[tuple[int, int]], angle: float
) -> tuple[np.ndarray, dict[str, Any]]:
    us, vs = [], []
    for (_a0, b0), (a1, _b1) in zip(rests[:-1], rests[1:], strict=True):
        seg = slice(b0 - 1, a1 + 1)
        ww = w[seg]
        dt = np.diff(t[seg])
        integ = np.sum(0.5 * (ww[1:] + ww[:-1]) * dt[:, None], axis=0)
        ax = int(np.argmax(np.abs(integ)))
        if abs(integ[ax]) < 0.5 * angle:
            continue
        v = np.zeros(3)
        v[ax] = np.sign(integ[ax]) * angle
        us.append(integ)
        vs.append(v)
    u, v = np.array(us), np.array(vs)
    axes_seen = {int(np.argmax(np.abs(x))) for x in v} if len(v) else set()
    if len(axes_seen) < 3:
        raise ImutoolError(
            f"gyro scale needs turns of {np.degrees(angle):.0f}° about all three axes between rests;"
            f" found turns about {len(axes_seen)} axis/axes"
        )
    st, *_ = np.linalg.lstsq(u, v, rcond=None)  # u S^T = v
    s = st.T
    res = v - u @ st
    return s, {"turns": len(u), "turn_residual_deg": float(np.degrees(np.sqrt(np.mean(res**2))))}


@dataclass
class AccelCal:
    """Accelerometer calibration: f = T (f_meas − b), |f| = g at rest."""

    bias: np.ndarray
    T: np.ndarray
    gravity: float
    kind: str
    poses: np.ndarray  # (P,3) mean specific force per pose (raw)
    residual_rms: float
    bias_std: np.ndarray
    quality: dict[str, Any] = field(default_factory=dict)

    def apply(self, f: np.ndarray) -> np.ndarray:
        return (np.asarray(f, dtype=float) - self.bias) @ self.T.T

    def to_section(self) -> dict[str, Any]:
        return {
            "model": "f = T (f_meas - b)",
            "units": "b: m/s^2; T: 1",
            "kind": self.kind,
            "bias": self.bias.tolist(),
            "T": self.T.tolist(),
            "gravity_m_s2": self.gravity,
            "bias_std": self.bias_std.tolist(),
        }


_UT = ((0, 1), (0, 2), (1, 2))
MAX_FIT_CONDITION = 1e6  # largest/smallest singular value of a fit's column-scaled Jacobian; above: not determined


def _jacobian_rank(jac: np.ndarray) -> tuple[int, float]:
    """(numerical rank, condition number) of a least-squares Jacobian with its columns scaled to unit norm (so
    parameters of different units compare); a column of zeros is a parameter the data do not touch."""
    j = np.asarray(jac, dtype=float)
    norms = np.linalg.norm(j, axis=0)
    if not np.all(np.isfinite(j)) or np.any(norms == 0):
        return int(np.count_nonzero(norms > 0)), float("inf")
    sv = np.linalg.svd(j / norms, compute_uv=False)
    rank = int(np.count_nonzero(sv > 1e-10 * sv[0]))
    return rank, float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")


def calibrate_accel(
    time: np.ndarray,
    accel: np.ndarray,
    gyro: np.ndarray | None = None,
    *,
    gravity: float = 9.80665,
    kind: str = "auto",
    min_poses: int = 6,
    **rest_opts: Any,
) -> AccelCal:
    """Six/many-position accelerometer calibration from automatically detected static poses.

    Each rest interval gives one mean specific force f_i; nearly identical poses (< 5° apart) are merged.
    Fit b (3) and T (``diag``: scale, 6 params; ``full``: upper-triangular scale + non-orthogonality, 9 params)
    minimising Σ (|T (f_i − b)| − g)² (scipy least_squares). auto: full with ≥ 9 poses, else diag.
    The rotation part of T is unobservable from |g| alone, hence upper-triangular.
    """
    t = np.asarray(time, dtype=float)
    f = np.asarray(accel, dtype=float)
    rests = detect_rest(t, gyro, f, **rest_opts)
    poses = []
    for a, b in rests:
        m = np.nanmean(f[a:b], axis=0)
        if np.all(np.isfinite(m)):
            poses.append(m)
    merged: list[np.ndarray] = []
    for p in poses:
        for i, q in enumerate(merged):
            c = p @ q / (np.linalg.norm(p) * np.linalg.norm(q))
            if c > np.cos(np.radians(5.0)):
                merged[i] = 0.5 * (q + p)
                break
        else:
            merged.append(p)
    pz = np.array(merged)
    if len(pz) < min_poses:
        raise ImutoolError(
            f"found {len(pz)} distinct static poses; at least {min_poses} needed (six-position: "
            "each axis up and down, a few seconds still in each)"
        )
    if kind == "auto":
        kind = "full" if len(pz) >= 9 else "diag"
    if kind not in ("offset", "diag", "full"):
        raise ImutoolError(f"unknown accel fit kind {kind!r} (offset, diag, full, auto)")
    npar = {"offset": 3, "diag": 6, "full": 9}[kind]
    if len(pz) < npar:  # whatever --min-poses says: fewer equations than unknowns determine nothing
        raise ImutoolError(
            f"found {len(pz)} distinct static pose(s) for a '{kind}' fit of {npar} parameters: the data cannot "
            f"determine it (rank ≤ {len(pz)} < {npar}); hold the sensor still in at least {npar} orientations "
            "(six-position: each axis up and down)"
        )

    def unpack(p):
        tm = np.eye(3)
        if kind != "offset":
            tm = np.diag(p[3:6])
        if kind == "full":
            for j, (r, c) in enumerate(_UT):
                tm[r, c] = p[6 + j]
        return p[:3], tm

    def fun(p):
        b, tm = unpack(p)
        return np.linalg.norm((pz - b) @ tm.T, axis=1) - gravity

    p0 = np.zeros(npar)
    if kind != "offset":
        p0[3:6] = 1.0
    sol = least_squares(fun, p0, method="trf" if len(pz) <= npar else "lm", x_scale="jac")
    b, tm = unpack(sol.x)
    res = fun(sol.x)
    rank, cond = _jacobian_rank(sol.jac)
    if rank < npar or cond > MAX_FIT_CONDITION:
        raise ImutoolError(
            f"the {len(pz)} static poses do not determine a '{kind}' accelerometer fit (Jacobian rank {rank} of "
            f"{npar}, condition {cond:.3g}): the poses point in too few directions; add poses with each axis "
            "up and down"
        )
    dof = len(pz) - npar
    if dof > 0:
        s2 = float(res @ res) / dof
        try:
            sd = np.sqrt(np.clip(np.diag(s2 * np.linalg.inv(sol.jac.T @ sol.jac)), 0, None))
        except np.linalg.LinAlgError:
            sd = np.full(npar, np.nan)
    else:
        sd = np.full(npar, np.nan)
    cal = AccelCal(
        bias=b,
        T=tm,
        gravity=gravity,
        kind=kind,
        poses=pz,
        residual_rms=float(np.sqrt(np.mean(res**2))),
        bias_std=sd[:3],
    )
    cal.quality = {
        "poses": len(pz),
        "rest_intervals": len(rests),
        "residual_rms_m_s2": cal.residual_rms,
        "dof": dof,
        "raw_norm_spread_m_s2": float(np.ptp(np.linalg.norm(pz, axis=1))),
    }
    if dof <= 0:
        cal.quality["note"] = "as many parameters as poses: exact fit, no uncertainty (add poses)"
    return cal
