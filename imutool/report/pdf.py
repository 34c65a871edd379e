"""PDF rendering of an evidence report with matplotlib (PdfPages): text pages with tables, then plot pages.

The PDF is written atomically (temporary name, then rename). Fonts: DejaVu (bundled with matplotlib), so the
degree sign and ± render. A4 portrait, 8.27 × 11.69 in.
"""

from __future__ import annotations

import json
import textwrap
from typing import Any

import numpy as np

from formats.atomic import atomic_path

A4 = (8.27, 11.69)
LINES_PER_PAGE = 100
WIDTH = 118
MAX_CHARS = 128  # hard limit per line at 7 pt on A4 (DejaVu Sans Mono)


def _js(v: Any) -> str:
    return json.dumps(v, ensure_ascii=False, default=str)


def _fmt(v: Any, nd: int = 3) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return "-" if not np.isfinite(v) else f"{float(v):.{nd}f}"
    return str(v)


def table(headers: list[str], rows: list[list[Any]], nd: int = 3) -> list[str]:
    """Fixed-width text table lines."""
    cells = [[_fmt(c, nd) for c in r] for r in rows]
    w = [max([len(h)] + [len(r[i]) for r in cells]) for i, h in enumerate(headers)]
    out = ["  ".join(h.ljust(w[i]) for i, h in enumerate(headers)), "  ".join("-" * x for x in w)]
    out += ["  ".join(c.ljust(w[i]) for i, c in enumerate(r)) for r in cells]
    return out


def wrap(text: str, indent: str = "") -> list[str]:
    return textwrap.wrap(text, WIDTH, initial_indent=indent, subsequent_indent=indent + "  ") or [""]


def _text_pages(pdf: Any, title: str, lines: list[str], footer: str) -> int:
    import matplotlib.pyplot as plt

    pages = 0
    chunks = [lines[i:i + LINES_PER_PAGE] for i in range(0, max(len(lines), 1), LINES_PER_PAGE)]
    for k, chunk in enumerate(chunks):
        fig = plt.figure(figsize=A4)
        fig.text(0.06, 0.965, title + (f" (continued {k + 1}/{len(chunks)})" if k else ""), fontsize=12,
                 weight="bold", va="top", parse_math=False)
        body = "\n".join(("\u25a0 " + ln[3:].upper()) if ln.startswith("## ") else ln[:MAX_CHARS] for ln in chunk)
        fig.text(0.06, 0.935, body, family="DejaVu Sans Mono", fontsize=7.0, va="top", linespacing=1.25,
                 parse_math=False)
        fig.text(0.06, 0.02, footer, fontsize=6, color="0.4", parse_math=False)
        pdf.savefig(fig)
        plt.close(fig)
        pages += 1
    return pages


def summary_lines(ev: dict[str, Any]) -> list[str]:
    """Identification, inputs, editions, criteria, overall result and the item table as text lines."""
    L: list[str] = []
    ov = ev["overall"]
    L += [f"## RESULT: {ov['status'].upper()}   ({ov['rule']})", ""]
    if ov["required_not_passed"]:
        L += wrap("Required items not passed: " + ", ".join(ov["required_not_passed"]))
    L += [""] + wrap("Scope: " + ev["scope"]) + [""]
    L += ["## Identification"]
    tool = ev["tool"]
    L += [f"generated (UTC): {ev['generated_utc']}   tool: imutool {tool['version']}  git {tool['git'] or '-'}"]
    for k, v in ev["identification"].items():
        if v not in (None, {}, ""):
            L += wrap(f"{k}: {_js(v) if isinstance(v, (dict, list)) else v}")
    L += ["", "## Inputs (sha256 of the files as read)"]
    for name, inp in ev["inputs"].items():
        if not inp:
            continue
        L += [f"{name}: {inp.get('path')}", f"   sha256 {inp.get('sha256')}",
              f"   kind {inp.get('kind')}  rows {_fmt(inp.get('rows'))}  rate {_fmt(inp.get('rate_hz'), 2)} Hz  "
              f"duration {_fmt(inp.get('duration_s'), 1)} s  channel {inp.get('channel', '-')}"]
        meta = inp.get("meta") or {}
        for key in ("sensor", "device", "frame", "convention", "mounting", "calibration", "filter", "injected"):
            if key in meta:
                L += wrap(f"{key}: {_js(meta[key]) if isinstance(meta[key], (dict, list)) else meta[key]}",
                          "   ")
    c = ev["conventions"]
    L += ["", "## Units, frames and sign conventions"]
    for k, v in c.items():
        L += wrap(f"{k}: {v}")
    L += ["", "## Editions applied (confidence: A verbatim, B secondary quote, C partial, R recalled, I inference)"]
    L += table(["document", "edition", "role", "conf"],
               [[e["document"], e["edition"][:44], e.get("role", "")[:38], e["confidence"]] for e in ev["editions"]])
    L += ["", "## Criteria"]
    L += table(["id", "criterion", "source", "conf"],
               [[c["id"], c["text"][:66], c["source"][:40], c["confidence"]] for c in ev["criteria"]])
    a = ev["alignment"]
    L += ["", "## Time alignment"]
    L += wrap(f"{a['method']}: lag {_fmt(a.get('lag_s'), 3)} s ({a.get('lag_positive_means', '')}); "
              f"applied: {_fmt(a['applied'])}; {a.get('note', '')}")
    for k in ("correlation", "linear_fit", "rms_at_lag_deg"):
        if k in a:
            L += wrap(f"{k}: {_js(a[k]) if isinstance(a[k], dict) else _fmt(a[k], 4)}")
    L += ["", "## Items (N, max |error|, RMS, p95 |error| in the item's unit)"]
    L += table(["item", "clause", "status", "N", "max|e|", "RMS", "p95", "mean"],
               [[it["id"], it["clause"][:44], it["status"], it["stats"].get("n"), it["stats"].get("max_abs"),
                 it["stats"].get("rmse"), it["stats"].get("p95_abs"), it["stats"].get("mean")]
                for it in ev["items"]])
    L += [""]
    for it in ev["items"]:
        L += wrap(f"{it['id']}: {it['status']} - {it['reason']}")
    return L


def detail_lines(ev: dict[str, Any]) -> list[str]:
    """Per-item row tables, then not tested, unconfirmed figures, warnings and settings."""
    L: list[str] = []
    for it in ev["items"]:
        L += [f"## {it['title']} - {it['clause']}", f"status: {it['status']}"]
        L += wrap(f"criterion: {it['criterion'] or '-'}")
        L += wrap(f"result: {it['reason']}")
        if it.get("source"):
            L += wrap(f"source of DUT values: {it['source']}")
        rows = it.get("rows") or []
        if rows:
            keys = [k for k in rows[0] if k not in ("side",)]
            if "side" in rows[0]:
                keys = ["side"] + keys
            L += table(keys, [[r.get(k) for k in keys] for r in rows[:60]])
            if len(rows) > 60:
                L += [f"... {len(rows) - 60} more rows in the JSON"]
        if it.get("capture"):
            for k, v in it["capture"].items():
                L += wrap(f"{k}: {_js(v) if isinstance(v, (dict, list)) else v}")
        L += [""]
    L += ["## Not tested / insufficient data"]
    for s in ev["not_tested"]:
        L += wrap("- " + s)
    L += ["", "## Figures from the standards that are NOT confirmed (standards.md)"]
    for u in ev["unconfirmed"]:
        L += wrap(f"- {u['id']} [{u['confidence']}]: {u['text']}")
    if ev["warnings"]:
        L += ["", "## Warnings"]
        for w in ev["warnings"]:
            L += wrap("! " + w)
    L += ["", "## Settings"]
    for k, v in ev["settings"].items():
        L += [f"{k} = {v}"]
    return L


def _shade_static(ax: Any, t: np.ndarray, mask: np.ndarray) -> None:
    if mask is None or not np.any(mask):
        return
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        ax.axvspan(t[a], t[b - 1], color="0.9", lw=0)


def _side_error_panel(ax: Any, rows: list[dict[str, Any]], unit_sfx: str, what: str, tol_fn: Any, tol_label: str,
                      empty: str, xlabel: str, ylabel: str) -> None:
    """Port/starboard errors against the reference value with the configured tolerance band (± tol_fn)."""
    for side, mk, col in (("stbd", "o", "C0"), ("port", "s", "C4")):
        mine = [r for r in rows if r["side"] == side]
        if mine:
            ax.plot([r["reference" + unit_sfx] for r in mine], [r["error" + unit_sfx] for r in mine], mk, color=col,
                    label=f"{side} {what}")
    if rows:
        xs = np.linspace(0, max(r["reference" + unit_sfx] for r in rows) * 1.1 + 1, 100)
        tl = tol_fn(xs)
        ax.fill_between(xs, -tl, tl, color="C2", alpha=0.25, lw=0, label=tol_label)
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, empty, ha="center", transform=ax.transAxes)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)


def _inclinometer_figures(ev: dict[str, Any], p: dict[str, Any]) -> list[Any]:
    import matplotlib.pyplot as plt

    figs = []
    t = p["t"]
    fig, axs = plt.subplots(3, 1, figsize=A4, sharex=True)
    fig.suptitle("Heel: DUT vs reference (grey = static steps)", fontsize=11)
    _shade_static(axs[0], t, p["static_mask"])
    axs[0].plot(t, p["ref"], "k-", lw=0.8, label="reference")
    axs[0].plot(t, p["dut"], "C1-", lw=0.6, label="DUT (aligned)")
    axs[0].set_ylabel("heel (deg, + stbd)")
    axs[0].legend(loc="upper right", fontsize=7)
    _shade_static(axs[1], t, p["static_mask"])
    axs[1].fill_between(t, -p["tol"], p["tol"], color="C2", alpha=0.25, lw=0, label="tolerance max(1°, 5 %)")
    axs[1].plot(t, p["err"], "C3-", lw=0.5, label="DUT − reference")
    axs[1].set_ylabel("error (deg)")
    axs[1].legend(loc="upper right", fontsize=7)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.abs(p["err"]) / p["tol"]
    axs[2].plot(t, ratio, "C0-", lw=0.5)
    axs[2].axhline(1.0, color="C3", lw=1, ls="--", label="limit")
    axs[2].set_ylabel("|error| / tolerance")
    axs[2].set_xlabel("time (s, reference clock)")
    axs[2].legend(loc="upper right", fontsize=7)
    for ax in axs:
        ax.grid(alpha=0.3)
    figs.append(fig)

    fig, axs = plt.subplots(3, 1, figsize=A4)
    fig.suptitle("Static steps, roll amplitudes and roll periods", fontsize=11)
    steps = [r for r in p["steps"] if r.get("n")]
    if steps:
        x = np.array([r["reference_deg"] for r in steps])
        axs[0].errorbar(x, [r["error_mean_deg"] for r in steps], yerr=None, fmt="o", color="C1", label="mean error")
        axs[0].plot(x, [np.sign(r["error_mean_deg"] or 1) * r["max_abs_error_deg"] for r in steps], "x", color="C3",
                    label="max |error| (signed)")
        xs = np.linspace(min(x.min(), -1), max(x.max(), 1), 200)
        tl = p["tol_angle"](xs)
        axs[0].fill_between(xs, -tl, tl, color="C2", alpha=0.25, lw=0, label=p["tol_angle_label"])
        axs[0].legend(fontsize=7)
    else:
        axs[0].text(0.5, 0.5, "no static steps: not tested", ha="center", transform=axs[0].transAxes)
    axs[0].set_xlabel("reference heel (deg)")
    axs[0].set_ylabel("error (deg)")
    _side_error_panel(axs[1], p["amp_rows"], "_deg", "amplitude", p["tol_angle"], p["tol_angle_label"],
                      "no roll cycles: not tested", "reference amplitude (deg)", "amplitude error (deg)")
    _side_error_panel(axs[2], p["per_rows"], "_s", "period", p["tol_period"], p["tol_period_label"],
                      "no roll periods: not tested", "reference period (s)", "period error (s)")
    for ax in axs:
        ax.grid(alpha=0.3)
    fig.tight_layout(rect=(0, 0.025, 1, 0.97))
    figs.append(fig)

    fig, axs = plt.subplots(2, 1, figsize=A4)
    fig.suptitle("Peak hold since reset and long-term hold", fontsize=11)
    axs[0].plot(t, p["ref_peak_stbd"], "k-", lw=1, label="reference stbd")
    axs[0].plot(t, p["ref_peak_port"], "k--", lw=1, label="reference port")
    if p.get("dut_peak_stbd") is not None:
        axs[0].plot(t, p["dut_peak_stbd"], "C0-", lw=0.8, label="DUT stbd")
        axs[0].plot(t, p["dut_peak_port"], "C4--", lw=0.8, label="DUT port")
    axs[0].set_ylabel("peak hold (deg, positive)")
    axs[0].set_xlabel("time (s)")
    axs[0].legend(fontsize=7)
    lt = next((it for it in ev["items"] if it["id"] == "long_term"), None)
    if lt and lt["status"] in ("pass", "fail"):
        m = (t >= lt["start_s"]) & (t <= lt["end_s"])
        axs[1].plot(t[m], p["err"][m], "C3-", lw=0.5, label="DUT − reference")
        tl = p["tol"][m]
        axs[1].fill_between(t[m], -tl, tl, color="C2", alpha=0.25, lw=0, label="tolerance")
        axs[1].set_title(f"long-term hold: drift {lt['drift_deg_per_h']:.3f} °/h", fontsize=9)
        axs[1].legend(fontsize=7)
    else:
        axs[1].text(0.5, 0.5, "long-term test: not tested", ha="center", transform=axs[1].transAxes)
    axs[1].set_xlabel("time (s)")
    axs[1].set_ylabel("error (deg)")
    for ax in axs:
        ax.grid(alpha=0.3)
    fig.tight_layout(rect=(0, 0.025, 1, 0.97))
    figs.append(fig)
    return figs


def _heading_figures(ev: dict[str, Any], p: dict[str, Any]) -> list[Any]:
    import matplotlib.pyplot as plt

    t = p["t"]
    fig, axs = plt.subplots(3, 1, figsize=A4, sharex=True)
    fig.suptitle("Heading: DUT vs reference (grey = static headings)", fontsize=11)
    _shade_static(axs[0], t, p["static_mask"])
    axs[0].plot(t, p["ref"], "k.", ms=0.8, label="reference")
    axs[0].plot(t, p["dut"], "C1.", ms=0.5, label="DUT (aligned)")
    axs[0].set_ylabel("heading (deg)")
    axs[0].legend(loc="upper right", fontsize=7)
    _shade_static(axs[1], t, p["static_mask"])
    axs[1].plot(t, p["err"], "C3-", lw=0.5)
    lim = p["static_limit_deg"]
    axs[1].axhline(lim, color="C2", ls="--", lw=0.8)
    axs[1].axhline(-lim, color="C2", ls="--", lw=0.8)
    axs[1].set_ylabel("error (deg, wrapped ±180)")
    axs[2].plot(t, p["rot"], "C0-", lw=0.6)
    for v in (p["band_split_dps"], p["band_max_dps"], -p["band_split_dps"], -p["band_max_dps"]):
        axs[2].axhline(v, color="0.5", ls=":", lw=0.8)
    axs[2].set_ylabel("reference rate of turn (°/s)")
    axs[2].set_xlabel("time (s)")
    for ax in axs:
        ax.grid(alpha=0.3)
    figs = [fig]
    fig, axs = plt.subplots(2, 1, figsize=A4)
    fig.suptitle("Static error by heading and follow-up error by rate of turn", fontsize=11)
    rows = p["static_rows"]
    if rows:
        axs[0].bar([r["heading_deg"] for r in rows], [r["error_mean_deg"] for r in rows], width=12, color="C1",
                   label="mean error")
        axs[0].plot([r["heading_deg"] for r in rows], [r["p95_abs_error_deg"] for r in rows], "kx",
                    label="p95 |error|")
        axs[0].axhline(lim, color="C3", ls="--", lw=0.8)
        axs[0].axhline(-lim, color="C3", ls="--", lw=0.8, label=f"±{lim:g}°")
        axs[0].legend(fontsize=7)
    else:
        axs[0].text(0.5, 0.5, "no static headings: not tested", ha="center", transform=axs[0].transAxes)
    axs[0].set_xlabel("reference heading (deg)")
    axs[0].set_ylabel("error (deg)")
    axs[0].set_xlim(-20, 360)
    m = p["turn_mask"]
    if np.any(m):
        axs[1].plot(np.abs(p["rot"][m]), p.get("err_fu", p["err"])[m], ".", ms=1.5, color="C0")
        bx = [0, p["band_split_dps"], p["band_split_dps"], p["band_max_dps"]]
        by = np.array([p["follow_low_deg"], p["follow_low_deg"], p["follow_high_deg"], p["follow_high_deg"]])
        axs[1].plot(bx, by, "C3--", lw=1, label="limit (MSC.116(73) defaults unless changed)")
        axs[1].plot(bx, -by, "C3--", lw=1)
        axs[1].legend(fontsize=7)
    else:
        axs[1].text(0.5, 0.5, "no turns: follow-up not tested", ha="center", transform=axs[1].transAxes)
    axs[1].set_xlabel("|rate of turn| (°/s)")
    axs[1].set_ylabel("follow-up error (deg)")
    for ax in axs:
        ax.grid(alpha=0.3)
    fig.tight_layout(rect=(0, 0.025, 1, 0.97))
    figs.append(fig)
    return figs


def render_pdf(ev: dict[str, Any], plots: dict[str, Any], path: str) -> int:
    """Write the evidence PDF (text pages, then plot pages). Returns the page count."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.backends.backend_pdf import PdfPages

    footer = (f"imutool {ev['tool']['version']} - {ev['report']} evidence - generated {ev['generated_utc']} - "
              f"result {ev['overall']['status']} - test evidence only, not a type approval")
    pages = 0
    with atomic_path(path) as tmp:
        with PdfPages(tmp) as pdf:
            pages += _text_pages(pdf, ev["title"], summary_lines(ev), footer)
            figs = _inclinometer_figures(ev, plots) if ev["report"] == "inclinometer" else _heading_figures(ev, plots)
            for fig in figs:
                fig.text(0.06, 0.01, footer, fontsize=6, color="0.4", parse_math=False)
                pdf.savefig(fig)
                plt.close(fig)
                pages += 1
            pages += _text_pages(pdf, "Details per item", detail_lines(ev), footer)
            d = pdf.infodict()
            d["Title"] = ev["title"]
            d["Creator"] = f"imutool {ev['tool']['version']}"
    return pages


def write_json(ev: dict[str, Any], path: str) -> None:
    """Write the evidence JSON atomically (UTF-8, indented)."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        json.dump(ev, f, indent=1, ensure_ascii=False, allow_nan=False)
        f.write("\n")


def load_schema() -> dict[str, Any]:
    """The evidence JSON schema shipped with imutool (schema/evidence.schema.json)."""
    from importlib import resources

    return json.loads(resources.files("imutool.report").joinpath("schema/evidence.schema.json").read_text())
