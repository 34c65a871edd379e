"""Compass deviation card: δ(ψ) = A + B sinψ + C cosψ + D sin2ψ + E cos2ψ (degrees).

Convention: ψ is the **compass heading** (what the instrument reads, degrees clockwise from the compass's
north) and the deviation is what is *added* to it: magnetic heading = ψ + δ(ψ); true heading = magnetic +
variation (east positive). The coefficients come from an ordinary least-squares fit of δ_i = ψ_ref,i − ψ_i
(wrapped to ±180°) against the compass heading, with the parameter covariance σ² (XᵀX)⁻¹ (σ² from the residuals;
samples are time-correlated, so with many samples per heading this is optimistic — also reported per heading bin).
A (constant: misaligned lubber line / induced symmetrical), B, C (hard iron: semicircular), D, E (soft iron:
quadrantal) — the classical Airy/Archibald Smith coefficients.

Mariner's notation: deviation and variation are written E/W (E = add to the compass/magnetic reading). The card
has two tables at 15° steps: compass → magnetic (what the compass reads → what it means) and magnetic →
compass (the course to steer), the second from the inverse of ψ + δ(ψ) = M, solved by Newton's method (not
approximated by −δ(M)). Limits flagged by the fit (:data:`DEVIATION_LIMIT_DEG`, :data:`FIT_LIMIT_DEG`):

- |δ| above 5° on any heading: ISO 25862 (as quoted by a secondary source, not seen in the standard:
  confidence C) asks for ≤ 3° after adjusting a new ship and ≤ 5° thereafter; the Panama Canal asks for
  < 7° (OP Notice N-1-2022, quoted by a compass adjuster: confidence B). Beyond 5° the compass wants adjusting;
- a systematic residual above 1° in any 15° heading bin, or a residual RMS above 1°: the five-term model does
  not describe this compass (ISO 22090-2's static-error limit for a transmitting magnetic heading device is
  ±1.0°, confidence B);
- |δ| above 20°, or a card that cannot be inverted (1 + dδ/dψ ≤ 0 somewhere): an absurd card — almost always a
  calibration or mounting that does not belong to this recording.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from formats.atomic import atomic_path
from formats.errors import ImutoolError
from formats.frames import angle_diff_deg, wrap_deg180

NAMES = ("A", "B", "C", "D", "E")
DEVIATION_LIMIT_DEG = 5.0  # adjust the compass above this (ISO 25862 as quoted; confidence C)
FIT_LIMIT_DEG = 1.0  # model misfit above this (per 15° bin or RMS)
ABSURD_DEG = 20.0  # a card beyond this is almost surely a mismatched calibration
MAX_NOISE_GAIN = 4.0  # coefficient noise gain vs one residual (full swing ≈ 1.4; 250° span ≈ 4)


def ew(value_deg: float | None, decimals: int = 1) -> str:
    """Mariner's notation: 3.2° E / 1.5° W (E = add); '—' for unknown."""
    if value_deg is None or not np.isfinite(value_deg):
        return "—"
    v = round(float(value_deg), decimals)
    if v == 0:
        return f"{0:.{decimals}f}°"
    return f"{abs(v):.{decimals}f}° {'E' if v > 0 else 'W'}"


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
    header: dict[str, Any] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

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

    def slope(self, heading_deg: np.ndarray) -> np.ndarray:
        """dδ/dψ (deg per deg) at compass headings ψ (degrees)."""
        p = np.radians(np.asarray(heading_deg, dtype=float))
        return np.radians(
            self.B * np.cos(p) - self.C * np.sin(p) + 2 * self.D * np.cos(2 * p) - 2 * self.E * np.sin(2 * p)
        )

    def invertible(self) -> bool:
        """True when ψ ↦ ψ + δ(ψ) is one-to-one (1 + dδ/dψ > 0 on every heading)."""
        return bool(np.min(1.0 + self.slope(np.arange(0.0, 360.0, 0.5))) > 0.05)

    def compass_from_magnetic(self, magnetic_deg: np.ndarray) -> np.ndarray:
        """Compass heading ψ in [0, 360) with ψ + δ(ψ) = magnetic (degrees): the course to steer.

        Newton's method from ψ₀ = M − δ(M); converges to < 1e-9° in a few steps for any card with
        |dδ/dψ| < 1. Raises ImutoolError for a card that cannot be inverted (an absurd card)."""
        if not self.invertible():
            raise ImutoolError(
                "the deviation card cannot be inverted (compass heading not unique for some "
                "magnetic headings): the card is absurd — check the calibration and mounting"
            )
        m = np.asarray(magnetic_deg, dtype=float)
        psi = m - self.deviation_deg(m)
        for _ in range(50):
            f = wrap_deg180(psi + self.deviation_deg(psi) - m)
            step = f / (1.0 + self.slope(psi))
            psi = psi - step
            if np.all(~np.isfinite(step) | (np.abs(step) < 1e-10)):
                break
        return psi % 360.0

    def max_abs_deg(self) -> float:
        """Largest |δ| over the circle (deg)."""
        return float(np.max(np.abs(self.deviation_deg(np.arange(0.0, 360.0, 0.5)))))

    def table_magnetic(self, step_deg: float = 15.0) -> list[tuple[float, float, float]]:
        """Magnetic → compass: (magnetic heading, deviation at the compass heading, compass heading to steer)."""
        mag = np.arange(0.0, 360.0, step_deg)
        psi = self.compass_from_magnetic(mag)
        d = self.deviation_deg(psi)
        return [(float(m), float(x), float(p)) for m, x, p in zip(mag, d, psi, strict=True)]

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
        if self.invertible():
            out["magnetic_to_compass_15deg"] = [[m, round(p, 3)] for m, _, p in self.table_magnetic(15.0)]
        if self.header:
            out["header"] = {k: v for k, v in self.header.items() if v not in (None, "")}
        if self.warnings:
            out["warnings"] = list(self.warnings)
        return out

    @classmethod
    def from_section(cls, s: dict[str, Any], path: str | None = None) -> DeviationCard:
        try:
            vals = {n: float(s.get(n, 0.0)) for n in NAMES}
        except (TypeError, ValueError):
            raise ImutoolError("calibration deviation: coefficients A–E must be numbers", path=path) from None
        std = {k: float(v) for k, v in (s.get("std") or {}).items()}
        header = dict(s.get("header") or {})
        return cls(**vals, std=std, header=header, warnings=[str(w) for w in (s.get("warnings") or [])])


def fit_deviation(
    compass_deg: np.ndarray,
    reference_deg: np.ndarray,
    *,
    min_span_deg: float = 270.0,
    terms: int = 5,
    limit_deg: float = DEVIATION_LIMIT_DEG,
    fit_limit_deg: float = FIT_LIMIT_DEG,
    max_noise_gain: float = MAX_NOISE_GAIN,
) -> DeviationCard:
    """Least-squares deviation card from compass headings and reference (magnetic) headings, degrees.

    δ_i = wrap(ref_i − compass_i); X = [1, sinψ, cosψ, sin2ψ, cos2ψ]; coefficients = argmin |X c − δ|².
    Refuses (ImutoolError) when the compass headings cover less than ``min_span_deg`` of the circle, or — whatever
    ``min_span_deg`` says — when the headings cannot separate the harmonics: a coefficient's noise gain
    √(n (XᵀX)⁻¹ᵢᵢ) above ``max_noise_gain`` (1.4 for a full, even swing; a 250° arc ≈ 4; 90° ≈ 190).
    ``terms`` = 3 fits A, B, C only. Residuals per 15° heading bin go into ``quality['residuals_15deg']``
    ([heading, n, mean, RMS]);
    warnings (deviation beyond ``limit_deg``, misfit beyond ``fit_limit_deg``, an absurd card) into
    ``card.warnings`` (see the module docstring for the limits and their sources).
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
            "A–E harmonics); swing the vessel through a full turn"
        )
    x = _design(c)[:, :terms]
    gain = np.sqrt(np.clip(np.diag(np.linalg.pinv(x.T @ x)), 0, None) * c.size)
    if not np.all(np.isfinite(gain)) or gain.max() > max_noise_gain:
        worst = NAMES[int(np.nanargmax(gain))] if np.any(np.isfinite(gain)) else "?"
        raise ImutoolError(
            f"compass headings cover {covered:.0f}° of the circle: too narrow to separate the A–E harmonics "
            f"(noise gain of {worst} = {np.nanmax(gain):.1f} × the residual, limit {max_noise_gain:g}; a full "
            "swing gives 1.4). A card from this would be an extrapolation: swing the vessel through a full turn"
        )
    d = angle_diff_deg(r, c)
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
    # residuals per 15° bin centred on the card headings (000 covers 352.5–7.5)
    b15 = np.floor(((c + 7.5) % 360.0) / 15.0).astype(int)
    per = []
    for k in range(24):
        m = b15 == k
        if m.any():
            per.append([15.0 * k, int(m.sum()), float(np.mean(res[m])), float(np.sqrt(np.mean(res[m] ** 2)))])
    rms = float(np.sqrt(np.mean(res**2)))
    card.quality = {
        "n": int(c.size),
        "residual_rms_deg": rms,
        "residual_max_deg": float(np.max(np.abs(res))),
        "heading_coverage_deg": float(covered),
        "noise_gain_max": float(gain.max()),
        "std_note": "one sigma from the residuals, scaled to independent 10-degree heading bins",
        "residuals_15deg": per,
        "residuals_15deg_columns": ["compass heading deg", "n", "mean deg", "rms deg"],
    }
    card.warnings = card_warnings(card, limit_deg, fit_limit_deg)
    return card


def card_warnings(
    card: DeviationCard, limit_deg: float = DEVIATION_LIMIT_DEG, fit_limit_deg: float = FIT_LIMIT_DEG
) -> list[str]:
    """Warnings for a card: absurd / beyond the adjusting limit / model misfit (limits: module docstring)."""
    out: list[str] = []
    mx = card.max_abs_deg()
    if mx > ABSURD_DEG or not card.invertible():
        out.append(
            f"absurd card: |deviation| reaches {mx:.0f}°"
            + ("" if card.invertible() else " and the card cannot be inverted")
            + " — an uncalibrated magnetometer (calibrate mag --method "
            "swing first) or a calibration/mounting that does not belong to this recording; do not issue this "
            "card"
        )
    elif mx > limit_deg:
        dd = card.deviation_deg(np.arange(0.0, 360.0, 0.5))
        out.append(
            f"deviation reaches {ew(dd[np.argmax(np.abs(dd))])} (> {limit_deg:g}°): the compass should be "
            "adjusted (ISO 25862 as quoted: ≤ 5° in service, "
            "≤ 3° after adjusting a new ship — confidence C; Panama Canal: < 7°)"
        )
    q = card.quality or {}
    rms = q.get("residual_rms_deg")
    bad = [b for b in q.get("residuals_15deg", []) if abs(b[2]) > fit_limit_deg]
    if rms is not None and rms > fit_limit_deg:
        out.append(
            f"residual {rms:.2f}° RMS > {fit_limit_deg:g}°: the reference is noisy or the five-term model "
            "does not fit this compass"
        )
    if bad:
        hs = ", ".join(f"{b[0]:03.0f}° ({b[2]:+.1f}°)" for b in bad[:6])
        out.append(
            f"systematic residual > {fit_limit_deg:g}° at {hs}: the five-term model does not fit there "
            "(local disturbance, heeling error or a reference/time-offset problem)"
        )
    return out


def card_text(card: DeviationCard, header: dict[str, Any] | None = None, step_deg: float = 15.0) -> str:
    """The deviation card as text: header block, coefficients, both tables (E/W), residuals, warnings,
    adjuster's signature line."""
    h = dict(card.header)
    h.update({k: v for k, v in (header or {}).items() if v not in (None, "")})
    labels = [
        ("vessel", "Vessel"),
        ("compass", "Compass"),
        ("place", "Place"),
        ("date", "Date of swing"),
        ("latitude", "Latitude"),
        ("longitude", "Longitude"),
        ("variation", "Variation"),
        ("reference", "Reference used"),
        ("conditions", "Swing conditions"),
        ("adjuster", "Adjuster"),
    ]
    lines = ["DEVIATION CARD", "=" * 78]
    for key, lab in labels:
        v = h.get(key)
        if key == "latitude" and isinstance(v, (int, float)):
            v = f"{abs(v):.3f}° {'N' if v >= 0 else 'S'}"
        if key == "longitude" and isinstance(v, (int, float)):
            v = f"{abs(v):.3f}° {'E' if v >= 0 else 'W'}"
        if key == "variation" and isinstance(v, (int, float)):
            v = ew(v) + (f" ({h['variation_source']})" if h.get("variation_source") else "")
        lines.append(f"{lab + ':':<18s} {v if v not in (None, '') else '—'}")
    lines += [
        "",
        "δ(ψ) = A + B sin ψ + C cos ψ + D sin 2ψ + E cos 2ψ  (ψ compass heading; magnetic = compass + δ;"
        " E = add, W = subtract)",
        "  " + "   ".join(f"{n} = {ew(getattr(card, n), 2)}" for n in NAMES),
        "",
    ]
    comp = card.table(step_deg)
    try:
        mag = card.table_magnetic(step_deg)
    except ImutoolError:
        mag = None
    lines.append(f"{'COMPASS → MAGNETIC':<38s}  {'MAGNETIC → COMPASS (course to steer)'}")
    lines.append(
        f"{'compass':>8s} {'deviation':>10s} {'magnetic':>9s}      {'magnetic':>8s} {'deviation':>10s} {'steer':>7s}"
    )
    for i, (p, d, m) in enumerate(comp):
        left = f"{p:7.0f}° {ew(d):>10s} {m:8.1f}°"
        if mag is not None:
            mm, dd, pp = mag[i]
            right = f"{mm:7.0f}° {ew(dd):>10s} {pp:6.1f}°"
        else:
            right = "   (card not invertible)" if i == 0 else ""
        lines.append(f"{left}      {right}")
    per = (card.quality or {}).get("residuals_15deg")
    if per:
        lines += ["", "Residuals (observed − card) per 15° compass-heading bin: heading mean / RMS (n)"]
        cells = [f"{b[0]:03.0f}° {b[2]:+.2f}/{b[3]:.2f} ({b[1]})" for b in per]
        for i in range(0, len(cells), 4):
            lines.append("  " + "   ".join(cells[i : i + 4]))
        q = card.quality
        lines.append(
            f"  overall {q['residual_rms_deg']:.2f}° RMS, max {q['residual_max_deg']:.2f}°, "
            f"{q['n']} samples, {q['heading_coverage_deg']:.0f}° of the circle swung"
        )
    ws = card.warnings or card_warnings(card)
    if ws:
        lines.append("")
        for w in ws:
            lines += textwrap.wrap(f"WARNING: {w}", width=110, subsequent_indent="         ")
    lines += [
        "",
        "Adjusted / swung by: ______________________________   Signature: ____________________   Date: ____________",
        "",
    ]
    return "\n".join(lines)


def _covered_deg(c: np.ndarray) -> float:
    """Circle covered by the headings: 360° minus the largest gap between neighbouring headings (deg)."""
    s = np.sort(np.asarray(c, dtype=float) % 360.0)
    gaps = np.diff(np.concatenate([s, [s[0] + 360.0]]))
    return float(360.0 - gaps.max())


def plot_card(
    card: DeviationCard,
    path: str,
    compass_deg: np.ndarray | None = None,
    deviation_obs_deg: np.ndarray | None = None,
    title: str = "Deviation card",
    header: dict[str, Any] | None = None,
) -> None:
    """Card as curve + the text card (header, both tables every 15°, residuals, warnings, signature line) to
    PNG, SVG or PDF (format from the extension)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(8.27, 11.0))
    ax = fig.add_axes((0.1, 0.62, 0.85, 0.30))
    psi = np.linspace(0, 360, 721)
    if compass_deg is not None and deviation_obs_deg is not None:
        step = max(1, len(compass_deg) // 4000)
        ax.plot(
            np.asarray(compass_deg)[::step] % 360,
            np.asarray(deviation_obs_deg)[::step],
            ".",
            ms=2,
            color="0.6",
            label="observed (reference − compass)",
        )
    ax.plot(psi, card.deviation_deg(psi), "C0", lw=2, label="fitted δ(ψ)")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlim(0, 360)
    ax.set_xticks(np.arange(0, 361, 45))
    ax.set_xlabel("compass heading ψ (deg)")
    ax.set_ylabel("deviation δ (deg, + = add to compass)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    coef = ", ".join(
        f"{n} = {getattr(card, n):+.2f}°" + (f" ± {card.std[n]:.2f}" if n in card.std else "") for n in NAMES
    )
    ax.set_title(f"{title}\nδ = A + B sinψ + C cosψ + D sin2ψ + E cos2ψ\n{coef}", fontsize=9)
    txt = card_text(card, header)
    fig.text(0.05, 0.54, txt, family="monospace", fontsize=5.6, va="top", ha="left")
    ext = str(path).rsplit(".", 1)[-1].lower()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=ext if ext in ("png", "pdf", "svg") else "png", dpi=110)
    plt.close(fig)
