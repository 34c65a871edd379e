"""Heading-device evidence (ISO 22090-2 / MSC.116(73)): injected errors recovered, limits flip, honest gaps."""

from __future__ import annotations

import jsonschema
import numpy as np
import pytest

import formats
from imutool.cli.nmea import nmea_lines
from imutool.report.heading import HeadingOptions, heading_evidence
from imutool.report.pdf import load_schema, render_pdf
from imutool.sim.programmes import heading_test


def items(ev):
    return {it["id"]: it for it in ev["items"]}


SHORT = {"hold_s": 15.0, "rolling_s": 40.0}


def test_static_error_by_heading_matches_injected():
    a, b, off = 0.4, -0.25, 0.2
    dut, ref, _ = heading_test(offset_deg=off, semicircular_deg=(a, b), noise_deg=0.05, lag_s=0.03, **SHORT)
    ev, _ = heading_evidence(dut, ref)
    st = items(ev)["static"]
    assert st["status"] == "pass" and st["distinct_headings"] == 8
    for r in st["rows"]:
        h = np.radians(r["heading_deg"])
        assert abs(r["error_mean_deg"] - (off + a * np.sin(h) + b * np.cos(h))) < 0.02
    # latency recovered from the follow-up error (static error by heading removed)
    assert abs(ev["alignment"]["latency_from_follow_up_s"] - 0.03) < 0.005
    jsonschema.validate(ev, load_schema())


@pytest.mark.parametrize("offset,expect", [(0.98, "pass"), (1.02, "fail")])
def test_static_limit_flips(offset, expect):
    dut, ref, _ = heading_test(offset_deg=offset, **SHORT)
    ev, _ = heading_evidence(dut, ref)
    assert items(ev)["static"]["status"] == expect


@pytest.mark.parametrize("lag,expect", [(0.058, "pass"), (0.066, "fail")])
def test_follow_up_band_flips_with_latency(lag, expect):
    # 8 °/s turn: follow-up error = rate · latency → 0.46° (pass) vs 0.53° (fail) against ±0.5°
    dut, ref, _ = heading_test(lag_s=lag, turn_rates=(8.0, 20.0), slew_dps=3.0, **SHORT)
    ev, _ = heading_evidence(dut, ref)
    fu = items(ev)["follow_up_10"]
    assert fu["status"] == expect, fu["reason"]
    assert abs(fu["stats"]["max_abs"] - 8.0 * lag) < 0.03
    assert items(ev)["follow_up_20"]["status"] == "pass"  # 20 °/s · 0.066 s ≈ 1.3° < 1.5°


def test_dynamic_error_from_roll_coupling():
    dut, ref, _ = heading_test(roll_coupling=0.04, **SHORT)  # ±0.4° at the 10 s roll period
    ev, _ = heading_evidence(dut, ref)
    d = items(ev)["dynamic"]
    assert d["status"] == "pass" and abs(d["amplitude_deg"] - 0.4) < 0.05
    dut, ref, _ = heading_test(roll_coupling=0.07, **SHORT)  # ±0.7° faster than 0.033 Hz → fails the clause
    ev, _ = heading_evidence(dut, ref)
    d = items(ev)["dynamic"]
    assert d["status"] == "fail" and "0.033" in d["reason"]


def test_too_few_headings_and_no_motion_are_not_a_pass():
    dut, ref, _ = heading_test(headings=2, turn_rates=(), rolling_s=0.0, roll_amp_deg=0.0, hold_s=15.0)
    ev, _ = heading_evidence(dut, ref)
    it = items(ev)
    assert it["static"]["status"] == "insufficient data"
    assert it["follow_up_20"]["status"] == "not tested"
    assert it["dynamic"]["status"] == "not tested"
    assert ev["overall"]["status"] == "incomplete"
    jsonschema.validate(ev, load_schema())


def test_the_dut_is_not_its_own_reference(tmp_path):
    """The same file and channel as DUT and reference would pass every item with zero error: refused, as the
    inclinometer report does; the same file with a variation correction is a different comparison (allowed)."""
    dut, _, _ = heading_test(**SHORT)
    path = tmp_path / "gyro.csv"
    formats.write(dut, path)
    rec = formats.read(path)
    with pytest.raises(formats.ImutoolError, match="cannot be its own reference"):
        heading_evidence(rec, formats.read(path), dut_path=str(path), ref_path=str(path))
    with pytest.raises(formats.ImutoolError, match="cannot be its own reference"):
        heading_evidence(rec, rec)
    ev, _ = heading_evidence(rec, rec, dut_correction_deg=1.0)
    assert abs(items(ev)["dynamic"]["amplitude_deg"] - 1.0) < 1e-6  # the correction is the whole error


@pytest.mark.slow
def test_nmea_dut_interface_and_pdf(tmp_path):
    dut, ref, _ = heading_test(offset_deg=0.1, **SHORT)
    nm = tmp_path / "dmc.nmea"
    with open(nm, "w", newline="") as fh:
        for ts, s in nmea_lines(dut, ["HDG"], None, deviation_deg=None, variation_deg=None):
            fh.write(f"{ts:.3f} {s}\r\n")
    dut_n = formats.read(nm)
    ev, plots = heading_evidence(dut_n, ref, dut_path=str(nm), options=HeadingOptions())
    it = items(ev)
    assert it["interface"]["status"] == "pass", it["interface"]["reason"]
    assert it["static"]["status"] == "pass"
    assert ev["inputs"]["dut"]["kind"] == "nmea" and len(ev["inputs"]["dut"]["sha256"]) == 64
    pages = render_pdf(ev, plots, str(tmp_path / "heading.pdf"))
    assert pages >= 4 and (tmp_path / "heading.pdf").read_bytes()[:5] == b"%PDF-"
