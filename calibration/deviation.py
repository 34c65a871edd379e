"""Compass deviation card: δ(ψ) = A + B sinψ + C cosψ + D sin2ψ + E cos2ψ (degrees).

Convention: ψ is the **compass heading** (what the instrument reads, degrees clockwise from the compass's
north) and the deviation is what is *added* to it: magnetic heading = ψ + δ(ψ); true heading = magnetic +
variation (east positive). The coefficients come from an ordinary least-squares fit of δ_i = ψ_ref,i − ψ_i
(wrapped to ±180°) against the compass heading, with the parameter covariance σ² (XᵀX)⁻¹ (σ² from the residuals;
samples are time-correlated, so with many samples per heading this is optimistic — also reported per heading bin).
A (constant: misaligned lubber line / induced symmetrical), B, C (hard iron: semicircular), D, E (soft iron:
quadrantal) — the classical Airy/Archibald Smith coefficients.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from formats.errors import ImutoolError
from formats.frames import wrap_deg180

NAMES = ("A", "B", "C", "D", "E")


def _design(psi_deg: np.ndarray) -> np.ndarray:
    p = np.radians(np.asarray(psi_deg, dtype=float))
    return np.stack([np.ones_like(p), np.sin(p), np.cos(p), np.sin(2 * p), np.cos(2 * p)], axis=-1)


@dataclass
class DeviationCard:
    """Coefficients A–E in degrees (and their one-sigma uncertainties), applied to compass headings."""

    A: float = 0.0
    B: float = 0.0
    C: float = 0.0
    D: float = 0.0
    E: float = 0.0
    std: dict[str, float] = field(default_factory=dict)
    quality: dict[str, Any] = field(default_factory=dict)

    @property
    def coefficients(self) -> np.ndarray:
        return np.array([self.A, self.B, self.C, self.D, self.E])

    def deviation_deg(self, heading_deg: np.ndarray) -> np.ndarray:
        """δ(ψ) in degrees for compass headings ψ (degrees); magnetic = ψ + δ(ψ)."""
        h = np.asarray(heading_deg, dtype=float)
        return _design(h) @ self.coefficients

    def correct(self, heading_deg: np.ndarray) -> np.ndarray:
        """Magnetic heading in [0, 360) from compass heading (degrees)."""
        h = np.asarray(heading_deg, dtype=float)
        return (h + self.deviation_deg(h)) % 360.0

    def table(self, step_deg: float = 15.0) -> list[tuple[float, float, float]]:
        """The card: (compass heading, deviation, magnetic heading) every ``step_deg`` degrees."""
        psi = np.arange(0.0, 360.0, step_deg)
        d = self.deviation_deg(psi)
        return [(float(p), float(x), float((p + x) % 360.0)) for p, x in zip(psi, d, strict=True)]

    def to_section(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "model": "magnetic = compass + A + B sin(psi) + C cos(psi) + D sin(2 psi) + E cos(2 psi); psi = compass",
            "units": "deg",
        }
        for n in NAMES:
            out[n] = float(getattr(self, n))
        if self.std:
            out["std"] = {k: float(v) for k, v in self.std.items()}
        out["card_15deg"] = [[p, round(d, 3)] for p, d, _ in self.table(15.0)]
        return out

    @classmethod
    def from_section(cls, s: dict[str, Any], path: str | None = None) -> DeviationCard:
        try:
            vals = {n: float(s.get(n, 0.0)) for n in NAMES}
        except (TypeError, ValueError):
            raise ImutoolError("calibration deviation: coefficients A–E must be numbers", path=path) from None
        std = {k: float(v) for k, v in (s.get("std") or {}).items()}
        return cls(**vals, std=std)


def fit_deviation(compass_deg: np.ndarray, reference_deg: np.ndarray, *, min_span_deg: float = 270.0,
                  terms: int = 5) -> DeviationCard:
    """Least-squares deviation card from compass headings and reference (magnetic) headings, degrees.

    δ_i = wrap(ref_i − compass_i); X = [1, sinψ, cosψ, sin2ψ, cos2ψ]; coefficients = argmin |X c − δ|².
    Refuses (ImutoolError) when the compass headings cover less than ``min_span_deg`` of the circle (the
    harmonics are then not separable). ``terms`` = 3 fits A, B, C only.
    """
    c = np.asarray(compass_deg, dtype=float)
    r = np.asarray(reference_deg, dtype=float)
    ok = np.isfinite(c) & np.isfinite(r)
    c, r = c[ok] % 360.0, r[ok]
    if c.size < 10:
        raise ImutoolError(f"deviation fit needs headings with a reference; only {c.size} usable samples")
    covered = _covered_deg(c)
    if covered < min_span_deg:
        raise ImutoolError(
            f"compass headings cover only {covered:.0f}° of the circle (< {min_span_deg:.0f}° needed for the "
            "A–E harmonics); swing the vessel through a full turn")
    d = wrap_deg180(r - c)
    x = _design(c)[:, :terms]
    coef, *_ = np.linalg.lstsq(x, d, rcond=None)
    res = d - x @ coef
    dof = max(1, c.size - terms)
    s2 = float(res @ res) / dof
    cov = s2 * np.linalg.inv(x.T @ x)
    # per-heading-bin (10°) spread: a more honest uncertainty when samples are correlated in time
    bins = np.floor(c / 10.0).astype(int)
    nb = len(np.unique(bins))
    cov_bins = cov * (c.size / max(nb, terms + 1))
    full = np.zeros(5)
    full[:terms] = coef
    std = {n: float(np.sqrt(cov_bins[i, i])) for i, n in enumerate(NAMES[:terms])}
    card = DeviationCard(*full, std=std)
    card.quality = {
        "n": int(c.size),
        "residual_rms_deg": float(np.sqrt(np.mean(res ** 2))),
        "residual_max_deg": float(np.max(np.abs(res))),
        "heading_coverage_deg": float(covered),
        "std_note": "one sigma from the residuals, scaled to independent 10-degree heading bins",
    }
    return card


def _covered_deg(c: np.ndarray) -> float:
    """Circle covered by the headings: 360° minus the largest gap between neighbouring headings (deg)."""
    s = np.sort(np.asarray(c, dtype=float) % 360.0)
    gaps = np.diff(np.concatenate([s, [s[0] + 360.0]]))
    return float(360.0 - gaps.max())


def plot_card(card: DeviationCard, path: str, compass_deg: np.ndarray | None = None,
              deviation_obs_deg: np.ndarray | None = None, title: str = "Deviation card") -> None:
    """Card as curve + table (every 15°) to PNG or PDF (format from the extension)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from formats.atomic import atomic_path

    fig = plt.figure(figsize=(8.27, 11.0))
    ax = fig.add_axes((0.1, 0.58, 0.85, 0.36))
    psi = np.linspace(0, 360, 721)
    if compass_deg is not None and deviation_obs_deg is not None:
        step = max(1, len(compass_deg) // 4000)
        ax.plot(np.asarray(compass_deg)[::step] % 360, np.asarray(deviation_obs_deg)[::step], ".", ms=2,
                color="0.6", label="observed (reference − compass)")
    ax.plot(psi, card.deviation_deg(psi), "C0", lw=2, label="fitted δ(ψ)")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlim(0, 360)
    ax.set_xticks(np.arange(0, 361, 45))
    ax.set_xlabel("compass heading ψ (deg)")
    ax.set_ylabel("deviation δ (deg, + = add to compass)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    coef = ", ".join(f"{n} = {getattr(card, n):+.2f}°" + (f" ± {card.std[n]:.2f}" if n in card.std else "")
                     for n in NAMES)
    ax.set_title(f"{title}\nδ = A + B sinψ + C cosψ + D sin2ψ + E cos2ψ\n{coef}", fontsize=9)
    rows = card.table(15.0)
    tab = fig.add_axes((0.1, 0.03, 0.85, 0.48))
    tab.axis("off")
    half = (len(rows) + 1) // 2
    cells = []
    for i in range(half):
        a = rows[i]
        b = rows[i + half] if i + half < len(rows) else None
        cells.append([f"{a[0]:03.0f}°", f"{a[1]:+.1f}°", f"{a[2]:05.1f}°"]
                     + ([f"{b[0]:03.0f}°", f"{b[1]:+.1f}°", f"{b[2]:05.1f}°"] if b else ["", "", ""]))
    t = tab.table(cellText=cells, colLabels=["compass", "deviation", "magnetic"] * 2, loc="upper center",
                  cellLoc="center")
    t.scale(1, 1.4)
    ext = str(path).rsplit(".", 1)[-1].lower()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=ext if ext in ("png", "pdf", "svg") else "png", dpi=110)
    plt.close(fig)
