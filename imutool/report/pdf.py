"""PDF rendering of an evidence report with matplotlib (PdfPages): text pages with tables, then plot pages.

The PDF is written atomically (temporary name, then rename). Fonts: DejaVu (bundled with matplotlib), so the
degree sign and ± render. A4 portrait, 8.27 × 11.69 in.
"""

from __future__ import annotations

import itertools
import json
import os
from importlib import resources
from typing import Any

import numpy as np

from formats.atomic import atomic_path
from imutool.clock import TIME_KEYS, Clock

A4 = (8.27, 11.69)
PW, PH = 595.0, 842.0  # page size (pt)
ML, MR, MT, MB = 48.0, 48.0, 56.0, 54.0  # margins (pt); the footer sits inside the bottom margin
TW = PW - ML - MR
FONT = "DejaVu Sans"  # proportional, bundled with matplotlib (° and ± render)
BLANK = "_" * 34  # a field to fill in by hand


def _fmt(v: Any, nd: int = 3) -> str:
    """A table cell: rounded numbers (never raw 17-digit floats), '-' for missing, yes/no for booleans."""
    if v is None:
        return "-"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        if not np.isfinite(v):
            return "-"
        txt = f"{float(v):.{nd}f}"
        return txt[1:] if txt.startswith("-") and float(txt) == 0.0 else txt  # no "-0.00"
    if isinstance(v, dict):
        return ", ".join(f"{k} {_fmt(x, nd)}" for k, x in v.items())
    if isinstance(v, (list, tuple)):
        return ", ".join(_fmt(x, nd) for x in v)
    return str(v)


def key_label(key: str, clock: Clock | None = None) -> tuple[str, str]:
    """Column label and unit of a row key: 'reference_deg' → ('reference', 'deg'), 't_peak_s' → ('t peak', 's');
    with a ``clock`` a time's unit is that clock's ('UTC' or 's from start')."""
    if clock is not None and key in TIME_KEYS:
        return key[:-2].replace("_", " "), clock.unit
    for suffix, unit in (("_deg", "deg"), ("_s", "s"), ("_ms2", "m/s²"), ("_hz", "Hz")):
        if key.endswith(suffix):
            return key[: -len(suffix)].replace("_", " "), unit
    return key.replace("_", " "), ""


def key_decimals(key: str) -> int:
    """Decimals of a row column: times of day 1, other seconds 2, angles 3."""
    if key in ("start_s", "end_s", "t_peak_s"):
        return 1
    if key.endswith("_s"):
        return 2
    return 3


def row_cells(keys: list[str], row: dict[str, Any], clock: Clock | None = None) -> list[str]:
    """The formatted cells of one detail row (the same text the PDF prints; tests compare it with the JSON); with
    a ``clock`` its times are UTC clock time (dated) or seconds from the start."""
    return [
        clock.text(row.get(k), key_decimals(k))
        if clock is not None and k in TIME_KEYS and isinstance(row.get(k), (int, float))
        else _fmt(row.get(k), key_decimals(k))
        for k in keys
    ]


def row_keys(rows: list[dict[str, Any]]) -> list[str]:
    keys: list[str] = []
    for r in rows:
        for k in r:
            if k not in keys and not k.endswith("_utc"):  # a time's ISO UTC: printed in its time column
                keys.append(k)
    if "side" in keys:
        keys.remove("side")
        keys.insert(0, "side")
    return keys


# ---- text layout: blocks → pages of drawing operations ----------------------------------------------------------
class _Measure:
    """Text widths in points exactly as matplotlib measures them (``TextToPath.get_text_width_height_descent``),
    at the cost of one measurement per word and per joint of two words instead of one per growing line.

    matplotlib lays a string out at 100 px per em (``TextToPath.FONT_SCALE``, whatever the size) in 1/64 px: a
    width is an integer sum of unhinted glyph advances, each with the kerning towards the next glyph, scaled by
    size / 100. So a line's width is additive: the sum of its words' widths plus, for each joint ``a b``, the
    width of ``a b`` less those of ``a`` and ``b`` (the space and the kerning of the pairs across it). Widths are
    kept in those integer units (a word's for every size) and turned into points as matplotlib does, so a
    wrapped line's width is bit for bit the width matplotlib gives the whole line."""

    def __init__(self) -> None:
        from matplotlib.font_manager import FontProperties
        from matplotlib.textpath import TextToPath

        self.tp = TextToPath()
        self.scale = float(TextToPath.FONT_SCALE)  # px per em of the layout
        self.props = {w: FontProperties(family=FONT, size=self.scale, weight=w) for w in ("normal", "bold")}
        self.cache: dict[tuple[str, str], int] = {}  # (text, weight) -> width (1/64 px at 100 px per em)
        self.joints: dict[tuple[str, str, str], int] = {}  # (a, b, weight) -> width("a b") - width(a) - width(b)
        self.wraps: dict[tuple[str, float, float, str], list[str]] = {}

    def units(self, text: str, weight: str = "normal") -> int:
        """Width of ``text`` in 1/64 px at 100 px per em (an integer: matplotlib's layout is fixed point)."""
        key = (text, weight)
        u = self.cache.get(key)
        if u is None:
            if weight not in self.props:
                from matplotlib.font_manager import FontProperties

                self.props[weight] = FontProperties(family=FONT, size=self.scale, weight=weight)
            w = self.tp.get_text_width_height_descent(text, self.props[weight], ismath=False)[0] if text else 0.0
            u = self.cache[key] = round(w * 64.0)  # at size 100 the scale is 1: w is exactly u / 64
        return u

    def joint(self, a: str, b: str, weight: str = "normal") -> int:
        """What joining ``a`` and ``b`` with a space adds to their widths (units of :meth:`units`): the space's
        advance and the kerning of the pairs across it, (last character of ``a``, space) and (space, first of
        ``b``). Measured on those characters alone, so a few hundred joints serve a report; a ligature ending or
        starting a word kerns with the space as its character does in DejaVu Sans (no glyph of it kerns with a
        space; the tests check ligature words)."""
        a, b = a[-1:], b[:1]
        key = (a, b, weight)
        j = self.joints.get(key)
        if j is None:
            j = self.joints[key] = self.units(a + " " + b, weight) - self.units(a, weight) - self.units(b, weight)
        return j

    def points(self, units: int, size: float) -> float:
        """Units of :meth:`units` in points at font ``size`` (the arithmetic of matplotlib's measurement)."""
        return units / 64.0 * (size / self.scale)

    def width(self, text: str, size: float, weight: str = "normal") -> float:
        """Width of ``text`` in points at font ``size`` (pt)."""
        return self.points(self.units(text, weight), size)

    def line_width(self, words: list[str], size: float, weight: str = "normal") -> float:
        """Width in points of ``words`` joined by single spaces, from the words' and the joints' widths (the
        arithmetic of :meth:`wrap`; equal to :meth:`width` of the joined line)."""
        units = self.units(words[0], weight) if words else 0
        for a, b in itertools.pairwise(words):
            units += self.joint(a, b, weight) + self.units(b, weight)
        return self.points(units, size)

    def wrap(self, text: str, width: float, size: float, weight: str = "normal") -> list[str]:
        """Greedy word wrap to a width in points (words longer than the width are cut by characters)."""
        key = (str(text), width, size, weight)
        got = self.wraps.get(key)
        if got is None:
            got = self.wraps[key] = self._wrap(str(text), width, size, weight)
        return list(got)

    def _wrap(self, text: str, width: float, size: float, weight: str) -> list[str]:
        out: list[str] = []
        for para in text.split("\n"):
            line, last, units = "", "", 0  # the line, its last word and its width (units)
            for word in para.split(" "):
                wu = self.units(word, weight)
                cand = wu if not line else units + self.joint(last, word, weight) + wu
                if self.points(cand, size) <= width:
                    line = word if not line else line + " " + word
                    last, units = word, cand
                    continue
                if line:
                    out.append(line)
                while self.width(word, size, weight) > width and len(word) > 1:
                    k = len(word)
                    while k > 1 and self.width(word[:k], size, weight) > width:
                        k -= 1
                    out.append(word[:k])
                    word = word[k:]
                line, last, units = word, word, self.units(word, weight)
            out.append(line)
        return out


class Layout:
    """Flows headings, paragraphs, key/value lists, tables (paginated, header repeated) and signature blocks onto
    A4 pages. Each page is a list of drawing operations in points (origin bottom left)."""

    def __init__(self, title: str, measure: _Measure | None = None) -> None:
        self.m = measure if measure is not None else _Measure()  # one shared by a report's layouts
        self.title = title
        self.pages: list[list[tuple]] = []
        self._new_page()

    def _new_page(self) -> None:
        self.page: list[tuple] = []
        self.pages.append(self.page)
        self.y = PH - MT

    def _need(self, h: float) -> None:
        if self.y - h < MB:
            self._new_page()

    def text(
        self, x: float, y: float, s: str, size: float, weight: str = "normal", color: str = "black", ha: str = "left"
    ) -> None:
        self.page.append(("text", x, y, s, size, weight, color, ha))

    def space(self, h: float) -> None:
        self.y -= h

    def page_break(self) -> None:
        if self.page:
            self._new_page()

    def heading(self, s: str, size: float = 12.0) -> None:
        self._need(size * 1.6 + 90)  # keep a heading with the first lines of what follows
        self.y -= size * 0.6
        for ln in self.m.wrap(s, TW, size, "bold"):
            self.y -= size * 1.25
            self.text(ML, self.y, ln, size, "bold")
        self.y -= 3

    def para(
        self, s: str, size: float = 8.5, indent: float = 0.0, weight: str = "normal", color: str = "black"
    ) -> None:
        lh = size * 1.3
        for ln in self.m.wrap(s, TW - indent, size, weight):
            self._need(lh)
            self.y -= lh
            self.text(ML + indent, self.y, ln, size, weight, color)
        self.y -= 2

    def banner(self, s: str, colour: str) -> None:
        size = 13.0
        lines = self.m.wrap(s, TW - 16, size, "bold")
        h = len(lines) * size * 1.3 + 12
        self._need(h)
        self.page.append(("rect", ML, self.y - h, TW, h, colour))
        yy = self.y - 6
        for ln in lines:
            yy -= size * 1.3
            self.text(ML + 8, yy + 3, ln, size, "bold", "white")
        self.y -= h + 6

    def kv(self, pairs: list[tuple[str, str]], size: float = 8.5, key_w: float = 170.0) -> None:
        lh = size * 1.3
        total = sum(
            max(len(self.m.wrap(k, key_w - 8, size, "bold")), len(self.m.wrap(v, TW - key_w, size))) * lh + 2
            for k, v in pairs
        )
        if total <= 250.0:  # a short list stays on one page
            self._need(total)
        for k, v in pairs:
            kl = self.m.wrap(k, key_w - 8, size, "bold")
            vl = self.m.wrap(v, TW - key_w, size)
            n = max(len(kl), len(vl))
            self._need(n * lh + 2)
            for i in range(n):
                self.y -= lh
                if i < len(kl):
                    self.text(ML, self.y, kl[i], size, "bold")
                if i < len(vl):
                    self.text(ML + key_w, self.y, vl[i], size)
            self.y -= 2

    def table(
        self,
        headers: list[str],
        rows: list[list[str]],
        units: list[str] | None = None,
        size: float = 7.5,
        caption: str | None = None,
        weights: list[float] | None = None,
        numeric: list[bool] | None = None,
    ) -> None:
        """A table that paginates: rows never cut, the header (and units) repeated on every page."""
        m = self.m
        pad = 4.0
        ncol = len(headers)
        units = units or [""] * ncol
        numeric = numeric or [False] * ncol
        nat = []
        for j in range(ncol):
            w = max(
                [m.width(w_, size, "bold") for w_ in (headers[j].split(" ") + [units[j]])]
                + [m.width(r[j], size) for r in rows]
                + [8.0]
            )
            nat.append(w + 2 * pad + 1.0)  # + 1 pt: rounding in the measured widths never forces a wrap
        tot = sum(nat)
        if tot > TW:  # shrink the wide columns first (they wrap), never below their longest header word
            # numbers never wrap; text columns shrink down to their longest header word
            minw = [
                nat[j] if numeric[j] else max(m.width(w_, size, "bold") for w_ in headers[j].split(" ")) + 2 * pad
                for j in range(ncol)
            ]
            wts = weights or [1.0] * ncol
            widths = list(nat)
            excess = tot - TW
            for _ in range(50):
                if excess <= 0.5:
                    break
                flex = [j for j in range(ncol) if widths[j] > minw[j] + 0.5]
                if not flex:
                    break
                share = sum(widths[j] * wts[j] for j in flex)
                for j in flex:
                    cut = min(widths[j] - minw[j], excess * widths[j] * wts[j] / share)
                    widths[j] -= cut
                excess = sum(widths) - TW
        else:
            widths = nat
        lh = size * 1.25

        def cell_lines(txt: str, j: int, weight: str = "normal") -> list[str]:
            return m.wrap(txt, widths[j] - 2 * pad, size, weight)

        head = [cell_lines(h, j, "bold") for j, h in enumerate(headers)]
        nh = max(len(h) for h in head) + (1 if any(units) else 0)
        head_h = nh * lh + 4

        def draw_header(cont: bool) -> None:
            if caption:
                self.y -= size * 1.5
                self.text(ML, self.y, caption + (" (continued)" if cont else ""), size + 0.5, "bold")
                self.y -= 3
            top = self.y
            self.page.append(("rect", ML, top - head_h, sum(widths), head_h, "#e6e9ef"))
            x = ML
            for j in range(ncol):
                yy = top
                for ln in head[j]:
                    yy -= lh
                    self.text(x + pad, yy, ln, size, "bold")
                if units[j]:
                    self.text(x + pad, top - nh * lh, f"({units[j]})", size, "normal", "#333333")
                x += widths[j]
            self.y = top - head_h
            self.page.append(("line", ML, self.y, ML + sum(widths), self.y, 0.6))

        self._need(head_h + lh * 2 + (size * 2 if caption else 0))
        draw_header(False)
        for r in rows:
            cl = [cell_lines(c, j) for j, c in enumerate(r)]
            h = max(len(c) for c in cl) * lh + 3
            if self.y - h < MB:
                self._new_page()
                draw_header(True)
            x = ML
            for j in range(ncol):
                yy = self.y
                for ln in cl[j]:
                    yy -= lh
                    if numeric[j]:
                        self.text(x + widths[j] - pad, yy, ln, size, ha="right")
                    else:
                        self.text(x + pad, yy, ln, size)
                x += widths[j]
            self.y -= h
            self.page.append(("line", ML, self.y, ML + sum(widths), self.y, 0.2))
        self.y -= 6

    def signatures(self, roles: list[str]) -> None:
        size = 8.5
        h = 62.0
        self._need(h * len(roles))  # the sign-off stays on one page
        for role in roles:
            self._need(h)
            self.y -= 14
            self.text(ML, self.y, role, size, "bold")
            self.y -= 30
            cols = (("Name", 0.0), ("Signature", 175.0), ("Date", 350.0))  # three 149 pt lines inside the margins
            for label, dx in cols:
                self.page.append(("line", ML + dx, self.y, ML + dx + 149, self.y, 0.6))
                self.text(ML + dx, self.y - 10, label, 7.0, color="#444444")
            self.y -= 18


def _draw_page(fig: Any, ops: list[tuple]) -> None:
    from matplotlib.patches import Rectangle

    from .pagetext import PageText

    texts = []
    for op in ops:
        if op[0] == "text":
            _, x, y, s, size, weight, color, ha = op
            texts.append((x / PW, y / PH, s, size, weight, color, ha))
        elif op[0] == "line":
            _, x0, y0, x1, y1, lw = op
            fig.add_artist(_line(x0, y0, x1, y1, lw))
        elif op[0] == "rect":
            _, x, y, w, h, col = op
            fig.add_artist(
                Rectangle((x / PW, y / PH), w / PW, h / PH, transform=fig.transFigure, color=col, lw=0, zorder=-1)
            )
    fig.add_artist(PageText(texts, FONT))  # after the rules and shading, as Text artists were drawn


def _line(x0: float, y0: float, x1: float, y1: float, lw: float) -> Any:
    from matplotlib.lines import Line2D

    return Line2D([x0 / PW, x1 / PW], [y0 / PH, y1 / PH], lw=lw, color="#555555")


def _footer(fig: Any, ev: dict[str, Any], k: int, n: int) -> None:
    num = (ev.get("test_record") or {}).get("report", {}).get("number") or "________"
    fig.add_artist(_line(ML, MB - 22, PW - MR, MB - 22, 0.4))
    fig.text(
        ML / PW,
        (MB - 34) / PH,
        f"Report No. {num}   ·   {ev['title']}   ·   result {ev['overall']['status'].upper()}",
        fontsize=6.5,
        color="#444444",
        family=FONT,
        parse_math=False,
    )
    fig.text(
        ML / PW,
        (MB - 43) / PH,
        f"imutool {ev['tool']['version']} · generated {ev['generated_utc']} · test evidence only, not a type approval",
        fontsize=6.0,
        color="#666666",
        family=FONT,
        parse_math=False,
    )
    fig.text(
        (PW - MR) / PW,
        (MB - 34) / PH,
        f"page {k} of {n}",
        fontsize=7.5,
        weight="bold",
        ha="right",
        family=FONT,
        parse_math=False,
    )


_STATUS_COLOUR = {"pass": "#1b7a3a", "fail": "#b0201e", "incomplete": "#b36b00"}


def _test_record_blocks(L: Layout, ev: dict[str, Any]) -> None:
    from .testinfo import FIELDS

    tr = ev.get("test_record") or {}
    L.heading("Test record")
    src = tr.get("source")
    L.para(
        ("From " + os.path.basename(src) + ". ")
        if src
        else "No test record was given (--test-info). "
        "Blank lines are fields the test record does not state: fill them in by hand; imutool never invents "
        "them.",
        size=8,
    )
    pairs = []
    for sec, key, label, _ in FIELDS:
        v = (tr.get(sec) or {}).get(key)
        if isinstance(v, float):
            v = f"{v:g}"
        elif isinstance(v, list) and all(isinstance(x, float) for x in v):
            v = " to ".join(f"{x:g}" for x in v)
        pairs.append((label, BLANK if v in (None, "", []) else _fmt(v, 3)))
    L.kv(pairs)


def summary_blocks(L: Layout, ev: dict[str, Any]) -> None:
    """Page 1 onwards: result, scope, test record, identification, inputs, conventions, editions, criteria, items."""
    ov = ev["overall"]
    L.banner("RESULT: " + ov.get("headline", ov["status"].upper()), _STATUS_COLOUR.get(ov["status"], "#444444"))
    L.para(ov["rule"], size=7.5, color="#333333")
    L.para("Scope: " + ev["scope"], size=7.5)
    L.heading("Items (one row per requirement; source says whether the device reported the values)", 11)
    L.table(
        ["item", "clause", "status", "source", "unit", "N", "max |error|", "RMS", "p95 |error|", "mean"],
        [
            [
                it["id"],
                it["clause"],
                it["status"],
                it.get("source") or "-",
                it.get("unit", ""),
                _fmt(it["stats"].get("n")),
                _fmt(it["stats"].get("max_abs")),
                _fmt(it["stats"].get("rmse")),
                _fmt(it["stats"].get("p95_abs")),
                _fmt(it["stats"].get("mean")),
            ]
            for it in ev["items"]
        ],
        size=7.0,
        caption=None,
        weights=[0.3, 1.5, 0.3, 1.5, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1],
        numeric=[False] * 5 + [True] * 5,
    )
    for it in ev["items"]:
        L.para(f"{it['id']} — {it['status']}: {it['reason']}", size=7.5, indent=0)
    _test_record_blocks(L, ev)
    L.heading("Identification")
    tool = ev["tool"]
    pairs = [("Generated (UTC)", ev["generated_utc"]), ("Tool", f"imutool {tool['version']}, git {tool['git'] or '-'}")]
    for k, v in ev["identification"].items():
        if v not in (None, {}, "", []):
            pairs.append((k.replace("_", " "), _fmt(v)))
    L.kv(pairs)
    L.heading("Inputs (sha256 of the files as read)")
    for name, inp in ev["inputs"].items():
        if not inp:
            continue
        pairs = [(name.replace("_", " "), f"{inp.get('path')}"), ("sha256", str(inp.get("sha256")))]
        if inp.get("rows") is not None:
            pairs.append(
                (
                    "content",
                    f"{inp.get('kind')}, {_fmt(inp.get('rows'))} rows, {_fmt(inp.get('rate_hz'), 2)}"
                    f" Hz (median), {_fmt(inp.get('duration_s'), 1)} s, channel "
                    f"{inp.get('channel', '-')}",
                )
            )
        if inp.get("streams"):  # a many-clock log: the channel's own stream, and the file's others
            pairs.append(
                (
                    "streams",
                    f"rows and rate above are stream {inp.get('stream')}'s own samples; the file's "
                    f"{_fmt(inp.get('file_rows'))} rows hold "
                    + "; ".join(
                        f"{k}: {_fmt(v.get('samples'))} at {_fmt(v.get('rate_hz'), 2)} Hz"
                        for k, v in inp["streams"].items()
                    ),
                )
            )
        if inp.get("loading"):
            from imutool.loading import loading_text

            pairs.append(("loaded", loading_text(inp["loading"])))
        L.kv(pairs)
    L.heading("Units, frames and sign conventions")
    L.kv([(k.replace("_", " "), _convention_text(k, v)) for k, v in ev["conventions"].items()])
    L.heading("Editions applied (confidence: A verbatim, B secondary quote, C partial, R recalled, I inference)")
    L.table(
        ["document", "edition", "role", "conf."],
        [[e["document"], e["edition"], e.get("role", ""), e["confidence"]] for e in ev["editions"]],
        weights=[0.5, 1.0, 1.0, 0.1],
    )
    L.heading("Criteria applied")
    L.table(
        ["id", "criterion", "source", "conf."],
        [[c["id"], c["text"], c["source"], c["confidence"]] for c in ev["criteria"]],
        weights=[0.2, 1.5, 1, 0.1],
    )
    a = ev["alignment"]
    L.heading("Time alignment")
    pairs = [
        ("method", a["method"]),
        ("lag (s)", f"{_fmt(a.get('lag_s'), 3)} ({a.get('lag_positive_means', '')})"),
        ("applied", f"{_fmt(a['applied'])}: {a.get('note', '')}"),
    ]
    if "correlation" in a:
        pairs.append(("correlation", _fmt(a["correlation"], 4)))
    lf = a.get("linear_fit")
    if lf:
        pairs.append(
            (
                "linear fit",
                f"offset {_fmt(lf.get('offset_deg'), 3)} deg, scale error "
                f"{_fmt(100 * lf['scale_error'] if lf.get('scale_error') is not None else None, 2)}"
                f" %  ({lf.get('model', '')})",
            )
        )
    if "rms_at_lag_deg" in a:
        pairs.append(("RMS at the lag (deg)", _fmt(a["rms_at_lag_deg"], 3)))
    if "latency_from_follow_up_s" in a:
        pairs.append(("latency from follow-up (s)", _fmt(a["latency_from_follow_up_s"], 3)))
    L.kv(pairs)


def detail_blocks(L: Layout, ev: dict[str, Any]) -> None:
    """Per-item row tables (every row of the JSON), not tested, standards cited, unconfirmed, warnings, settings,
    signatures."""
    clock = clock_of(ev)
    for it in ev["items"]:
        L.heading(f"{it['title']} — {it['clause']}", 11)
        pairs = [("status", it["status"]), ("criterion", it["criterion"] or "-"), ("result", it["reason"])]
        if it.get("source"):
            pairs.append(("values", it["source"]))
        for k in ("judging", "error_definition"):
            if it.get(k):
                pairs.append((k.replace("_", " "), str(it[k])))
        cyc = it.get("cycles")
        if cyc:
            nj = "; ".join(f"{v} {k}" for k, v in cyc["not_judged"].items()) or "none"
            pairs.append(
                ("cycles", f"{cyc['judged']} of {cyc['reference_maxima']} reference maxima judged; not judged: {nj}")
            )
        if it.get("raw_error_stats"):
            r = it["raw_error_stats"]
            pairs.append(
                (
                    "raw error (static error included)",
                    f"N {_fmt(r.get('n'))}, max |error| "
                    f"{_fmt(r.get('max_abs'))} deg, RMS {_fmt(r.get('rmse'))} deg, p95 {_fmt(r.get('p95_abs'))}"
                    f" deg; status on the raw error: {it.get('raw_status', '-')}",
                )
            )
        if it.get("drift_deg_per_h") is not None:
            pairs.append(
                (
                    "drift",
                    f"{_fmt(it['drift_deg_per_h'], 3)} ± {_fmt(it.get('drift_u95_deg_per_h'), 3)} "
                    f"°/h (95 %) over {_fmt(it.get('duration_s'), 0)} s",
                )
            )
        L.kv(pairs, size=8)
        rows = it.get("rows") or []
        if rows:
            keys = row_keys(rows)
            labels = [key_label(k, clock) for k in keys]
            L.table(
                [lb for lb, _ in labels],
                [row_cells(keys, r, clock) for r in rows],
                units=[u for _, u in labels],
                caption=f"{it['id']}: {len(rows)} rows",
                numeric=[k not in ("side", "status") for k in keys],
            )
        if it.get("capture"):
            L.kv([(k.replace("_", " "), _fmt(v)) for k, v in it["capture"].items()], size=7.5)
    L.heading("Not tested / insufficient data")
    for s in ev["not_tested"]:
        L.para("• " + s, size=8)
    sc = ev.get("standards_cited")
    if sc:
        L.heading(f"Standards excerpts applied ({sc['file']})")
        L.table(
            ["id", "requirement", "value", "conf."],
            [[r["id"], r["requirement"], r["value"], r["confidence"]] for r in sc["rows"]],
            weights=[0.1, 2.0, 1.0, 0.1],
            size=7.0,
        )
    L.heading("Figures from the standards that are NOT confirmed")
    for u in ev["unconfirmed"]:
        L.para(f"• {u['id']} [{u['confidence']}]: {u['text']}", size=8)
    if ev["warnings"]:
        L.heading("Warnings")
        for w in ev["warnings"]:
            L.para("! " + w, size=8)
    L.heading("Settings")
    L.kv([(k.replace("_", " "), _fmt(v, 3)) for k, v in ev["settings"].items()], size=7.5, key_w=190)
    L.heading("Sign-off")
    L.para(
        "The undersigned confirm that the test was carried out as recorded above and that this evidence "
        "belongs to the device identified in the test record.",
        size=8,
    )
    L.signatures(
        ["Operator (test house)", "Witness (surveyor / recognised organisation)", "Approved for the test house"]
    )


def _convention_text(key: str, value: Any) -> str:
    if key == "clock" and isinstance(value, dict):
        if value.get("start_utc"):
            return f"times in UTC clock time; the reference's first sample at {value.get('start_utc')}"
        return "times in seconds from the reference's first sample (the recording has no date)"
    return str(value)


def clock_of(ev: dict[str, Any], plots: dict[str, Any] | None = None) -> Clock:
    """The evidence's clock (``conventions.clock``; an evidence without one: undated, from the first time)."""
    if plots is not None and isinstance(plots.get("clock"), Clock):
        return plots["clock"]
    t = (plots or {}).get("t")
    start = float(t[0]) if t is not None and len(t) else 0.0
    return Clock.from_json(ev.get("conventions", {}).get("clock"), start)


def _shade_static(ax: Any, t: np.ndarray, mask: np.ndarray | None, color: str = "0.9") -> None:
    if mask is None or not np.any(mask):
        return
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        ax.axvspan(t[a], t[b - 1], color=color, lw=0)


def _side_error_panel(
    ax: Any,
    rows: list[dict[str, Any]],
    unit_sfx: str,
    what: str,
    tol_fn: Any,
    tol_label: str,
    empty: str,
    xlabel: str,
    ylabel: str,
) -> None:
    """Port/starboard errors against the reference value with the configured tolerance band (± tol_fn)."""
    for side, mk, col in (("stbd", "o", "C0"), ("port", "s", "C4")):
        mine = [r for r in rows if r["side"] == side]
        if mine:
            ax.plot(
                [r["reference" + unit_sfx] for r in mine],
                [r["error" + unit_sfx] for r in mine],
                mk,
                color=col,
                label=f"{side} {what}",
            )
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
    clock = clock_of(ev, p)
    t = clock.x(p["t"])  # seconds from the start: no "+1.4e9" axis offset; dated ticks read as UTC
    fig, axs = plt.subplots(3, 1, figsize=A4, sharex=True)
    fig.suptitle("Heel: DUT vs reference (grey = static steps, blue = lateral acceleration)", fontsize=11)
    _shade_static(axs[0], t, p["static_mask"])
    _shade_static(axs[0], t, p.get("acc_mask"), "#cfe0f5")
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
    clock.axis(axs[2], "reference time")
    axs[2].legend(loc="upper right", fontsize=7)
    lt = next((it for it in ev["items"] if it["id"] == "long_term"), None)
    if lt and lt.get("start_s") is not None and t.size and lt["end_s"] - lt["start_s"] > 0.5 * (t[-1] - t[0]):
        # the long hold has its own plot: show the programme before it at a readable scale
        axs[2].set_xlim(t[0], clock.x(lt["start_s"]) + 30.0)
        at = clock.text(lt["start_s"], 0) + (" UTC" if clock.dated else " s")
        axs[0].set_title(f"programme before the long-term hold (from {at}: see the long-term plot)", fontsize=8)
    for ax in axs:
        ax.grid(alpha=0.3)
    figs.append(fig)

    fig, axs = plt.subplots(3, 1, figsize=A4)
    fig.suptitle("Static steps, roll amplitudes and roll periods", fontsize=11)
    steps = [r for r in p["steps"] if r.get("n")]
    if steps:
        x = np.array([r["reference_deg"] for r in steps])
        axs[0].errorbar(x, [r["error_mean_deg"] for r in steps], yerr=None, fmt="o", color="C1", label="mean error")
        axs[0].plot(
            x,
            [np.sign(r["error_mean_deg"] or 1) * r["max_abs_error_deg"] for r in steps],
            "x",
            color="C3",
            label="max |error| (signed)",
        )
        xs = np.linspace(min(x.min(), -1), max(x.max(), 1), 200)
        tl = p["tol_angle"](xs)
        axs[0].fill_between(xs, -tl, tl, color="C2", alpha=0.25, lw=0, label=p["tol_angle_label"])
        axs[0].legend(fontsize=7)
    else:
        axs[0].text(0.5, 0.5, "no static steps: not tested", ha="center", transform=axs[0].transAxes)
    axs[0].set_xlabel("reference heel (deg)")
    axs[0].set_ylabel("error (deg)")
    _side_error_panel(
        axs[1],
        p["amp_rows"],
        "_deg",
        "amplitude",
        p["tol_angle"],
        p["tol_angle_label"],
        "no roll cycles: not tested",
        "reference amplitude (deg)",
        "amplitude error (deg)",
    )
    _side_error_panel(
        axs[2],
        p["per_rows"],
        "_s",
        "period",
        p["tol_period"],
        p["tol_period_label"],
        "no roll periods: not tested",
        "reference period (s)",
        "period error (s)",
    )
    for ax in axs:
        ax.grid(alpha=0.3)
    fig.tight_layout(rect=(0, 0.06, 1, 0.97))
    figs.append(fig)

    fig, axs = plt.subplots(2, 1, figsize=A4)
    fig.suptitle("Peak hold since reset and long-term hold", fontsize=11)
    axs[0].plot(t, p["ref_peak_stbd"], "k-", lw=1, label="reference stbd")
    axs[0].plot(t, p["ref_peak_port"], "k--", lw=1, label="reference port")
    if p.get("dut_peak_stbd") is not None:
        axs[0].plot(t, p["dut_peak_stbd"], "C0-", lw=0.8, label="DUT stbd")
        axs[0].plot(t, p["dut_peak_port"], "C4--", lw=0.8, label="DUT port")
    axs[0].set_ylabel("peak hold (deg, positive)")
    clock.axis(axs[0])
    axs[0].legend(fontsize=7)
    lt = next((it for it in ev["items"] if it["id"] == "long_term"), None)
    if lt and lt["status"] in ("pass", "fail"):
        m = (t >= clock.x(lt["start_s"])) & (t <= clock.x(lt["end_s"]))
        axs[1].plot(t[m], p["err"][m], "C3-", lw=0.5, label="DUT − reference")
        tl = p["tol"][m]
        axs[1].fill_between(t[m], -tl, tl, color="C2", alpha=0.25, lw=0, label="tolerance")
        axs[1].set_title(f"long-term hold: drift {lt['drift_deg_per_h']:.3f} °/h", fontsize=9)
        axs[1].legend(fontsize=7)
        clock.axis(axs[1])
    else:
        axs[1].text(0.5, 0.5, "long-term test: not tested", ha="center", transform=axs[1].transAxes)
        axs[1].set_xlabel(clock.axis_label())
    axs[1].set_ylabel("error (deg)")
    for ax in axs:
        ax.grid(alpha=0.3)
    fig.tight_layout(rect=(0, 0.06, 1, 0.97))
    figs.append(fig)
    return figs


def _heading_figures(ev: dict[str, Any], p: dict[str, Any]) -> list[Any]:
    import matplotlib.pyplot as plt

    clock = clock_of(ev, p)
    t = clock.x(p["t"])  # seconds from the start: no "+1.4e9" axis offset; dated ticks read as UTC
    fig, axs = plt.subplots(3, 1, figsize=A4, sharex=True)
    fig.suptitle("Heading: DUT vs reference (grey = static headings)", fontsize=11)
    _shade_static(axs[0], t, p["static_mask"])
    # the DUT drawn as reference + wrapped error and both broken where the reference wraps: a DUT at 359.9°
    # against a reference at 0.1° is drawn at −0.1°, next to it, not a full circle away
    ref_w = np.asarray(p["ref"], float).copy()
    dut_w = ref_w + np.asarray(p["err"], float)
    brk = np.flatnonzero(np.abs(np.diff(ref_w)) > 180.0) + 1
    ref_w = np.insert(ref_w, brk, np.nan)
    dut_w = np.insert(dut_w, brk, np.nan)
    tw = np.insert(np.asarray(t, float), brk, np.nan)
    axs[0].plot(tw, ref_w, "k-", lw=0.8, label="reference")
    axs[0].plot(tw, dut_w, "C1-", lw=0.6, label="DUT (aligned; drawn as reference + wrapped error)")
    axs[0].set_ylim(-15, 375)
    axs[0].set_yticks([0, 90, 180, 270, 360])
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
    clock.axis(axs[2])
    for ax in axs:
        ax.grid(alpha=0.3)
    figs = [fig]
    fig, axs = plt.subplots(2, 1, figsize=A4)
    fig.suptitle("Static error by heading and follow-up error by rate of turn", fontsize=11)
    rows = p["static_rows"]
    if rows:
        axs[0].bar(
            [r["heading_deg"] for r in rows],
            [r["error_mean_deg"] for r in rows],
            width=12,
            color="C1",
            label="mean error",
        )
        axs[0].plot([r["heading_deg"] for r in rows], [r["p95_abs_error_deg"] for r in rows], "kx", label="p95 |error|")
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
        axs[1].plot(
            np.abs(p["rot"][m]),
            p.get("err_raw", p["err"])[m],
            ".",
            ms=1.2,
            color="0.6",
            label="raw error (static error included)",
        )
        axs[1].plot(
            np.abs(p["rot"][m]),
            p.get("err_fu", p["err"])[m],
            ".",
            ms=1.5,
            color="C0",
            label="static error removed (judged)",
        )
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
    fig.tight_layout(rect=(0, 0.06, 1, 0.97))
    figs.append(fig)
    return figs


def render_pdf(ev: dict[str, Any], plots: dict[str, Any], path: str) -> int:
    """Write the evidence PDF: summary pages, plot pages, detail pages; footer with the report number and
    "page x of y" on every page. Returns the page count."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.backends.backend_pdf import PdfPages

    head = Layout(ev["title"])
    head.heading(ev["title"], 14)
    summary_blocks(head, ev)
    tail = Layout("Details per item", head.m)
    tail.pages.clear()
    tail._new_page()
    tail.heading("Details per item (every row of the JSON)", 13)
    detail_blocks(tail, ev)
    tail.pages = [p for p in tail.pages if p]
    figs = _inclinometer_figures(ev, plots) if ev["report"] == "inclinometer" else _heading_figures(ev, plots)
    total = len(head.pages) + len(figs) + len(tail.pages)

    def text_page(ops):
        fig = plt.figure(figsize=A4)
        _draw_page(fig, ops)
        return fig

    # lazily: one text page drawn, written and closed at a time
    pages = itertools.chain((text_page(ops) for ops in head.pages), figs, (text_page(ops) for ops in tail.pages))
    with atomic_path(path) as tmp:
        with PdfPages(tmp) as pdf:
            for k, fig in enumerate(pages, start=1):  # footer (report number, page k of total) on every page
                _footer(fig, ev, k, total)
                pdf.savefig(fig)
                plt.close(fig)
            d = pdf.infodict()
            d["Title"] = ev["title"]
            d["Creator"] = f"imutool {ev['tool']['version']}"
    return total


def write_json(ev: dict[str, Any], path: str) -> None:
    """Write the evidence JSON atomically (UTF-8, indented)."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        json.dump(ev, f, indent=1, ensure_ascii=False, allow_nan=False)
        f.write("\n")


def load_schema() -> dict[str, Any]:
    """The evidence JSON schema shipped with imutool (schema/evidence.schema.json)."""
    return json.loads(resources.files("imutool.report").joinpath("schema/evidence.schema.json").read_text())
