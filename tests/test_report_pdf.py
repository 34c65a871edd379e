"""The evidence PDF loses nothing: every JSON row of every table is in the PDF text, every page has the report
number and "page x of y", numbers are rounded; heading plots have no 360°/0° artefact."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from imutool.report.heading import heading_evidence
from imutool.report.inclinometer import InclinometerOptions, inclinometer_evidence
from imutool.report.pdf import _heading_figures, render_pdf, row_cells, row_keys
from imutool.report.testinfo import load_test_info
from imutool.sim.programmes import heading_test, inclinometer_test

SAMPLE_TOML = Path(__file__).resolve().parents[1] / "sample_data" / "test_info.toml"

needs_pdftotext = pytest.mark.skipif(
    shutil.which("pdftotext") is None, reason="pdftotext (poppler-utils) not installed: PDF text not extracted"
)


def _pdf_text(pdf: Path) -> tuple[str, list[str]]:
    """pdftotext -layout output, whole and per page (pages are separated by form feeds)."""
    out = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], check=True, capture_output=True, text=True).stdout
    return out, out.split("\f")


def _norm(s: str) -> str:
    return re.sub(r"\s+", " ", s).strip()


@pytest.fixture(scope="module")
def long_report(tmp_path_factory):
    """Many rows (more than a page per table): 27+ roll periods, 13 static steps, a test record with a blank."""
    tmp = tmp_path_factory.mktemp("pdf")
    dyn = ((5.0, 6.0, 6.0, 12), (8.0, 10.0, 10.0, 10), (12.0, 20.0, 14.0, 6))
    dut, ref, _ = inclinometer_test(noise_deg=0.05, offset_deg=0.2, dynamic=dyn, long_s=0.0, hold_s=12.0)
    info = load_test_info(str(SAMPLE_TOML))
    info["test"]["witness"] = None  # a blank field must be printed as a line to fill
    ev, plots = inclinometer_evidence(
        dut, ref, test_info=info, options=InclinometerOptions(declared_period_range_s=(5.0, 12.0))
    )
    pdf = tmp / "evidence.pdf"
    pages = render_pdf(ev, plots, str(pdf))
    return ev, pdf, pages


@pytest.mark.slow
@needs_pdftotext
def test_every_json_row_is_in_the_pdf(long_report):
    ev, pdf, _ = long_report
    text, _ = _pdf_text(pdf)
    lines = [_norm(ln) for ln in text.splitlines()]
    n_tables = 0
    for it in ev["items"]:
        rows = it.get("rows") or []
        if not rows:
            continue
        n_tables += 1
        keys = row_keys(rows)
        found = 0
        for r in rows:
            cells = " ".join(row_cells(keys, r))
            found += sum(1 for ln in lines if cells in ln)
        # each row once (identical rows would be counted twice each: none here)
        assert found == len(rows), f"{it['id']}: {found} of {len(rows)} JSON rows in the PDF text"
        assert f"{it['id']}: {len(rows)} rows" in text
    assert n_tables >= 4
    per = next(it for it in ev["items"] if it["id"] == "roll_period")
    assert len(per["rows"]) > 27  # more rows than fit on a page: the table paginated without losing any


@pytest.mark.slow
@needs_pdftotext
def test_summary_items_table_and_footers(long_report):
    ev, pdf, pages = long_report
    text, per_page = _pdf_text(pdf)
    per_page = [p for p in per_page if p.strip()]
    assert len(per_page) == pages
    num = ev["test_record"]["report"]["number"]
    for k, page in enumerate(per_page, start=1):
        assert f"page {k} of {pages}" in page, f"page {k}: no 'page x of y'"
        assert f"Report No. {num}" in page, f"page {k}: no report number"
    flat = _norm(text)
    for it in ev["items"]:  # one row per item in the summary table, with its status
        assert re.search(rf"\b{it['id']}\b", flat)
    assert "INCOMPLETE" in flat and "not tested:" in flat
    # no raw float dumps (17 significant digits) anywhere
    assert not re.search(r"\d\.\d{7,}", text)
    # the blank test-record field is a line to fill, the given ones are printed
    assert re.search(r"Witness \(surveyor\)\s+_{10,}", text)
    assert ev["test_record"]["reference"]["certificate"] in text
    # unit column and signatures
    assert "unit" in flat and "deg" in flat and "Signature" in flat and "Witness (surveyor / recognised" in flat


@pytest.mark.slow
def test_pdf_pages_render_without_overprinting(long_report, tmp_path):
    """Footer and body never share pixels: the band between the body's bottom margin and the footer is empty."""
    if shutil.which("pdftoppm") is None:
        pytest.skip("pdftoppm (poppler-utils) not installed")
    _, pdf, pages = long_report
    subprocess.run(["pdftoppm", "-r", "50", "-png", str(pdf), str(tmp_path / "p")], check=True)
    import matplotlib.image as mpimg

    pngs = sorted(tmp_path.glob("p-*.png"))
    assert len(pngs) == pages
    for png in pngs:
        img = mpimg.imread(png)[..., :3].mean(axis=2)
        h = img.shape[0]
        # body ends at 54 pt from the bottom, footer rule at 32 pt: the band 36-52 pt must be blank on text pages
        band = img[h - int(52 / 842 * h) : h - int(36 / 842 * h), int(0.1 * img.shape[1]) : int(0.9 * img.shape[1])]
        assert float(np.mean(band < 0.8)) < 0.02, f"{png.name}: ink between body and footer"


def test_heading_plot_has_no_wrap_artefact():
    # a DUT reading 359.x while the reference reads 0.x must be drawn next to it, not 360° away
    dut, ref, _ = heading_test(offset_deg=-0.4, noise_deg=0.05, hold_s=15.0, rolling_s=40.0)
    ev, plots = heading_evidence(dut, ref)
    figs = _heading_figures(ev, plots)
    try:
        ax = figs[0].axes[0]
        ref_line, dut_line = ax.get_lines()[:2]
        y_ref = np.asarray(ref_line.get_ydata(), float)
        y_dut = np.asarray(dut_line.get_ydata(), float)
        ok = np.isfinite(y_ref) & np.isfinite(y_dut)
        assert ok.sum() > 1000
        assert np.max(np.abs(y_dut[ok] - y_ref[ok])) < 2.0
        near_zero = ok & (np.abs(y_ref) < 1.0)
        assert near_zero.any() and np.all(y_dut[near_zero] < 2.0)  # the DUT at 359.6° is drawn at −0.4°
        # raw and static-corrected follow-up errors are both drawn
        labels = [ln.get_label() for ln in figs[1].axes[1].get_lines()]
        assert any("raw" in s for s in labels) and any("static error removed" in s for s in labels)
    finally:
        import matplotlib.pyplot as plt

        for f in figs:
            plt.close(f)


def test_heading_follow_up_needs_twenty_degrees_per_second():
    dut, ref, _ = heading_test(lag_s=0.02, noise_deg=0.03, turn_rates=(8.0, 15.0), hold_s=15.0, rolling_s=40.0)
    ev, _ = heading_evidence(dut, ref)
    fu = {it["id"]: it for it in ev["items"]}["follow_up_20"]
    assert fu["status"] == "insufficient data" and "20 °/s" in fu["reason"]
    dut, ref, _ = heading_test(lag_s=0.02, noise_deg=0.03, turn_rates=(8.0, 20.0), hold_s=15.0, rolling_s=40.0)
    ev, _ = heading_evidence(dut, ref)
    fu = {it["id"]: it for it in ev["items"]}["follow_up_20"]
    assert fu["status"] == "pass" and fu["seconds_at_test_rate"] >= 5.0
    assert fu["raw_error_stats"]["n"] == fu["stats"]["n"] and fu["raw_status"] in ("pass", "fail")


# words that kern (AV, To, T., Wa), make ligatures (fi, ffi, fl), and the report's own signs
_WORDS = (
    "AV To T. Wa L' office fluff affine fi of off -0.500 12.345 ± ° µT m/s² · • − — ≤ |error| (deg) "
    "______ 2014-08-01T12:00:00Z MSC.363(92) stbd/port Heel, “quoted” sha256 3f2a9c01d4e7 p95 RMS"
).split(" ")


def test_wrap_widths_are_matplotlibs():
    """A line's width summed from its words and joints is matplotlib's width of the whole line, and the wrap
    breaks where a wrap that measures every growing line breaks."""
    import random

    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextToPath

    from imutool.report.pdf import FONT, _Measure

    tp, m, rng = TextToPath(), _Measure(), random.Random(7)

    def mpl_width(s: str, size: float, weight: str) -> float:
        prop = FontProperties(family=FONT, size=size, weight=weight)
        return tp.get_text_width_height_descent(s, prop, ismath=False)[0] if s else 0.0

    for _ in range(120):
        words = [rng.choice(_WORDS) for _ in range(rng.randint(1, 8))]
        if rng.random() < 0.2:
            words.insert(rng.randint(0, len(words)), "")  # two spaces in a row
        size, weight = rng.choice((6.0, 7.5, 8.5, 13.0)), rng.choice(("normal", "bold"))
        ref = mpl_width(" ".join(words), size, weight)
        assert m.line_width(words, size, weight) == pytest.approx(ref, abs=1e-6), (words, size, weight)

    def greedy(text: str, width: float, size: float, weight: str) -> list[str]:  # main's wrap, line by line
        out = []
        for para in text.split("\n"):
            line = ""
            for word in para.split(" "):
                cand = word if not line else line + " " + word
                if mpl_width(cand, size, weight) <= width:
                    line = cand
                    continue
                if line:
                    out.append(line)
                while mpl_width(word, size, weight) > width and len(word) > 1:
                    k = len(word)
                    while k > 1 and mpl_width(word[:k], size, weight) > width:
                        k -= 1
                    out.append(word[:k])
                    word = word[k:]
                line = word
            out.append(line)
        return out

    for width in (40.0, 90.0, 150.0):
        text = " ".join(rng.choice(_WORDS) for _ in range(30)) + "\n  " + "x" * 40 + " AV"
        assert m.wrap(text, width, 8.5, "bold") == greedy(text, width, 8.5, "bold")


def test_page_text_draws_as_text_artists(tmp_path):
    """A layout page drawn by PageText writes the same PDF as the same page drawn with one Text per string."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.backends.backend_pdf import PdfPages

    from imutool.report.pdf import A4, FONT, PH, PW, _draw_page

    ops = [
        ("rect", 48.0, 700.0, 200.0, 20.0, "#e6e9ef"),
        ("text", 48.0, 780.0, "RESULT: PASS — ±1 °", 13.0, "bold", "white", "left"),
        ("text", 300.0, 760.0, "-12.345", 7.5, "normal", "black", "right"),
        ("text", 300.0, 750.0, "0.500", 7.5, "normal", "black", "right"),
        ("text", 60.0, 740.0, "office AV To T. (deg)", 8.5, "normal", "#333333", "left"),
        ("text", 60.0, 730.0, "", 8.5, "normal", "black", "left"),
        ("line", 48.0, 720.0, 300.0, 720.0, 0.6),
    ]

    def write(path, draw) -> bytes:
        fig = plt.figure(figsize=A4)
        draw(fig)
        with PdfPages(path, metadata={"CreationDate": None}) as pdf:
            pdf.savefig(fig)
        plt.close(fig)
        return path.read_bytes()

    def as_text_artists(fig) -> None:  # main's _draw_page: one Text per string
        _draw_page(fig, [op for op in ops if op[0] != "text"])
        fig.artists.pop()  # the (empty) PageText
        for _, x, y, s, size, weight, color, ha in (op for op in ops if op[0] == "text"):
            fig.text(x / PW, y / PH, s, fontsize=size, weight=weight, color=color, ha=ha, va="baseline",
                     family=FONT, parse_math=False)  # fmt: skip

    assert write(tmp_path / "page.pdf", lambda fig: _draw_page(fig, ops)) == write(
        tmp_path / "text.pdf", as_text_artists
    )
