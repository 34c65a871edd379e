"""Allan deviation (overlapping) and the IEEE Std 952 noise terms of a gyro/accelerometer/magnetometer.

Overlapping Allan variance of a rate signal y sampled at τ0, cluster time τ = m τ0, with θ_k = τ0 Σ_{i<k} y_i:

    σ²(τ) = 1 / (2 τ² (N − 2m)) · Σ_k (θ_{k+2m} − 2 θ_{k+m} + θ_k)²

computed from the cumulative sum (numba kernel) on log-spaced τ: cluster sizes m < 16 in one fused pass over
every k (the exact overlapping estimator); for m ≥ 16 the sum runs over every s-th k, s = the largest power of two
≤ m/8 (m rounded to a multiple of s), on θ decimated by s — still heavily overlapping, so the variance of the
estimate barely changes, while 24 h of 200 Hz data take a few seconds.

Noise terms (σ²(τ) = N²/τ + (0.664 B)² + K² τ/3 near the flat part):
  - N: angle (velocity) random walk, read on the slope −½ line at τ = 1 s (unit/√Hz = unit·√s … per √s);
  - B: bias instability = min σ(τ) / 0.664 (= √(2 ln 2 / π)) — only when a flicker floor is there: without one
    the minimum is the white/random-walk crossover (σ² = 2NK/√3 at τ = √3 N/K) and is labelled so
    (``B_kind``; see :func:`fit_noise_terms`);
  - K: rate (acceleration) random walk, read on the slope +½ line at τ = 3 s (unit/√s); when the +½ slope is
    not seen (recording too short) K is not resolved and only the bound K ≤ min σ(τ) √(3/τ) is known.
The lines are placed by a weighted non-negative least-squares fit of the three-term model to σ²(τ) (weights
from the number of independent clusters), which is steadier than reading one point where the slope is ±½.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import nnls

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.atomic import atomic_path
from formats.errors import ImutoolError
from formats.jit.decorators import njit

BI_FACTOR = 0.6643  # √(2 ln 2 / π)


SMALL_M = 16  # cluster sizes below this use every k (exact overlapping estimator)


def _stride(m: int) -> int:
    """Sub-sampling step of k for cluster size m: the largest power of two ≤ m // 8 (1 below SMALL_M)."""
    if m < SMALL_M:
        return 1
    return 1 << (int(m // 8).bit_length() - 1)


def _round_m(m: int) -> int:
    s = _stride(m)
    return s * max(1, round(m / s))


@njit(cache=True)
def _adev_axis(
    y: np.ndarray, dt: float, ms: np.ndarray, out: np.ndarray, theta: np.ndarray, dec: np.ndarray
) -> None:  # pragma: no cover - numba
    """Overlapping Allan deviation of one axis y (N,) for increasing cluster sizes ms into out (len ms).

    θ_k = dt Σ_{i<k} (y_i − ȳ) (mean removed: σ unchanged, θ stays small). Cluster sizes below 16 are summed
    over every k in one fused pass; larger ones over k = 0, s, 2s, ... (s = power of two ≤ m/8, m a multiple of s)
    on θ decimated by s, so long τ cost little. theta (N+1) and dec (N//2 + 1) are scratch buffers reused
    across axes (no page faults per call)."""
    n = y.shape[0]
    mean = 0.0
    for i in range(n):
        mean += y[i]
    mean /= n
    nt = n + 1
    theta[0] = 0.0
    acc = 0.0
    for i in range(n):
        acc += (y[i] - mean) * dt
        theta[i + 1] = acc
    ns = 0
    while ns < ms.shape[0] and ms[ns] < 16:
        ns += 1
    if ns > 0:
        sums = np.zeros(ns)
        kend = max(nt - 2 * ms[ns - 1], 0)
        for k in range(kend):
            t0 = theta[k]
            for j in range(ns):
                m = ms[j]
                d = theta[k + 2 * m] - 2.0 * theta[k + m] + t0
                sums[j] += d * d
        for j in range(ns):
            m = ms[j]
            for k in range(kend, nt - 2 * m):
                d = theta[k + 2 * m] - 2.0 * theta[k + m] + theta[k]
                sums[j] += d * d
            tau = m * dt
            out[j] = np.sqrt(sums[j] / (2.0 * tau * tau * max(nt - 2 * m, 1)))
    level = 1
    ln = nt
    for j in range(ns, ms.shape[0]):
        m = ms[j]
        s = 1
        while s * 2 <= m // 8:
            s *= 2
        while level < s:  # decimate by 2 (in place after the first step): dec[i] = θ[i · 2·level]
            src = theta if level == 1 else dec
            ln = (ln + 1) // 2
            for i in range(ln):
                dec[i] = src[2 * i]
            level *= 2
        if level == 1:
            src = theta
        else:
            src = dec
        mm = m // level
        acc = 0.0
        for k in range(ln - 2 * mm):
            d = src[k + 2 * mm] - 2.0 * src[k + mm] + src[k]
            acc += d * d
        tau = m * dt
        out[j] = np.sqrt(acc / (2.0 * tau * tau * max(ln - 2 * mm, 1)))


def tau_grid(n: int, dt: float, per_decade: int = 10) -> np.ndarray:
    """Cluster sizes m (int, unique, increasing, log-spaced) from 1 to (n − 1) // 9 (at least ~9 clusters);
    sizes ≥ 16 are rounded to a multiple of their sub-sampling step (see :func:`_stride`)."""
    mmax = max(1, (n - 1) // 9)
    m = np.unique(np.round(np.logspace(0, np.log10(mmax), int(per_decade * np.log10(max(mmax, 10))) + 1)))
    r = sorted({_round_m(int(x)) for x in m})
    return np.array([x for x in r if x <= mmax] or [1], dtype=np.int64)


def allan_deviation(
    y: np.ndarray, rate_hz: float, per_decade: int = 10, m: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Overlapping Allan deviation of a rate signal y (N,) or (N,k). Returns (τ s, σ(τ) (len τ, k), n_eff).

    n_eff: number of independent clusters ≈ (N − 2m) / m, for the confidence of each point (σ relative
    uncertainty ≈ 1 / √(2 n_eff)). NaN samples are refused (fill or cut them first).
    """
    y = np.asarray(y, dtype=float)
    one = y.ndim == 1
    y2 = y[:, None] if one else y
    if not np.all(np.isfinite(y2)):
        raise ImutoolError("Allan deviation: the signal has NaN/inf samples; cut them out first")
    n = y2.shape[0]
    if n < 20:
        raise ImutoolError(f"Allan deviation needs at least 20 samples; got {n}")
    dt = 1.0 / rate_hz
    if m is None:
        ms = tau_grid(n, dt, per_decade)
    else:
        ms = np.array(sorted({_round_m(int(x)) for x in np.asarray(m).ravel()}), dtype=np.int64)
    out = np.empty((len(ms), y2.shape[1]))
    col = np.empty(n)
    theta = np.empty(n + 1)
    dec = np.empty(n // 2 + 2)
    for j in range(y2.shape[1]):
        col[:] = y2[:, j]
        res = np.empty(len(ms))
        _adev_axis(col, dt, ms, res, theta, dec)
        out[:, j] = res
    taus = ms * dt
    n_eff = np.maximum((n - 2 * ms) / ms, 1.0)
    return taus, (out[:, 0] if one else out), n_eff


def fit_noise_terms(
    taus: np.ndarray, adev: np.ndarray, n_eff: np.ndarray, flicker_share: float = 0.25
) -> dict[str, float | bool | str]:
    """N (τ=1 line), B (min/0.664), K (τ=3 line) for one axis; plus what the minimum is and whether K is seen.

    ``B_kind``: ``"bias instability"`` when the fitted flat (flicker) term carries at least ``flicker_share`` of
    σ² at the minimum; else ``"crossover"`` when N and K alone explain the minimum — the white/random-walk
    crossover, σ_min² = 2NK/√3 at τ = √3 N/K, which is *not* a bias instability (B is then only an upper bound) —
    or ``"upper bound"`` when σ still falls at the longest τ. ``K_resolved``: the +½ slope is seen (K > 0, the
    minimum is not at the end, and the K term carries ≥ ``flicker_share`` of σ² at the longest τ); ``K_upper``:
    the bound K ≤ min over τ of σ(τ) √(3/τ) (σ²(τ) ≥ K²τ/3 whatever the other noise), with σ(τ) raised by twice
    its estimation error 1/√(2 n_eff) so that the scatter of few long clusters does not push the bound below K.
    """
    a2 = adev**2
    w = np.sqrt(n_eff) / a2  # relative weighting: each point's σ² has relative std ≈ 1/√(n_eff/2)
    x = np.column_stack([1.0 / taus, np.ones_like(taus), taus / 3.0]) * w[:, None]
    coef, _ = nnls(x, a2 * w)
    n_, b0, k_ = np.sqrt(np.clip(coef, 0, None))
    i = int(np.argmin(adev))
    at_end = bool(i >= len(taus) - 2)
    if b0**2 >= flicker_share * a2[i]:
        kind = "bias instability"  # the flat (flicker) term is there, whether or not σ has turned up yet
    elif at_end:
        kind = "upper bound"
    else:
        kind = "crossover"
    k_resolved = bool(k_ > 0 and not at_end and k_**2 * taus[-1] / 3.0 >= flicker_share * a2[-1])
    return {
        "N": float(n_),
        "B": float(adev[i] / BI_FACTOR),
        "K": float(k_),
        "tau_min_s": float(taus[i]),
        "adev_min": float(adev[i]),
        "flat_B_fit": float(b0 / BI_FACTOR),
        "B_upper_bound": kind != "bias instability",
        "B_kind": kind,
        "K_resolved": k_resolved,
        "K_upper": float(np.min(adev * (1.0 + 2.0 / np.sqrt(2.0 * n_eff)) * np.sqrt(3.0 / taus))),
    }


@dataclass
class AllanResult:
    """Allan deviation of one sensor channel (3 axes) with its noise terms."""

    name: str
    unit: str
    taus: np.ndarray
    adev: np.ndarray  # (len τ, 3)
    n_eff: np.ndarray
    terms: list[dict[str, float]] = field(default_factory=list)

    def mean_term(self, key: str) -> float:
        return float(np.mean([t[key] for t in self.terms]))

    def summary(self) -> dict[str, Any]:
        return {
            k: [t[k] for t in self.terms]
            for k in ("N", "B", "K", "tau_min_s", "B_upper_bound", "B_kind", "K_resolved", "K_upper")
        }


def analyse(y: np.ndarray, rate_hz: float, name: str, unit: str, per_decade: int = 10) -> AllanResult:
    if not (np.isfinite(rate_hz) and 1e-6 < rate_hz < 1e7):
        raise ImutoolError(f"Allan deviation: sample rate {rate_hz:.3g} Hz is not plausible (check the time column)")
    taus, adev, n_eff = allan_deviation(y, rate_hz, per_decade)
    adev2 = adev if adev.ndim == 2 else adev[:, None]
    if not np.all(np.isfinite(adev2)):
        raise ImutoolError("Allan deviation is not finite (values too large for double precision?)")
    if np.any(adev2 <= 0):
        raise ImutoolError(
            f"{name}: the signal does not change at some cluster times (Allan deviation 0): a "
            "constant or stuck channel has no noise terms to fit"
        )
    terms = [fit_noise_terms(taus, adev2[:, j], n_eff) for j in range(adev2.shape[1])]
    return AllanResult(name, unit, taus, adev2, n_eff, terms)


def plot_allan(results: list[AllanResult], path: str, title: str = "Allan deviation") -> None:
    """Log-log Allan deviation per axis with the fitted N (slope −½), B (flat) and K (slope +½) lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(len(results), 1, figsize=(8, 4.2 * len(results)), squeeze=False)
    for ax, r in zip(axs[:, 0], results, strict=True):
        for j, lab in enumerate("xyz"[: r.adev.shape[1]]):
            t = r.terms[j]
            c = f"C{j}"
            bl = "B" if t.get("B_kind", "bias instability") == "bias instability" else f"min/0.664 ({t['B_kind']})"
            kl = f"K={t['K']:.3g}" if t.get("K_resolved", True) else f"K≤{t['K_upper']:.3g} (not resolved)"
            ax.loglog(
                r.taus, r.adev[:, j], "-", color=c, lw=1.5, label=f"{lab}: N={t['N']:.3g}, {bl}={t['B']:.3g}, {kl}"
            )
            tt = r.taus
            ax.loglog(tt, t["N"] / np.sqrt(tt), ":", color=c, lw=0.8)
            ax.loglog(tt, t["K"] * np.sqrt(tt / 3.0), "--", color=c, lw=0.8)
            ax.axhline(t["B"] * BI_FACTOR, color=c, lw=0.6, ls="-.")
            ax.plot([1.0], [t["N"]], "o", color=c, ms=4)
            ax.plot([3.0], [t["K"]], "s", color=c, ms=4)
        lo, hi = np.nanmin(r.adev), np.nanmax(r.adev)
        ax.set_ylim(lo / 3, hi * 3)
        ax.set_xlabel("cluster time τ (s)")
        ax.set_ylabel(f"σ(τ) ({r.unit})")
        ax.set_title(
            f"{r.name}: N at τ=1 s (slope −½, dotted), B = min/0.664 (dash-dot), K at τ=3 s (slope +½, dashed)",
            fontsize=8,
        )
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    ext = str(path).rsplit(".", 1)[-1].lower()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=ext if ext in ("png", "pdf", "svg") else "png", dpi=100)
    plt.close(fig)
