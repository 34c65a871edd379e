"""Times as a user reads them: UTC clock time where the recording has a date (Unix-second times, or a UTC start
in the metadata), seconds from the start otherwise — in the evidence JSON (an ISO field beside each time), the
PDF tables and the PDF time axes (no "t peak 1406851247.4", no "+1.406851e9" axis offset)."""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pytest

from formats import Recording
from imutool.clock import Clock
from imutool.report.heading import heading_evidence
from imutool.report.pdf import render_pdf, row_cells, row_keys
from imutool.sim.programmes import heading_test

needs_pdftotext = pytest.mark.skipif(
    shutil.which("pdftotext") is None, reason="pdftotext (poppler-utils) not installed: PDF text not extracted"
)

EPOCH = 1406851200.0  # 2014-08-01T00:00:00Z


def test_clock_of_a_recording():
    dated = Clock.of(Recording(EPOCH + np.array([47.44, 50.0])))
    assert dated.dated and dated.text(EPOCH + 47.44) == "00:00:47.4" and dated.unit == "UTC"
    assert dated.iso(EPOCH + 47.44) == "2014-08-01T00:00:47.440Z" and dated.date() == "2014-08-01"
    assert dated.text(EPOCH + 59.96) == "00:01:00.0"  # rounded, not cut
    by_meta = Clock.of(Recording(np.array([10.0, 11.0]), meta={"utc_start": "2014-08-01T06:00:00Z"}))
    assert by_meta.text(10.0) == "06:00:10.0" and by_meta.iso(11.0) == "2014-08-01T06:00:11.000Z"
    plain = Clock.of(Recording(np.array([43200.0, 43201.0])))  # seconds of a day, no date: from the start
    assert not plain.dated and plain.text(43201.5) == "1.5" and plain.iso(43201.5) is None
    assert plain.axis_label() == "time (s from the start)"


@pytest.fixture(scope="module")
def dated_report(tmp_path_factory):
    dut, ref, _ = heading_test(offset_deg=0.2, noise_deg=0.05, hold_s=15.0, rolling_s=40.0)
    for r in (dut, ref):
        r.time = r.time + EPOCH
    ev, plots = heading_evidence(dut, ref)
    pdf = tmp_path_factory.mktemp("clock") / "evidence.pdf"
    render_pdf(ev, plots, str(pdf))
    return ev, plots, pdf


@pytest.mark.slow
def test_json_times_carry_iso_utc(dated_report):
    ev, _, _ = dated_report
    assert ev["conventions"]["clock"]["start_utc"] == "2014-08-01T00:00:00.000Z"
    rows = [r for it in ev["items"] for r in it.get("rows") or [] if "start_s" in r]
    assert rows and all(r["start_utc"].startswith("2014-08-01T") and r["end_utc"].endswith("Z") for r in rows)
    r = rows[0]
    assert Clock(0.0).iso(r["start_s"]) == r["start_utc"]


@pytest.mark.slow
@needs_pdftotext
def test_pdf_prints_utc_clock_times(dated_report):
    ev, plots, pdf = dated_report
    text = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], check=True, capture_output=True, text=True).stdout
    # neither the Unix seconds nor an axis offset ("+1.406851e9"); a hex id printed in the report ("…2fe9…") is not one
    assert "1406851" not in text and not re.search(r"(?<![0-9a-f])[+-]?\d(\.\d+)?e\+?0?9(?![0-9a-f])", text)
    assert "time (UTC, 2014-08-01)" in text
    clock = plots["clock"]
    for it in ev["items"]:
        rows = it.get("rows") or []
        if rows and "start_s" in rows[0]:
            keys = row_keys(rows)
            assert "start_utc" not in keys  # printed in the start column, not as a column of its own
            cells = row_cells(keys, rows[0], clock)
            assert re.fullmatch(r"\d\d:\d\d:\d\d\.\d", cells[keys.index("start_s")])
            assert " ".join(cells) in re.sub(r"\s+", " ", text)
            break
    else:
        pytest.fail("no row with a start time")
