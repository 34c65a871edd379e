"""Magnetometer hard/soft-iron calibration from full 3-D rotations (sphere fit).

Model, stated once for all of imutool::

    m_true = A (m_meas − b)          b: hard iron (µT, sensor axes), A: soft iron (3×3 symmetric positive-definite)

so that |m_true| = F (the local field strength) for every orientation. (The simulator's forward model is
m_meas = A_s m_true + b, hence A = A_s⁻¹ when A_s is symmetric.)

Method:

1. Algebraic ellipsoid-specific fit (Q. Li, J. G. Griffiths, "Least squares ellipsoid specific fitting",
   Proc. Geometric Modeling and Processing 2004): conic v = [a b c f g h p q r d] of
   a x² + b y² + c z² + 2f yz + 2g xz + 2h xy + 2p x + 2q y + 2r z + d = 0, minimise |D v|² subject to
   k J − I² = 1 (I = a+b+c, J = ab+bc+ca−f²−g²−h², k = 4), solved as the generalised eigenproblem
   (S11 − S12 S22⁻¹ S21) v1 = λ C1 v1, v2 = −S22⁻¹ S21 v1 (their eqs. 9–12). Data are centred and scaled first.
2. Nonlinear least squares refinement (scipy.optimize.least_squares, analytic Jacobian) of the geometric
   residual r_i = |A (m_i − b)| − F over b and the free elements of A for the chosen kind:
   ``offset`` (A = s·I: hard iron only), ``diag`` (axis-aligned scale), ``full`` (symmetric A).
3. Scale: with a given field strength F the fit returns A such that |m_true| = F; otherwise det A = 1
   (A preserves volume; F is then the geometric-mean radius), like MATLAB magcal.
4. Parameter covariance σ² (JᵀJ)⁻¹ with σ² = RSS / (N − p). Consecutive samples are correlated, so these
   one-sigma values are lower bounds.
5. Coverage of *field directions*: fraction of an equal-area grid on the unit sphere (Lambert cylindrical:
   ``n_bands`` bands equal in z, ``2·n_bands`` longitude sectors) that holds at least ``min_per_cell``
   corrected directions. Only directions of the field count, not of the noise: the samples are first averaged
   over ``COVERAGE_WINDOW`` consecutive samples (noise down 5×, a rotation barely blurred) and a mean counts only
   when its corrected magnitude is within ±30 % of the fitted field. A motionless recording (a noise cloud that
   a sphere fit happily blows up to "100 % coverage, field 3 µT") collapses to its centre or to one direction
   and covers ≈ 0 %: refused.
6. Every fitted A is checked: finite, symmetric positive-definite, condition number ≤ ``MAX_CONDITION``
   (real soft iron is a few tens of percent; a large ratio means the data did not determine A); b finite.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.atomic import atomic_path
from formats.errors import ImutoolError
from formats.jit.decorators import njit

KINDS = ("offset", "diag", "full", "auto")
# coverage needed for each kind (fraction of the equal-area sphere grid); below: refused
MIN_COVERAGE = {"offset": 0.25, "diag": 0.45, "full": 0.60}
WARN_COVERAGE = 0.75
COVERAGE_WINDOW = 25  # samples averaged before a direction counts (noise ÷ 5)
MAX_CONDITION = 4.0  # largest/smallest eigenvalue of a fitted soft-iron matrix
_IDX = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


@dataclass
class MagFit:
    """Result of a magnetometer calibration: m_true = A (m_meas − b), |m_true| ≈ field_ut."""

    b: np.ndarray  # µT
    A: np.ndarray  # 3×3 symmetric
    field_ut: float
    kind: str
    residual_rms_ut: float
    residual_rel: float  # residual RMS / field
    coverage: float
    n: int
    b_std: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    A_std: np.ndarray = field(default_factory=lambda: np.full((3, 3), np.nan))
    raw_rel_std: float = float("nan")  # std(|m_meas|)/mean before
    cal_rel_std: float = float("nan")  # std(|m_true|)/mean after
    reason: str = ""
    warnings: list[str] = field(default_factory=list)
    candidates: dict[str, dict[str, float]] = field(default_factory=dict)
    method: str = "sphere"
    extra: dict[str, Any] = field(default_factory=dict)

    def apply(self, m: np.ndarray) -> np.ndarray:
        """Corrected field (N,3) µT from measured (N,3) µT."""
        return (np.asarray(m, dtype=float) - self.b) @ self.A.T

    def to_section(self) -> dict[str, Any]:
        out = {
            "model": "m_true = A (m_meas - b)",
            "units": "b: uT (sensor axes); A: 1; field_ut: uT",
            "kind": self.kind,
            "method": self.method,
            "b": self.b.tolist(),
            "A": self.A.tolist(),
            "field_ut": float(self.field_ut),
            "b_std": self.b_std.tolist(),  # nan = not estimated (e.g. vertical terms of a swing)
            "A_std": self.A_std.tolist(),
        }
        out.update(self.extra.get("section", {}))
        return out

    def quality(self) -> dict[str, Any]:
        q = {
            "n": self.n,
            "residual_rms_ut": self.residual_rms_ut,
            "residual_relative": self.residual_rel,
            "coverage": self.coverage,
            "raw_field_relative_std": self.raw_rel_std,
            "calibrated_field_relative_std": self.cal_rel_std,
            "kind_reason": self.reason,
        }
        if self.warnings:
            q["warnings"] = "; ".join(self.warnings)
        return q


# -- coverage ------------------------------------------------------------------------------------------------
def sphere_coverage(directions: np.ndarray, n_bands: int = 8, min_per_cell: int | None = None) -> float:
    """Fraction of equal-area cells (n_bands × 2·n_bands, equal steps in z and longitude) that are visited.

    A cell counts when it holds ≥ min_per_cell directions (default max(3, 5 % of the mean count per cell), so a
    few noisy samples straddling a cell edge do not count as coverage).
    """
    u = np.asarray(directions, dtype=float)
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    u = u[np.all(np.isfinite(u), axis=1)]
    nz, nl = n_bands, 2 * n_bands
    iz = np.clip(((u[:, 2] + 1.0) / 2.0 * nz).astype(int), 0, nz - 1)
    il = np.clip(((np.arctan2(u[:, 1], u[:, 0]) + np.pi) / (2 * np.pi) * nl).astype(int), 0, nl - 1)
    counts = np.bincount(iz * nl + il, minlength=nz * nl)
    if min_per_cell is None:
        min_per_cell = max(3, int(0.05 * len(u) / (nz * nl)))
    return float(np.count_nonzero(counts >= min_per_cell)) / (nz * nl)


def field_direction_coverage(
    m: np.ndarray,
    b: np.ndarray,
    a: np.ndarray,
    field: float,
    n_bands: int = 8,
    window: int = COVERAGE_WINDOW,
    tolerance: float = 0.3,
) -> float:
    """Coverage of the calibrated field's directions (see module docstring, item 5).

    m: (N,3) samples in time order; b, A, field: a calibration with |A (m − b)| ≈ field. Moving means over
    ``window`` samples (fewer for short records: at most N/20) are corrected; those whose magnitude is within
    ``tolerance`` of the field give the directions counted by :func:`sphere_coverage` (cells need ≥ 3 of them).
    """
    m = np.asarray(m, dtype=float)
    m = m[np.all(np.isfinite(m), axis=1)]
    w = int(max(1, min(window, len(m) // 20)))
    if len(m) < w or not np.isfinite(field) or field <= 0:
        return 0.0
    c = np.cumsum(np.vstack([np.zeros((1, 3)), m]), axis=0)
    sm = (c[w:] - c[:-w]) / w
    y = (sm - b) @ np.asarray(a, dtype=float).T
    n = np.linalg.norm(y, axis=1)
    ok = np.abs(n - field) <= tolerance * field
    if np.count_nonzero(ok) < 3:
        return 0.0
    nz, nl = n_bands, 2 * n_bands
    cov = sphere_coverage(y[ok], n_bands, min_per_cell=max(3, int(0.05 * len(y) / (nz * nl))))
    return cov


def check_soft_iron(
    b: np.ndarray, a: np.ndarray, what: str = "fitted", max_condition: float = MAX_CONDITION
) -> str | None:
    """Why (b, A) is not a usable hard/soft-iron correction, or None: finite, A symmetric positive-definite,
    condition number ≤ max_condition."""
    b = np.asarray(b, dtype=float)
    a = np.asarray(a, dtype=float)
    if b.shape != (3,) or a.shape != (3, 3):
        return f"{what} b must be 3 numbers and A 3×3"
    if not (np.all(np.isfinite(b)) and np.all(np.isfinite(a))):
        return f"{what} b or A is not finite"
    if not np.allclose(a, a.T, rtol=1e-6, atol=1e-9 * max(1.0, float(np.max(np.abs(a))))):
        return f"{what} A is not symmetric"
    ev = np.linalg.eigvalsh(0.5 * (a + a.T))
    if ev[0] <= 0:
        rank = int(np.count_nonzero(np.abs(ev) > 1e-9 * max(1e-300, float(np.max(np.abs(ev))))))
        return f"{what} A is not positive-definite (eigenvalues {np.array2string(ev, precision=3)}, rank {rank})"
    cond = float(ev[-1] / ev[0])
    if cond > max_condition:
        return (
            f"{what} A is badly conditioned (eigenvalue ratio {cond:.3g} > {max_condition:g}; real soft iron "
            "is a few tens of percent)"
        )
    return None


# -- algebraic fit -------------------------------------------------------------------------------------------
def ellipsoid_fit_li(m: np.ndarray, k: float = 4.0) -> tuple[np.ndarray, np.ndarray, float]:
    """Li & Griffiths (2004) ellipsoid-specific algebraic fit. Returns (centre b, A with |A(m−b)| ≈ 1, 1).

    ``A`` is the symmetric square root of the normalised quadric matrix (unit-radius sphere after correction).
    """
    m = np.asarray(m, dtype=float)
    mu = m.mean(axis=0)
    sc = float(np.sqrt(np.mean(np.sum((m - mu) ** 2, axis=1))))
    if not np.isfinite(sc) or sc <= 0:
        raise ImutoolError("magnetometer data do not vary: cannot fit an ellipsoid")
    x, y, z = ((m - mu) / sc).T
    d = np.stack([x * x, y * y, z * z, 2 * y * z, 2 * x * z, 2 * x * y, 2 * x, 2 * y, 2 * z, np.ones_like(x)])
    s = d @ d.T
    s11, s12, s22 = s[:6, :6], s[:6, 6:], s[6:, 6:]
    c1 = np.zeros((6, 6))
    c1[:3, :3] = k / 2.0 - 1.0
    np.fill_diagonal(c1[:3, :3], -1.0)
    c1[3:, 3:] = np.diag([-k, -k, -k])
    try:
        s22i_s21 = np.linalg.solve(s22, s12.T)
        mm = s11 - s12 @ s22i_s21
        w, v = np.linalg.eig(np.linalg.solve(c1, mm))
    except np.linalg.LinAlgError:
        raise ImutoolError("ellipsoid fit: singular system (too few or degenerate magnetometer samples)") from None
    w = np.real(w)
    v = np.real(v)
    # the solution satisfies the constraint v1ᵀ C1 v1 > 0 (then λ = v1ᵀ M v1 / v1ᵀ C1 v1 ≥ 0: the unique
    # positive eigenvalue of Li & Griffiths; ≈ 0 for noise-free data)
    q = np.einsum("ij,ik,kj->j", v, c1, v)
    pos = np.flatnonzero(q > 0)
    if pos.size == 0:
        raise ImutoolError("ellipsoid fit: no ellipsoid solution (data too flat or too few orientations)")
    v1 = v[:, pos[np.argmin(np.abs(w[pos]))]]
    v2 = -s22i_s21 @ v1
    a, b_, c, f, g, h = v1
    p, q, r, dd = v2
    qm = np.array([[a, h, g], [h, b_, f], [g, f, c]])
    u = np.array([p, q, r])
    try:
        centre = -np.linalg.solve(qm, u)
    except np.linalg.LinAlgError:
        raise ImutoolError("ellipsoid fit: degenerate quadric") from None
    rhs = centre @ qm @ centre - dd
    qn = qm / rhs
    ev, evec = np.linalg.eigh(qn)
    if np.any(ev <= 0):
        raise ImutoolError("ellipsoid fit: the data do not describe an ellipsoid (coverage too poor?)")
    a_unit = evec @ np.diag(np.sqrt(ev)) @ evec.T  # unit radius in scaled coordinates
    return mu + sc * centre, a_unit / sc, 1.0


def sphere_fit_linear(m: np.ndarray) -> tuple[np.ndarray, float]:
    """Linear least-squares sphere: |m|² = 2 m·b + (R² − |b|²). Returns (centre µT, radius µT)."""
    m = np.asarray(m, dtype=float)
    mu = m.mean(axis=0)
    x = m - mu
    a = np.column_stack([2 * x, np.ones(len(x))])
    sol, *_ = np.linalg.lstsq(a, np.sum(x * x, axis=1), rcond=None)
    c = sol[:3]
    r2 = sol[3] + c @ c
    return mu + c, float(np.sqrt(max(r2, 1e-30)))


# -- nonlinear refinement ------------------------------------------------------------------------------------
def _unpack(p: np.ndarray, kind: str) -> tuple[np.ndarray, np.ndarray]:
    b = p[:3]
    if kind == "offset":
        return b, np.eye(3) * p[3]
    if kind == "diag":
        return b, np.diag(p[3:6])
    a = np.empty((3, 3))
    for j, (r, c) in enumerate(_IDX):
        a[r, c] = a[c, r] = p[3 + j]
    return b, a


def _pack(b: np.ndarray, a: np.ndarray, kind: str) -> np.ndarray:
    if kind == "offset":
        return np.concatenate([b, [np.cbrt(max(np.linalg.det(a), 1e-30))]])
    if kind == "diag":
        return np.concatenate([b, np.diag(a)])
    return np.concatenate([b, [a[r, c] for r, c in _IDX]])


@njit(cache=True)
def _res_jac_kernel(
    m: np.ndarray, b: np.ndarray, a: np.ndarray, field: float, jac: np.ndarray, want_jac: bool
) -> np.ndarray:  # pragma: no cover - numba
    """r_i = |A (m_i − b)| − field; jac (N,9): ∂r/∂b (3), ∂r/∂A diagonal (3), ∂r/∂A_01, A_02, A_12 (symmetric)."""
    n = m.shape[0]
    res = np.empty(n)
    for i in range(n):
        d0 = m[i, 0] - b[0]
        d1 = m[i, 1] - b[1]
        d2 = m[i, 2] - b[2]
        y0 = a[0, 0] * d0 + a[0, 1] * d1 + a[0, 2] * d2
        y1 = a[1, 0] * d0 + a[1, 1] * d1 + a[1, 2] * d2
        y2 = a[2, 0] * d0 + a[2, 1] * d1 + a[2, 2] * d2
        nn = np.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
        res[i] = nn - field
        if want_jac:
            if nn <= 0.0:
                nn = 1e-30
            u0, u1, u2 = y0 / nn, y1 / nn, y2 / nn
            jac[i, 0] = -(u0 * a[0, 0] + u1 * a[1, 0] + u2 * a[2, 0])
            jac[i, 1] = -(u0 * a[0, 1] + u1 * a[1, 1] + u2 * a[2, 1])
            jac[i, 2] = -(u0 * a[0, 2] + u1 * a[1, 2] + u2 * a[2, 2])
            jac[i, 3] = u0 * d0
            jac[i, 4] = u1 * d1
            jac[i, 5] = u2 * d2
            jac[i, 6] = u0 * d1 + u1 * d0
            jac[i, 7] = u0 * d2 + u2 * d0
            jac[i, 8] = u1 * d2 + u2 * d1
    return res


_NO_JAC = np.empty((0, 9))


def _residual(p: np.ndarray, m: np.ndarray, kind: str, field: float) -> np.ndarray:
    b, a = _unpack(p, kind)
    return _res_jac_kernel(m, np.ascontiguousarray(b), np.ascontiguousarray(a), float(field), _NO_JAC, False)


def _residual_jac(p: np.ndarray, m: np.ndarray, kind: str, field: float) -> tuple[np.ndarray, np.ndarray]:
    b, a = _unpack(p, kind)
    full = np.empty((len(m), 9))
    res = _res_jac_kernel(m, np.ascontiguousarray(b), np.ascontiguousarray(a), float(field), full, True)
    if kind == "full":
        return res, full
    if kind == "diag":
        return res, np.ascontiguousarray(full[:, :6])
    out = np.empty((len(m), 4))
    out[:, :3] = full[:, :3]
    out[:, 3] = full[:, 3:6].sum(axis=1)  # A = s·I: ∂r/∂s = Σ_i u_i d_i
    return res, out


def refine(
    m: np.ndarray, b0: np.ndarray, a0: np.ndarray, kind: str, field: float = 1.0, max_nfev: int = 50
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Levenberg–Marquardt refinement of b, A (kind) for residual |A(m−b)| − field. Returns (b, A, res, cov)."""
    p0 = _pack(b0, a0, kind)
    m = np.ascontiguousarray(m, dtype=np.float64)
    sol = least_squares(
        lambda p: _residual(p, m, kind, field),
        p0,
        jac=lambda p: _residual_jac(p, m, kind, field)[1],
        method="lm",
        max_nfev=max_nfev,
        x_scale="jac",
    )
    b, a = _unpack(sol.x, kind)
    res, j = _residual_jac(sol.x, m, kind, field)
    dof = max(1, len(m) - len(sol.x))
    s2 = float(res @ res) / dof
    try:
        cov = s2 * np.linalg.inv(j.T @ j)
    except np.linalg.LinAlgError:
        cov = np.full((len(sol.x), len(sol.x)), np.nan)
    return b, a, res, cov


def _std_from_cov(cov: np.ndarray, kind: str, scale: float) -> tuple[np.ndarray, np.ndarray]:
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    b_std = sd[:3]
    a_std = np.zeros((3, 3))
    if kind == "offset":
        a_std = np.eye(3) * sd[3]
    elif kind == "diag":
        a_std = np.diag(sd[3:6])
    else:
        for j, (r, c) in enumerate(_IDX):
            a_std[r, c] = a_std[c, r] = sd[3 + j]
    return b_std, a_std * scale


def _initial(
    m: np.ndarray, kind: str, li: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    if kind == "offset" or li is None:
        c, r = sphere_fit_linear(m)
        return c, np.eye(3) / r
    c, a = li
    if kind == "diag":
        a = np.diag(np.abs(np.diag(a)))
    return c, a


def fit_one(
    m: np.ndarray, kind: str, field_ut: float | None = None, li: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray, float, np.ndarray, np.ndarray, np.ndarray]:
    """Fit one kind. Returns (b, A, field, residuals µT, b_std, A_std) with the scale convention applied.

    ``li``: (centre, A) of the algebraic fit as the starting point (computed here when None).
    """
    if li is None and kind != "offset":
        try:
            li = ellipsoid_fit_li(m)[:2]
        except ImutoolError:
            li = None
    b0, a0 = _initial(m, kind, li)
    b, a, res, cov = refine(m, b0, a0, kind, 1.0)
    # ensure A positive-definite (sign ambiguity of the norm)
    if kind != "full":
        a = np.abs(a)
    else:
        ev, evec = np.linalg.eigh(a)
        if np.any(ev <= 0):
            a = evec @ np.diag(np.abs(ev)) @ evec.T
    if field_ut is not None and field_ut > 0:
        s = float(field_ut)
    else:
        s = float(np.cbrt(np.linalg.det(a))) ** -1  # det(sA) = 1
    b_std, a_std = _std_from_cov(cov, kind, s)
    return b, a * s, s, res * s, b_std, a_std


SPREAD_OVER_NOISE = 5.0  # a principal direction counts when the averaged field spreads this many noise σ along it
SPREAD_MIN_FRACTION = 0.005  # ... and by this fraction of the mean raw magnitude at least


def require_three_dimensions(m: np.ndarray) -> None:
    """Refuse samples (N,3) µT whose field does not move in three dimensions above the noise: a sphere or an
    ellipsoid through a point cloud, a line or a circle is not determined (its centre is free along the
    directions the data do not span), whatever coverage floor the user gave.

    The spread is taken on means of :data:`COVERAGE_WINDOW` consecutive samples (principal axes of their
    scatter, RMS µT) against the noise of such a mean (first differences of the samples, σ/√window)."""
    w = COVERAGE_WINDOW
    n = len(m) // w
    means = m[: n * w].reshape(n, w, 3).mean(axis=1) if n >= 4 else m
    sv = np.linalg.svd((means - means.mean(axis=0)) / np.sqrt(len(means)), compute_uv=False)
    sigma = float(np.max(np.std(np.diff(m, axis=0), axis=0))) / np.sqrt(2.0)
    noise = sigma / np.sqrt(w) if n >= 4 else sigma
    floor = max(SPREAD_OVER_NOISE * noise, SPREAD_MIN_FRACTION * float(np.mean(np.linalg.norm(m, axis=1))))
    rank = int(np.count_nonzero(sv > floor))
    if rank < 3:
        raise ImutoolError(
            f"the magnetometer field moves in only {rank} of 3 dimensions above the noise (spread "
            f"{', '.join(f'{v:.3g}' for v in sv)} µT RMS along its principal axes; needed > {floor:.3g} µT): "
            f"a hard/soft-iron fit is not determined (rank {rank} < 3), whatever --min-coverage says; rotate the "
            "sensor about several axes, or use --method swing for a sensor that only turns in heading"
        )


def calibrate_sphere(
    mag_ut: np.ndarray,
    kind: str = "auto",
    field_ut: float | None = None,
    min_coverage: float | None = None,
    n_bands: int = 8,
    max_samples: int | None = None,
) -> MagFit:
    """Full-sphere hard/soft-iron calibration of magnetometer samples (N,3) µT (see module docstring).

    kind: offset | diag | full | auto. auto fits all three and keeps the simplest whose residual RMS is within
    5 % of the best (and whose parameters are well determined); it says which and why in ``reason``.
    min_coverage: refuse a kind below this equal-area coverage (default per kind: offset 0.25, diag 0.45,
    full 0.60); a warning is added below 0.75.
    """
    if kind not in KINDS:
        raise ImutoolError(f"unknown fit kind {kind!r} (offset, diag, full, auto)")
    if field_ut is not None and not (np.isfinite(field_ut) and field_ut > 0):
        raise ImutoolError(f"field strength {field_ut} µT: must be a positive number (the Earth's is 20–70 µT)")
    if min_coverage is not None and not (np.isfinite(min_coverage) and 0 <= min_coverage <= 1):
        raise ImutoolError(f"minimum coverage {min_coverage}: must be between 0 and 1")
    m = np.asarray(mag_ut, dtype=float)
    m = m[np.all(np.isfinite(m), axis=1)]
    if len(m) < 20:
        raise ImutoolError(f"magnetometer calibration needs at least 20 valid samples; got {len(m)}")
    if max_samples and len(m) > max_samples:
        m = m[np.linspace(0, len(m) - 1, max_samples).astype(int)]
    # coverage of field directions from a first fit (noise averaged out, see field_direction_coverage)
    li = None
    c0, r0 = sphere_fit_linear(m)
    cov_frac = field_direction_coverage(m, c0, np.eye(3) / r0, 1.0, n_bands)
    try:
        c1, a1, _ = ellipsoid_fit_li(m)
        if check_soft_iron(c1, a1 * r0) is None:
            li = (c1, a1)
            cov_frac = max(cov_frac, field_direction_coverage(m, c1, a1, 1.0, n_bands))
    except ImutoolError:
        pass

    def need(k: str) -> float:
        return MIN_COVERAGE[k] if min_coverage is None else float(min_coverage)

    kinds = ["offset", "diag", "full"] if kind == "auto" else [kind]
    allowed = [k for k in kinds if cov_frac >= need(k)]
    if not allowed:
        k = kinds[0] if kind != "auto" else "offset"
        raise ImutoolError(
            f"field-direction coverage {100 * cov_frac:.0f}% of the sphere (equal-area grid {n_bands}×"
            f"{2 * n_bands}, noise averaged out), below the {100 * need(k):.0f}% needed for a '{k}' fit; rotate "
            "the sensor through many orientations (tumble it through every side up, or turn it about several axes), "
            "use --method swing for a sensor that only turns in heading, or lower --min-coverage at your own risk"
        )
    require_three_dimensions(m)  # whatever min_coverage allowed
    results = {}
    refused = {}
    for k in allowed:
        r = fit_one(m, k, field_ut, li)
        why = check_soft_iron(r[0], r[1], f"'{k}' fit:")
        if why is None:
            results[k] = r
        else:
            refused[k] = why
    if not results:
        raise ImutoolError(
            f"magnetometer calibration not determined by the data: {'; '.join(refused.values())}; "
            "rotate the sensor through more orientations"
        )
    allowed = [k for k in allowed if k in results]
    raw_n = np.linalg.norm(m, axis=1)
    raw_rel = float(np.std(raw_n) / np.mean(raw_n))
    cands = {
        k: {"residual_rms_ut": float(np.sqrt(np.mean(r[3] ** 2))), "params": {"offset": 4, "diag": 6, "full": 9}[k]}
        for k, r in results.items()
    }
    if kind == "auto":
        best = min(v["residual_rms_ut"] for v in cands.values())
        chosen = None
        for k in allowed:  # simplest first
            rel_unc = float(np.max(results[k][5]) / max(np.min(np.abs(np.diag(results[k][1]))), 1e-12))
            cands[k]["max_relative_A_std"] = rel_unc
            if cands[k]["residual_rms_ut"] <= 1.05 * best and rel_unc < 0.05:
                chosen = k
                break
        if chosen is None:
            chosen = allowed[-1]
        others = ", ".join(f"{k} {v['residual_rms_ut']:.3g} µT" for k, v in cands.items())
        reason = (
            f"auto chose '{chosen}': simplest kind whose residual RMS is within 5% of the best and whose A is "
            f"well determined (residuals: {others}; coverage {100 * cov_frac:.0f}%"
            + (
                f"; {'/'.join(k for k in kinds if k not in allowed)} not allowed at this coverage"
                if len(allowed) < 3
                else ""
            )
            + ")"
        )
    else:
        chosen = kind
        reason = f"'{kind}' requested"
    b, a, s, res, b_std, a_std = results[chosen]
    corr = (m - b) @ a.T
    cn = np.linalg.norm(corr, axis=1)
    # the coverage the chosen calibration itself sees (field directions, noise averaged out)
    cov_fit = field_direction_coverage(m, b, a, float(np.mean(cn)), n_bands)
    if cov_fit < need(chosen):
        raise ImutoolError(
            f"calibrated field-direction coverage {100 * cov_fit:.0f}% of the sphere, below the "
            f"{100 * need(chosen):.0f}% needed for a '{chosen}' fit; rotate the sensor through many orientations "
            "(every side up), or use --method swing for a sensor that only turns in heading"
        )
    cov_frac = cov_fit
    warns = []
    if refused:
        warns.append("not determined by the data: " + "; ".join(refused.values()))
    f_est = float(np.mean(cn)) if field_ut is None else float(field_ut)
    if field_ut is None and not 10.0 <= f_est <= 150.0:
        warns.append(f"fitted field {f_est:.3g} µT is not the Earth's (20–70 µT): check the magnetometer unit")
    if cov_frac < WARN_COVERAGE:
        warns.append(f"coverage only {100 * cov_frac:.0f}% of the sphere: soft-iron terms are weakly determined")
    fit = MagFit(
        b=b,
        A=a,
        field_ut=float(np.mean(cn)) if field_ut is None else float(field_ut),
        kind=chosen,
        residual_rms_ut=float(np.sqrt(np.mean(res**2))),
        residual_rel=float(np.sqrt(np.mean(res**2)) / np.mean(cn)),
        coverage=cov_frac,
        n=len(m),
        b_std=b_std,
        A_std=a_std,
        raw_rel_std=raw_rel,
        cal_rel_std=float(np.std(cn) / np.mean(cn)),
        reason=reason,
        warnings=warns,
        candidates=cands,
    )
    return fit


# -- convention crosswalk ------------------------------------------------------------------------------------
def crosswalk(b: np.ndarray, a: np.ndarray, form: str) -> str:
    """Text of the parameters in another tool's convention (matlab | fusion | magneto | json)."""
    b = np.asarray(b, dtype=float)
    a = np.asarray(a, dtype=float)

    def mat(x: np.ndarray, fmt: str = "{:+.6f}") -> str:
        return "\n".join("  [" + ", ".join(fmt.format(v) for v in row) + "]" for row in x)

    if form == "matlab":
        return (
            "% MATLAB magcal convention: C = (D - b) * A   (rows of D are samples; A symmetric)\n"
            "% imutool m_true = A (m_meas - b) as a column vector is the same as a row vector (m - b) * A'.\n"
            "% A is symmetric, so MATLAB A = imutool A, b = imutool b (same units, uT).\n"
            f"b = [{', '.join(f'{v:.6f}' for v in b)}];\nA = [\n{mat(a)}\n];\n"
        )
    if form == "fusion":
        return (
            "// x-io Fusion convention: m_cal = S (m - h)   (FusionCalibrationMagnetic(m, softIronMatrix,"
            " hardIronOffset))\n// S = imutool A (soft-iron matrix), h = imutool b (hard-iron offset)\n"
            "const FusionMatrix softIronMatrix = {" + ", ".join(f"{v:.6f}f" for v in a.ravel()) + "};\n"
            "const FusionVector hardIronOffset = {" + ", ".join(f"{v:.6f}f" for v in b) + "};\n"
        )
    if form == "magneto":
        return (
            "Magneto (sailboatinstruments) convention: h_cal = A^-1_magneto (h - b), printed as\n"
            "'Combined bias (b)' and 'Correction for combined scale factors, misalignments and soft iron "
            "(A^-1)'.\nThe correction matrix Magneto prints is imutool A; b is imutool b.\n"
            "Combined bias (b):\n  " + "  ".join(f"{v:.6f}" for v in b) + "\n"
            "Correction for combined scale factors, misalignments and soft iron (A^-1):\n"
            + "\n".join("  " + "  ".join(f"{v:.6f}" for v in row) for row in a)
            + "\n"
        )
    if form == "json":
        return json.dumps({"model": "m_true = A (m_meas - b)", "b_uT": b.tolist(), "A": a.tolist()}, indent=2)
    raise ImutoolError(f"unknown form {form!r} (matlab, fusion, magneto, json)")


NORMALISED_TOL = 0.05  # a fitted |m| within 5 % of 1 (in whatever unit) is a normalised magnetometer
CONSTANT_FIELD_REL_STD = 0.005  # raw |m| constant to 0.5 %: calibrated or normalised before it was logged


def absent_information(fit: MagFit, field_given: bool = False) -> list[str]:
    """What a fit cannot say about this magnetometer, one line each: the field strength of a normalised
    magnetometer (|m| ≈ 1, unit-less: b and the field are in that unit, not µT), and the sensor's own iron when
    |m| is already constant (the data were calibrated or normalised before they were logged)."""
    out = []
    if not field_given and abs(fit.field_ut - 1.0) <= NORMALISED_TOL:
        out.append(
            f"field strength unknown: the magnetometer is normalised (|m| = {fit.field_ut:.3g}), so b and the field "
            "are in its normalised unit, not µT (give --field-ut to scale A to a known field)"
        )
    if fit.raw_rel_std < CONSTANT_FIELD_REL_STD:
        out.append(
            f"hard/soft iron unknown: |m| is already constant (relative std {100 * fit.raw_rel_std:.2g}% before "
            "the fit): the data were calibrated or normalised before they were logged, so b ≈ 0 and A ≈ I say "
            "nothing of the sensor's own iron"
        )
    return out


def plot_before_after(m: np.ndarray, fit: MagFit, path: str, title: str = "Magnetometer calibration") -> None:
    """Before/after plot (:func:`before_after_figure`) written atomically to ``path`` (.png, .pdf, .svg)."""
    import matplotlib.pyplot as plt

    fig = before_after_figure(m, fit, title)
    ext = str(path).rsplit(".", 1)[-1].lower()
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=ext if ext in ("png", "pdf", "svg") else "png", dpi=100)
    finally:
        plt.close(fig)


def _hist_bins(*values: np.ndarray, n: int = 60) -> np.ndarray:
    """Common histogram bin edges of |m| values; a spread too small for ``n`` bins (a normalised or already
    calibrated magnetometer: |m| constant) gets ±1 % around the mean."""
    v = np.concatenate([np.asarray(x, float).ravel() for x in values])
    v = v[np.isfinite(v)]
    if v.size == 0:
        return np.linspace(0.0, 1.0, n + 1)
    lo, hi = float(v.min()), float(v.max())
    mid = 0.5 * (lo + hi)
    half = max(0.5 * (hi - lo), 0.01 * abs(mid), 1e-9)
    return np.linspace(mid - half, mid + half, n + 1)


def before_after_figure(m: np.ndarray, fit: MagFit, title: str = "Magnetometer calibration") -> Any:
    """Before/after figure: three projections of raw and corrected samples plus |m| histograms (the caller
    saves and closes it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = np.asarray(m, dtype=float)
    m = m[np.all(np.isfinite(m), axis=1)]
    step = max(1, len(m) // 5000)
    raw = m[::step]
    cal = fit.apply(raw)
    fig, axs = plt.subplots(2, 2, figsize=(10, 9))
    pairs = [(0, 1, "x", "y"), (0, 2, "x", "z"), (1, 2, "y", "z")]
    th = np.linspace(0, 2 * np.pi, 200)
    for ax, (i, j, li, lj) in zip(axs.ravel()[:3], pairs, strict=True):
        ax.plot(raw[:, i], raw[:, j], ".", ms=1.5, color="C3", alpha=0.5, label="raw")
        ax.plot(cal[:, i], cal[:, j], ".", ms=1.5, color="C0", alpha=0.5, label="calibrated")
        ax.plot(fit.field_ut * np.cos(th), fit.field_ut * np.sin(th), "k--", lw=0.8, label=f"|m| = {fit.field_ut:.1f}")
        ax.set_aspect("equal")
        ax.set_xlabel(f"m_{li} (µT)")
        ax.set_ylabel(f"m_{lj} (µT)")
        ax.grid(alpha=0.3)
    axs[0, 0].legend(fontsize=7, markerscale=5)
    ax = axs[1, 1]
    nr, nc = np.linalg.norm(raw, axis=1), np.linalg.norm(cal, axis=1)
    bins = _hist_bins(nr, nc)
    ax.hist(nr, bins=bins, color="C3", alpha=0.6, label=f"raw: std/mean {100 * np.std(nr) / np.mean(nr):.1f}%")
    ax.hist(nc, bins=bins, color="C0", alpha=0.6, label=f"calibrated: {100 * np.std(nc) / np.mean(nc):.2f}%")
    ax.set_xlabel("|m| (µT)")
    ax.legend(fontsize=8)
    fig.suptitle(
        f"{title}: kind {fit.kind}, residual {fit.residual_rms_ut:.3g} µT, coverage "
        f"{100 * fit.coverage:.0f}%\nmodel m_true = A (m_meas − b)",
        fontsize=10,
    )
    fig.tight_layout()
    return fig
