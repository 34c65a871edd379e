"""Verdicts that mean what they say: irregular sea roll, refusals, long-term minimum, lateral acceleration,
guard band, the test record and the exit status."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import formats
from formats import ImutoolError
from imutool.cli import cli
from imutool.report.inclinometer import InclinometerOptions, inclinometer_evidence
from imutool.report.testinfo import FIELDS, load_test_info, missing_fields
from imutool.sim.programmes import inclinometer_test, sea_pair

SAMPLE_TOML = Path(__file__).resolve().parents[1] / "sample_data" / "test_info.toml"
SHORT = {
    "steps": (0.0, 10.0, 30.0, -10.0, -30.0, 0.0),
    "hold_s": 12.0,
    "dynamic": ((8.0, 10.0, 10.0, 5),),
    "long_s": 0.0,
}


def items(ev):
    return {it["id"]: it for it in ev["items"]}


# ---- irregular sea roll: two motion sensors on one ship, 1 Hz, 0.01° resolution ------------------------------
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_two_good_units_in_small_irregular_roll_agree(seed):
    # JONSWAP-like roll, σ 0.5° (peaks ≈ ±1.5°), 1 Hz, 0.01° quantisation, different noise on each unit
    dut, ref = sea_pair(duration_s=1800.0, std_deg=0.5, seed=seed, noise_ref_deg=0.02, noise_dut_deg=0.03)
    assert np.max(np.abs(ref["roll"])) < 2.5 and np.all(np.abs(ref["roll"] * 100 - np.round(ref["roll"] * 100)) < 1e-6)
    o = InclinometerOptions(declared_period_range_s=(8.0, 12.0))
    ev, _ = inclinometer_evidence(dut, ref, options=o)
    it = items(ev)
    assert ev["overall"]["status"] != "fail", ev["overall"]["headline"]
    assert not [k for k, v in it.items() if v["status"] == "fail" or v.get("derived_result") == "fail"]
    # pairing by time overlap and the amplitude/resolution limits: every judged period agrees within 0.5 s
    per = it["roll_period"]
    assert per["rows"] and max(abs(r["error_s"]) for r in per["rows"]) < 0.5
    c = per["cycles"]
    assert c["judged"] == len(per["rows"]) and c["judged"] + sum(c["not_judged"].values()) == c["reference_maxima"]
    assert c["not_judged"].get("a maximum below 1°", 0) > c["judged"]  # most small cycles are refused, and counted
    assert all(r["crest_s"] <= r["tolerance_s"] for r in per["rows"])


def test_naive_pairing_would_have_failed_the_good_pair():
    """The failure mode of the issue: consecutive same-side maxima of each unit, matched by order, drift apart
    as soon as one unit sees an excursion the other does not."""
    from imutool.roll import roll_cycles

    dut, ref = sea_pair(duration_s=1800.0, std_deg=0.5, seed=1)
    cr = roll_cycles(ref.time, ref["roll"])
    cd = roll_cycles(dut.time, dut["roll"])
    assert len(cr) != len(cd) or np.any(cr.side != cd.side) or np.max(np.abs(cr.t_peak - cd.t_peak)) > 5


@pytest.mark.parametrize("std", [0.5, 6.0])
def test_offset_of_one_and_a_half_degrees_fails(std):
    dut, ref = sea_pair(duration_s=1200.0, std_deg=std, seed=4, offset_deg=1.5)
    ev, _ = inclinometer_evidence(dut, ref)
    assert items(ev)["dynamic_heel"]["status"] == "fail"
    assert ev["overall"]["status"] == "fail" and "dynamic_heel" in ev["overall"]["headline"]


def test_seven_percent_scale_fails():
    # a 7 % scale error exceeds max(1°, 5 %) only above 14.3° of heel: a rougher sea (σ 6°, peaks > 15°)
    dut, ref = sea_pair(duration_s=1200.0, std_deg=6.0, seed=5, scale=0.07)
    assert np.max(np.abs(ref["roll"])) > 16
    ev, _ = inclinometer_evidence(dut, ref)
    it = items(ev)
    assert it["dynamic_heel"]["status"] == "fail" and ev["overall"]["status"] == "fail"
    assert it["amplitude_stbd"]["derived_result"] == "fail" or it["amplitude_port"]["derived_result"] == "fail"
    # the same sea with a good unit: nothing fails
    dut, ref = sea_pair(duration_s=1200.0, std_deg=6.0, seed=5)
    ev, _ = inclinometer_evidence(dut, ref, options=InclinometerOptions(declared_period_range_s=(8.0, 12.0)))
    assert not [k for k, v in items(ev).items() if v["status"] == "fail" or v.get("derived_result") == "fail"]
    assert items(ev)["roll_period"]["derived_result"] == "pass"


# ---- refusals ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kw",
    [
        {"angle_floor_deg": 0.0},
        {"angle_floor_deg": -1.0},
        {"angle_pct": 0.0},
        {"period_floor_s": -0.5},
        {"period_pct": -5.0},
        {"angle_pct": 150.0},
    ],
)
def test_impossible_tolerances_are_refused(kw):
    dut, ref, _ = inclinometer_test(noise_deg=0.02, **SHORT)
    with pytest.raises(ImutoolError, match="tolerance"):
        inclinometer_evidence(dut, ref, options=InclinometerOptions(**kw))


def test_device_against_itself_or_unrelated_reference_is_refused(tmp_path):
    dut, ref, _ = inclinometer_test(noise_deg=0.05, **SHORT)
    p = tmp_path / "dut.csv"
    formats.write(dut, str(p))
    r = CliRunner().invoke(
        cli, ["report", "inclinometer", str(p), "--reference", str(p), "-o", str(tmp_path / "e.pdf")]
    )
    assert r.exit_code == 2 or (r.exit_code != 0 and "own reference" in str(r.exception))
    with pytest.raises(ImutoolError, match="own reference"):
        inclinometer_evidence(ref, ref)  # the same samples
    other = formats.Recording(ref.time.copy(), {"roll": np.roll(ref["roll"], len(ref) // 3)}, {"roll": "deg"})
    with pytest.raises(ImutoolError, match="uncorrelated"):
        inclinometer_evidence(other, ref)


def test_cli_exit_status_two_for_usage_errors(tmp_path):
    from imutool.cli import main

    dut, ref, _ = inclinometer_test(noise_deg=0.05, **SHORT)
    pd_, pr = tmp_path / "dut.csv", tmp_path / "ref.csv"
    formats.write(dut, str(pd_))
    formats.write(ref, str(pr))
    bad = tmp_path / "bad.toml"
    bad.write_text("[dut]\nheel_range_deg = -5\n")
    for extra in (["--angle-floor", "0"], ["--period-pct", "-1"], ["--test-info", str(bad)]):
        with pytest.raises(SystemExit) as exc:
            main(["report", "inclinometer", str(pd_), "--reference", str(pr), "-o", str(tmp_path / "x.pdf"), *extra])
        assert exc.value.code == 2, extra
    assert not (tmp_path / "x.pdf").exists()


# ---- long-term hold, lateral acceleration, guard band -------------------------------------------------------
def test_long_term_needs_the_stated_minimum_hold():
    dut, ref, _ = inclinometer_test(noise_deg=0.05, drift_deg_per_h=0.1, **{**SHORT, "long_s": 330.0})
    lt = items(inclinometer_evidence(dut, ref)[0])["long_term"]
    assert lt["status"] == "insufficient data" and lt["minimum_hold_s"] == 3600.0
    assert "shorter than the 3600 s minimum" in lt["reason"]
    # an hour-long hold at 1 Hz resolves a 0.1 °/h drift
    dut, ref, _ = inclinometer_test(noise_deg=0.05, drift_deg_per_h=0.1, **{**SHORT, "long_s": 3700.0})
    lt = items(inclinometer_evidence(dut, ref)[0])["long_term"]
    assert lt["status"] == "pass" and abs(lt["drift_deg_per_h"] - 0.1) < 3 * lt["drift_u95_deg_per_h"]
    assert lt["drift_u95_deg_per_h"] < 0.05
    # a drift limit the hold cannot resolve is refused; a drift beyond the limit fails
    o = InclinometerOptions(drift_limit_deg_per_h=0.01)
    assert items(inclinometer_evidence(dut, ref, options=o)[0])["long_term"]["status"] == "insufficient data"
    dut, ref, _ = inclinometer_test(noise_deg=0.05, drift_deg_per_h=0.5, **{**SHORT, "long_s": 3700.0})
    o = InclinometerOptions(drift_limit_deg_per_h=0.25)
    assert items(inclinometer_evidence(dut, ref, options=o)[0])["long_term"]["status"] == "fail"


@pytest.mark.parametrize("coupling,expect", [(0.05, "pass"), (1.0, "fail")])
def test_lateral_acceleration_item(coupling, expect):
    # 1 m/s² tilts an accelerometer's apparent vertical by 5.8°: an accelerometer-only DUT fails, a gyro-aided one
    # (5 % leakage, 0.3°) passes; the segment is its own item, not a static step or dynamic heel
    dut, ref, _ = inclinometer_test(noise_deg=0.03, accel_coupling=coupling, lat_accel_ms2=1.0, **SHORT)
    it = items(inclinometer_evidence(dut, ref)[0])
    la = it["lateral_acceleration"]
    assert la["status"] == expect and abs(la["max_accel_ms2"] - 1.0) < 0.01
    assert abs(la["stats"]["max_abs"] - coupling * np.degrees(np.arctan(1.0 / 9.80665))) < 0.15
    assert it["dynamic_heel"]["status"] == "pass" and it["static_heel"]["status"] != "fail"


def test_guard_band_decision_rule(tmp_path):
    # offset 0.9°: passes simple acceptance (1°), fails with a guard band of U = 0.2° (limit 0.8°)
    dut, ref, _ = inclinometer_test(offset_deg=0.9, noise_deg=0.01, **SHORT)
    st = items(inclinometer_evidence(dut, ref)[0])["static_heel"]
    assert all(r["status"] == "pass" for r in st["rows"] if abs(r["reference_deg"]) < 20)
    toml = tmp_path / "t.toml"
    toml.write_text('[reference]\nuncertainty_k2_deg = 0.2\n[decision_rule]\nrule = "guard band"\n')
    ev, _ = inclinometer_evidence(dut, ref, test_info=load_test_info(str(toml)))
    st = items(ev)["static_heel"]
    assert st["status"] == "fail" and all(
        abs(r["tolerance_deg"] - 0.8) < 1e-9 for r in st["rows"] if abs(r["reference_deg"]) < 20
    )
    assert any(c["id"] == "decision_rule" and "guard band" in c["text"] for c in ev["criteria"])
    with pytest.raises(ImutoolError, match="uncertainty"):
        inclinometer_evidence(dut, ref, options=InclinometerOptions(guard_band=True))


# ---- test record ---------------------------------------------------------------------------------------------
def test_example_test_record_is_complete_and_blank_fields_stay_blank(tmp_path):
    info = load_test_info(str(SAMPLE_TOML))
    assert missing_fields(info) == []
    assert info["dut"]["heel_range_deg"] == 45.0 and info["report"]["number"]
    assert set(info["external"]) == {"display", "alarms", "power_supply", "environmental_emc"}
    part = tmp_path / "part.toml"
    part.write_text('[report]\nnumber = "R-1"\n[test]\noperator = "A. N. Other"\n')
    info = load_test_info(str(part))
    miss = missing_fields(info)
    assert len(miss) == len(FIELDS) - 2 and "Witness (surveyor)" in miss and "Calibration certificate no." in miss
    dut, ref, _ = inclinometer_test(noise_deg=0.05, **SHORT)
    ev, _ = inclinometer_evidence(dut, ref, test_info=info)
    assert ev["test_record"]["test"]["witness"] is None  # never invented
    assert ev["test_record_missing"] == miss


@pytest.mark.parametrize(
    "text,msg",
    [
        ("[dut]\nheel_range = 30\n", "unknown field"),
        ("[lab]\nx = 1\n", "unknown section"),
        ('[external.display]\nresult = "pass"\n', "evidence"),
        ('[external.display]\nresult = "ok"\nevidence = "x"\n', "result"),
        ('[decision_rule]\nrule = "whatever"\n', "rule"),
        ("[dut]\nperiod_range_s = [30, 4]\n", "min, max"),
        ("not toml [", "TOML"),
    ],
)
def test_bad_test_record_is_one_clear_error(tmp_path, text, msg):
    p = tmp_path / "t.toml"
    p.write_text(text)
    with pytest.raises(ImutoolError, match=msg):
        load_test_info(str(p))


def test_attested_clauses_complete_the_verdict(tmp_path):
    """PASS needs every required item: the external clauses come only from an attestation with evidence."""
    dut, ref, _ = inclinometer_test(noise_deg=0.05, **SHORT)
    ev, _ = inclinometer_evidence(dut, ref, test_info=load_test_info(str(SAMPLE_TOML)))
    it = items(ev)
    assert it["display"]["status"] == "pass" and "not verified by imutool" in it["display"]["reason"]
    ov = ev["overall"]
    assert ov["status"] == "incomplete" and ov["exit_status"] == 1
    assert "display" in ov["passed"] and "interface" in ov["not_tested"] and "long_term" in ov["not_tested"]
    assert json.dumps(ev, allow_nan=False)
