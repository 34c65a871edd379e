"""Inclinometer evidence: injected errors recovered, pass/fail at the tolerance, honest "not tested", PDF/JSON."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from click.testing import CliRunner

import formats
from formats import Recording
from formats.nmea import checksum
from imutool.cli import cli
from imutool.report.inclinometer import InclinometerOptions, hrm_capture_check, inclinometer_evidence
from imutool.report.pdf import load_schema
from imutool.roll import roll_stats
from imutool.sim.programmes import inclinometer_test, write_sample_data, write_steps_csv

SAMPLE_TOML = str(Path(__file__).resolve().parents[1] / "sample_data" / "test_info.toml")
SHORT = {
    "steps": (0.0, 5.0, 10.0, 30.0, -5.0, -10.0, -30.0, 0.0),
    "hold_s": 15.0,
    "dynamic": ((8.0, 10.0, 10.0, 5), (12.0, 20.0, 14.0, 4)),
    "long_s": 0.0,
}


def items(ev):
    return {it["id"]: it for it in ev["items"]}


@pytest.fixture(scope="module")
def injected():
    dut, ref, segs = inclinometer_test(
        offset_deg=0.3, scale=0.02, lag_s=0.4, noise_deg=0.05, ref_noise_deg=0.01, seed=2, **SHORT
    )
    ev, _ = inclinometer_evidence(dut, ref, options=InclinometerOptions(align="xcorr"))
    return ev, segs


def test_injected_errors_are_measured(injected):
    ev, _ = injected
    a = ev["alignment"]
    assert abs(a["lag_s"] - 0.4) < 0.02
    assert abs(a["linear_fit"]["offset_deg"] - 0.3) < 0.02
    assert abs(a["linear_fit"]["scale_error"] - 0.02) < 0.002
    it = items(ev)
    # static: each step's mean error = offset + scale·reference; scatter = injected noise
    for r in it["static_heel"]["rows"]:
        assert abs(r["error_mean_deg"] - (0.3 + 0.02 * r["reference_deg"])) < 0.03
    assert abs(np.median([r["error_std_deg"] for r in it["static_heel"]["rows"]]) - np.hypot(0.05, 0.01)) < 0.01
    # amplitude errors per side follow the model: stbd +offset + scale·A, port −offset + scale·A
    for r in it["amplitude_stbd"]["rows"]:
        assert abs(r["error_deg"] - (0.3 + 0.02 * r["reference_deg"])) < 0.06
    for r in it["amplitude_port"]["rows"]:
        assert abs(r["error_deg"] - (-0.3 + 0.02 * r["reference_deg"])) < 0.06
    assert it["roll_period"]["stats"]["max_abs"] < 0.1
    assert ev["overall"]["status"] == "incomplete"  # everything passes, but the long-term item is not tested
    # the longest hold is a 15 s step: far below the stated 3600 s minimum, so long-term is not judged
    assert it["long_term"]["status"] == "insufficient data" and "3600 s minimum" in it["long_term"]["reason"]


def test_lag_counts_as_error_without_alignment():
    dut, ref, _ = inclinometer_test(lag_s=0.4, **SHORT)
    ev, _ = inclinometer_evidence(dut, ref)  # default: common clock, no lag removed
    assert abs(ev["alignment"]["lag_s"] - 0.4) < 0.02 and not ev["alignment"]["applied"]
    # 0.4 s lag at 20° / 12 s: up to 2π·20/12·0.4 ≈ 4.2° error → the dynamic test must fail
    assert items(ev)["dynamic_heel"]["status"] == "fail"


@pytest.mark.parametrize("offset,expect", [(0.98, "pass"), (1.02, "fail"), (-0.98, "pass"), (-1.02, "fail")])
def test_static_offset_flips_at_one_degree(tmp_path, offset, expect):
    dut, ref, segs = inclinometer_test(offset_deg=offset, **SHORT)
    steps = tmp_path / "steps.csv"
    write_steps_csv(segs, str(steps))
    ev, _ = inclinometer_evidence(
        dut, ref, steps_path=str(steps), options=InclinometerOptions(declared_heel_range_deg=30.0)
    )
    st = items(ev)["static_heel"]
    assert st["status"] == expect
    small = [r for r in st["rows"] if abs(r["reference_deg"]) <= 10]
    assert all(r["status"] == expect for r in small)  # tolerance 1° up to 20°


@pytest.mark.parametrize("scale,expect", [(0.049, "pass"), (0.051, "fail")])
def test_static_scale_flips_at_five_percent(scale, expect):
    dut, ref, _ = inclinometer_test(scale=scale, **SHORT)
    ev, _ = inclinometer_evidence(dut, ref, options=InclinometerOptions(declared_heel_range_deg=30.0))
    rows = items(ev)["static_heel"]["rows"]
    at30 = [r for r in rows if abs(abs(r["reference_deg"]) - 30.0) < 0.01]
    assert len(at30) == 2 and all(r["status"] == expect for r in at30)
    assert all(abs(r["tolerance_deg"] - 1.5) < 1e-9 for r in at30)
    assert items(ev)["static_heel"]["status"] == expect


def _device_outputs(ref: Recording, d_amp=0.0, d_period=0.0) -> Recording:
    """A DUT that reports HRM-like fields: the reference's own statistics plus injected errors."""
    rs = roll_stats(ref.time, ref["roll"])
    heel = ref["roll"] + 0.01  # the device's heel (not sample-for-sample the reference: that is refused)
    return Recording(
        ref.time.copy(),
        {
            "roll": heel,
            "roll_period": rs.roll_period + d_period,
            "amp_port": rs.amp_port + d_amp,
            "amp_stbd": rs.amp_stbd + d_amp,
            "peak_port": rs.peak_port,
            "peak_stbd": rs.peak_stbd,
        },
        {"roll_period": "s", "amp_port": "deg", "amp_stbd": "deg", "peak_port": "deg", "peak_stbd": "deg"},
    )


@pytest.mark.parametrize("d,expect", [(0.97, "pass"), (1.03, "fail")])
def test_amplitude_and_period_flip_at_tolerance(d, expect):
    _, ref, _ = inclinometer_test(steps=(0.0,), dynamic=((10.0, 10.0, 10.0, 8),), long_s=0.0)
    o = InclinometerOptions(declared_period_range_s=(9.0, 11.0))  # the programme rolls at 10 s only
    ev, _ = inclinometer_evidence(_device_outputs(ref, d_amp=d), ref, options=o)
    it = items(ev)
    assert it["amplitude_stbd"]["status"] == expect and it["amplitude_port"]["status"] == expect
    assert it["amplitude_stbd"]["source"].startswith("reported by the device")
    assert abs(it["amplitude_stbd"]["stats"]["mean"] - d) < 0.01
    # tolerance max(1 s, 5 % of 10 s) = 1 s
    ev, _ = inclinometer_evidence(_device_outputs(ref, d_period=d), ref, options=o)
    assert items(ev)["roll_period"]["status"] == expect
    assert abs(items(ev)["roll_period"]["stats"]["mean"] - d) < 0.01


def test_never_pass_without_data():
    # static steps only: dynamic/amplitude/period are not tested, the report is incomplete, not a pass
    dut, ref, _ = inclinometer_test(dynamic=(), long_s=0.0, hold_s=15.0, noise_deg=0.02)
    ev, _ = inclinometer_evidence(dut, ref, options=InclinometerOptions(declared_heel_range_deg=45.0))
    it = items(ev)
    assert it["static_heel"]["status"] == "pass"
    for k in ("dynamic_heel", "amplitude_stbd", "amplitude_port", "roll_period"):
        assert it[k]["status"] in ("not tested", "insufficient data"), k
    assert ev["overall"]["status"] == "incomplete"
    assert any("Roll period" in s for s in ev["not_tested"])
    # two roll cycles only: too few to judge, even though they are accurate
    dut, ref, _ = inclinometer_test(steps=(0.0,), dynamic=((10.0, 10.0, 10.0, 2),), long_s=0.0, noise_deg=0.02)
    ev, _ = inclinometer_evidence(dut, ref)
    for k in ("amplitude_stbd", "amplitude_port", "roll_period"):
        assert items(ev)[k]["status"] in ("insufficient data", "not tested"), k
    dut, ref, _ = inclinometer_test(steps=(0.0,), dynamic=((10.0, 10.0, 10.0, 3),), long_s=20.0, noise_deg=0.02)
    ev, _ = inclinometer_evidence(dut, ref)
    amp = items(ev)["amplitude_stbd"]
    # derived by imutool from a CSV heel: the device's function is not tested; the derived result is shown
    assert amp["status"] == "not tested" and amp["derived_result"] == "pass"
    assert len(amp["rows"]) == 3 and amp["cycles"]["judged"] == 6 and "not reported by the device" in amp["reason"]
    # steps on one side only
    dut, ref, _ = inclinometer_test(steps=(0.0, 5.0, 10.0, 20.0), dynamic=(), long_s=0.0, hold_s=15.0, noise_deg=0.02)
    ev, _ = inclinometer_evidence(dut, ref)
    assert items(ev)["static_heel"]["status"] == "insufficient data"
    jsonschema.validate(ev, load_schema())


def test_sign_mismatch_is_flagged():
    dut, ref, _ = inclinometer_test(**SHORT)
    dut.channels["roll"] = -dut["roll"]
    ev, _ = inclinometer_evidence(dut, ref)
    assert any("sign" in w for w in ev["warnings"])
    assert ev["overall"]["status"] == "fail"


def test_bad_steps_file(tmp_path):
    dut, ref, _ = inclinometer_test(noise_deg=0.02, **SHORT)
    p = tmp_path / "steps.csv"
    p.write_text("start,end\n10,5\n")
    with pytest.raises(formats.ImutoolError, match="not after start"):
        inclinometer_evidence(dut, ref, steps_path=str(p))
    p.write_text("a,b\n1,2\n")
    with pytest.raises(formats.ImutoolError, match="header"):
        inclinometer_evidence(dut, ref, steps_path=str(p))


def test_hrm_capture_interface(tmp_path):
    files = write_sample_data(str(tmp_path), rate_hz=5.0)
    nm = files["inclinometer_dut.nmea"]
    # corrupt one sentence's checksum: the interface item must fail and count it
    lines = open(nm, newline="").read().split("\r\n")
    lines[500] = lines[500][:-2] + ("00" if not lines[500].endswith("00") else "11")
    bad = tmp_path / "bad.nmea"
    bad.write_text("\r\n".join(lines), newline="")
    # and one sentence's status field (A or V) wrong under a good checksum: a field format error
    k = next(i for i in range(600, len(lines)) if "HRM" in lines[i])
    d = lines[k].index("$")
    f = lines[k][d + 1 : lines[k].index("*")].split(",")
    body = ",".join(f[:5] + ["X"] + f[6:])
    lines[k] = f"{lines[k][:d]}${body}*{checksum(body)}"
    bad.write_text("\r\n".join(lines), newline="")
    cap = hrm_capture_check(str(bad))
    assert cap["checksum_bad"] == 1 and cap["hrm_sentences"] == len([x for x in lines if "HRM" in x])
    assert cap["field_format_errors"] == 1 and cap["checksum_ok"] == cap["hrm_sentences"] - 1
    ref = formats.read(files["inclinometer_reference.csv"])
    dut = formats.read(nm)
    ev, _ = inclinometer_evidence(dut, ref, dut_path=nm)
    it = items(ev)
    assert it["interface"]["status"] == "pass", it["interface"]["reason"]
    assert it["amplitude_stbd"]["source"].startswith("reported by the device")
    assert it["peak_hold"]["source"].startswith("reported by the device")
    for k in ("amplitude_stbd", "amplitude_port", "roll_period", "peak_hold"):
        assert it[k]["status"] == "pass", (k, it[k]["reason"])
    # 5 Hz through the programme, 1 Hz through the hour-long hold (the sample keeps files small that way)
    iv = it["interface"]["capture"]["output_intervals_s"]
    assert iv["0.2"] > 3000 and abs(iv["1"] - 3700) <= 1
    jsonschema.validate(ev, load_schema())
    ev, _ = inclinometer_evidence(formats.read(str(bad), checksum_policy="require"), ref, dut_path=str(bad))
    assert items(ev)["interface"]["status"] == "fail"


@pytest.mark.slow
def test_cli_pdf_and_json(tmp_path):
    files = write_sample_data(str(tmp_path / "sample"), rate_hz=5.0)
    pdf = tmp_path / "out" / "evidence.pdf"
    # a CSV DUT: amplitude/period/peak hold only derived by imutool, no interface → INCOMPLETE, exit status 1
    r = CliRunner().invoke(
        cli,
        [
            "report",
            "inclinometer",
            files["inclinometer_dut.csv"],
            "--reference",
            files["inclinometer_reference.csv"],
            "--static-steps",
            files["inclinometer_steps.csv"],
            "-o",
            str(pdf),
            "--device",
            "SIM-INC-1 s/n 1",
            "--json",
        ],
    )
    assert r.exit_code == 1, r.output
    summary = json.loads(r.stdout)
    ev = json.loads((tmp_path / "out" / "evidence.json").read_text())
    jsonschema.validate(ev, load_schema())
    assert summary["overall"] == ev["overall"]["status"] == "incomplete"
    assert summary["headline"].startswith("INCOMPLETE: passed: ") and "not tested: " in summary["headline"]
    for k in ("interface", "amplitude_stbd", "roll_period", "peak_hold", "display"):
        assert k in ev["overall"]["not_tested"]
    assert ev["inputs"]["dut"]["sha256"] and len(ev["inputs"]["static_steps"]["sha256"]) == 64
    assert ev["identification"]["device_declared"] == "SIM-INC-1 s/n 1"
    assert pdf.exists() and pdf.read_bytes()[:5] == b"%PDF-"
    # the HRM capture and the example test record: every required item tested → PASS, exit status 0
    pdf2 = tmp_path / "out" / "evidence_hrm.pdf"
    r = CliRunner().invoke(
        cli,
        [
            "report",
            "inclinometer",
            files["inclinometer_dut.nmea"],
            "--reference",
            files["inclinometer_reference.csv"],
            "--static-steps",
            files["inclinometer_steps.csv"],
            "--test-info",
            SAMPLE_TOML,
            "-o",
            str(pdf2),
            "--json",
        ],
    )
    assert r.exit_code == 0, r.output
    summary = json.loads(r.stdout)
    assert summary["overall"] == "pass" and summary["exit_status"] == 0
    if shutil.which("pdftoppm") is None:
        pytest.skip("pdftoppm (poppler-utils) not installed: PDF pages not rasterised")
    subprocess.run(["pdftoppm", "-r", "40", "-png", str(pdf2), str(tmp_path / "page")], check=True)
    pages = sorted(tmp_path.glob("page-*.png"))
    assert len(pages) == summary["pages"] >= 8
    import matplotlib.image as mpimg

    ink = []
    for png in pages:
        img = mpimg.imread(png)[..., :3]
        h, w = img.shape[:2]
        mid = img[int(0.1 * h) : int(0.9 * h), int(0.1 * w) : int(0.9 * w)]
        ink.append(float(np.mean(mid.mean(axis=2) < 0.9)))
    assert min(ink) > 0.005, f"a nearly blank page: {ink}"  # no empty pages (a page break before nothing)
    # a bad output name is one clear error
    r = CliRunner().invoke(
        cli,
        [
            "report",
            "inclinometer",
            files["inclinometer_dut.csv"],
            "--reference",
            files["inclinometer_reference.csv"],
            "-o",
            str(tmp_path / "x.txt"),
        ],
    )
    assert r.exit_code != 0 and ".pdf" in str(r.exception)


def test_plot_tolerance_bands_follow_the_configured_tolerances():
    dut, ref, _ = inclinometer_test(seed=3, noise_deg=0.02, **SHORT)
    o = InclinometerOptions(angle_floor_deg=0.5, angle_pct=2.0, period_floor_s=0.7, period_pct=3.0)
    _, plots = inclinometer_evidence(dut, ref, options=o)
    np.testing.assert_allclose(plots["tol_angle"](np.array([0.0, 10.0, 40.0])), [0.5, 0.5, 0.8])
    np.testing.assert_allclose(plots["tol_period"](np.array([10.0, 30.0])), [0.7, 0.9])
    assert "0.5°" in plots["tol_angle_label"] and "2 %" in plots["tol_angle_label"]


# -- a reference as it comes: another Seapath, a clockless table log; windows in UTC ------------------------------
T_2014 = 1406894400.0  # 2014-08-01T12:00:00Z


def _psxn23(roll: float) -> str:
    """$PSXN,23 (Kongsberg Seapath): roll (+ port up = imutool's), pitch (+ bow up), heading (true), heave (+ down),
    with its checksum; the documented layout."""
    from formats.nmea import checksum

    body = f"PSXN,23,{roll:.2f},0.50,120.00,-0.10"
    return f"${body}*{checksum(body)}"


def _table_roll(n: int, rate_hz: float = 2.0) -> np.ndarray:
    """A tilt table's roll (deg, 2 decimals as a Seapath sends them): 8° at 12 s."""
    return np.round(8.0 * np.sin(2 * np.pi * (np.arange(n) / rate_hz) / 12.0), 2)


def _seapath_log(path: Path, roll: np.ndarray, rate_hz: float = 2.0) -> str:
    """A logger's file of $PSXN,23 lines, each after its arrival stamp (Unix s, 2014-08-01 from 12:00:00 UTC)."""
    path.write_text("".join(f"{T_2014 + k / rate_hz:.2f} {_psxn23(r)}\n" for k, r in enumerate(roll)))
    return str(path)


def _report(capsys, tmp_path: Path, args: list[str]) -> tuple[int, str, dict]:
    """``imutool report inclinometer ARGS -o ev.pdf`` in-process → (exit status, stdout — on an error its one
    error line —, the evidence JSON or {})."""
    from imutool.cli import main

    (tmp_path / "ev.json").unlink(missing_ok=True)
    code = 0
    try:
        main(["report", "inclinometer", *args, "-o", str(tmp_path / "ev.pdf"), "--force"])
    except SystemExit as e:
        code = int(e.code or 0)
    out, err = capsys.readouterr()
    if code == 2:
        errors = [ln for ln in err.splitlines() if ": error: " in ln]
        assert len(errors) == 1 and "Traceback" not in err, err
        return code, errors[0], {}
    return code, out, json.loads((tmp_path / "ev.json").read_text())


@pytest.mark.slow
def test_two_seapath_logs_as_dut_and_reference_in_a_utc_window(tmp_path, capsys):
    """Issue 38: one Seapath against another in one call, no parser written; the DUT reads the table's roll + 0.30°.
    The window is given as UTC clock time; a lateral-acceleration log is merged onto the reference (--ref-with)."""
    ref_roll = _table_roll(1200)
    ref = _seapath_log(tmp_path / "seapath_b.nmea", ref_roll)
    dut = _seapath_log(tmp_path / "seapath_a.nmea", ref_roll + 0.30)
    acc = tmp_path / "accel.csv"
    acc.write_text("time,lat_accel\n" + "".join(f"{T_2014 + k:.1f},0\n" for k in range(601)))
    code, out, ev = _report(
        capsys,
        tmp_path,
        [dut, "--reference", ref, "--start", "2014-08-01T12:01:00Z", "--end", "2014-08-01T12:09:00Z"]
        + ["--ref-with", str(acc)],
    )
    assert code == 1, out  # INCOMPLETE/FAIL: a CSV-less NMEA DUT without HRM cannot pass the interface item
    jsonschema.validate(ev, load_schema())
    it = items(ev)
    dyn = it["dynamic_heel"]
    assert dyn["status"] == "pass"
    assert dyn["stats"]["max_abs"] == pytest.approx(0.30, abs=1e-6)
    assert dyn["stats"]["rmse"] == pytest.approx(0.30, abs=1e-6)
    assert dyn["stats"]["n"] == 960  # [12:01:00, 12:09:00) at 2 Hz
    fit = ev["alignment"]["linear_fit"]
    assert fit["offset_deg"] == pytest.approx(0.30, abs=1e-3) and abs(fit["scale_error"]) < 1e-4
    for side in ("amplitude_stbd", "amplitude_port"):
        assert it[side]["stats"]["max_abs"] == pytest.approx(0.30, abs=0.011)  # stbd +0.3, port −0.3 (2-dp crests)
    assert ev["inputs"]["dut"]["meta"]["evaluated_window_utc"] == [
        "2014-08-01T12:01:00.000Z",
        "2014-08-01T12:09:00.000Z",
    ]
    assert ev["conventions"]["clock"]["start_utc"] == "2014-08-01T12:01:00.000Z"
    ld = ev["inputs"]["reference"]["loading"]
    assert ld["dated"] and ld["options"] == {"--ref-with": [str(acc)]}
    assert ld["merged"] == [{"input": str(acc), "channels": ["lat_accel"], "offset_s": 0.0}]
    assert ev["inputs"]["dut"]["loading"] == {"options": {}, "time": "stamp", "dated": True}
    assert "reference loaded: --ref-with" in out


@pytest.mark.slow
def test_clockless_reference_given_its_rate_header_rows_and_start(tmp_path, capsys):
    """A tilt table's log without a clock (a row of names, a row of units, 2 Hz) against a dated Seapath DUT."""
    ref_roll = _table_roll(1200)
    dut = _seapath_log(tmp_path / "seapath.nmea", np.round(1.05 * ref_roll, 2))  # the DUT reads 5 % high
    table = tmp_path / "table.csv"
    table.write_text("Roll,Pitch\ndeg,deg\n" + "".join(f"{r:.2f},0.5\n" for r in ref_roll))
    args = [dut, "--reference", str(table), "--ref-rate", "2", "--ref-header-rows", "2"]
    code, out, _ = _report(capsys, tmp_path, args)  # without --ref-start: the table counts from 0, the DUT is dated
    assert code == 2 and "do not overlap in time" in out
    code, out, ev = _report(capsys, tmp_path, [*args, "--ref-start", "2014-08-01T12:00:00Z"])
    assert code == 1, out
    fit = ev["alignment"]["linear_fit"]
    assert fit["scale_error"] == pytest.approx(0.05, abs=2e-3) and abs(fit["offset_deg"]) < 0.01
    dyn = items(ev)["dynamic_heel"]["stats"]
    assert dyn["max_abs"] == pytest.approx(0.40, abs=0.011) and dyn["n"] == 1200  # 5 % of 8°
    ld = ev["inputs"]["reference"]["loading"]
    assert ld["options"] == {"--ref-rate": 2.0, "--ref-header-rows": 2, "--ref-start": "2014-08-01T12:00:00Z"}
    assert ld["dated"] and "--ref-rate 2 Hz" in ld["time"] and "first row at --ref-start" in ld["time"]
    assert ev["inputs"]["reference"]["meta"]["source_header_rows"] == 2
    # a reference option the reference's format does not take is one line naming the reference's flag
    code, out, _ = _report(capsys, tmp_path, [dut, "--reference", dut, "--ref-rate", "2"])
    assert code == 2 and "--ref-rate: only for a CSV file" in out


def test_report_window_refusals(tmp_path, capsys):
    """A UTC --start on a recording without a date, and a window outside the recording: one line, exit status 2."""
    ref_roll = _table_roll(240)
    ref = _seapath_log(tmp_path / "b.nmea", ref_roll)
    dut = _seapath_log(tmp_path / "a.nmea", ref_roll + 0.1)
    code, out, _ = _report(capsys, tmp_path, [dut, "--reference", ref, "--start", "2014-08-01T13:00:00Z"])
    assert code == 2 and "outside the recording (12:00:00.0 … 12:01:59.5 UTC, 2014-08-01)" in out
    code, out, _ = _report(capsys, tmp_path, [dut, "--reference", ref, "--end", "1406894000"])  # seconds on its clock
    assert code == 2 and "--end 1406894000.0: outside the recording" in out
    code, out, _ = _report(
        capsys, tmp_path, [dut, "--reference", ref, "--start", "2014-08-01T12:01:00", "--end", "12:00"]
    )
    assert code == 2 and "--end" in out and "UTC date and time" in out
    nodate = tmp_path / "nodate.csv"
    nodate.write_text("time,roll\n" + "".join(f"{k / 2:.1f},{r:.2f}\n" for k, r in enumerate(ref_roll)))
    code, out, _ = _report(capsys, tmp_path, [str(nodate), "--reference", ref, "--start", "2014-08-01T12:00:30Z"])
    assert code == 2 and len(out.strip().splitlines()) == 1
    assert "nodate.csv: --start 2014-08-01T12:00:30Z: a UTC clock time, but the recording has no date" in out


@pytest.mark.slow
def test_reference_with_foreign_column_names_mapped_with_ref_columns(tmp_path, capsys):
    """An NMEA DUT (no --columns of its own to lend) against a ship's CSV log whose roll/pitch are HeelDeg/TrimDeg:
    --ref-columns maps them. A CSV DUT's --profile is not the reference's once it has its own mapping; without
    one, the reference takes the DUT's as before."""
    ref_roll = _table_roll(240)
    dut = _seapath_log(tmp_path / "seapath.nmea", ref_roll + 0.20)
    log = tmp_path / "shiplog.csv"
    log.write_text(
        "Time_s,HeelDeg,TrimDeg\n" + "".join(f"{T_2014 + k / 2:.2f},{r:.2f},0.50\n" for k, r in enumerate(ref_roll))
    )
    code, out, _ = _report(capsys, tmp_path, [dut, "--reference", str(log)])
    assert code == 2 and "needs a 'roll' or 'heel' channel" in out
    mapping = "HeelDeg=roll:deg,TrimDeg=pitch:deg"
    code, out, ev = _report(capsys, tmp_path, [dut, "--reference", str(log), "--ref-columns", mapping])
    assert code == 1, out
    jsonschema.validate(ev, load_schema())
    dyn = items(ev)["dynamic_heel"]["stats"]
    assert dyn["n"] == 240 and dyn["rmse"] == pytest.approx(0.20, abs=1e-6)
    assert ev["inputs"]["reference"]["loading"]["options"] == {"--ref-columns": mapping}
    assert "reference loaded: --ref-columns HeelDeg=roll:deg,TrimDeg=pitch:deg" in out
    # a CSV DUT with a profile of its own: the reference's --ref-columns replaces it (the profile's columns are
    # not in the ship's log); without --ref-columns the reference inherits the DUT's mapping, as before
    dut_csv = tmp_path / "dut.csv"
    dut_csv.write_text(
        "t,Krängung\n" + "".join(f"{T_2014 + k / 2:.2f},{r + 0.2:.2f}\n" for k, r in enumerate(ref_roll))
    )
    profile = tmp_path / "dut.toml"
    profile.write_text('[columns]\n"Krängung" = { to = "roll", unit = "deg" }\nt = "time"\n')
    args = [str(dut_csv), "--profile", str(profile), "--reference", str(log)]
    code, out, _ = _report(capsys, tmp_path, args)
    assert code == 2 and "column 'Krängung' named in the profile is not in the file" in out  # the log's
    code, out, ev = _report(capsys, tmp_path, [*args, "--ref-columns", mapping])
    assert code == 1, out
    assert items(ev)["dynamic_heel"]["stats"]["rmse"] == pytest.approx(0.20, abs=1e-6)
    assert ev["inputs"]["dut"]["loading"]["options"] == {"--profile": str(profile)}
    code, out, ev = _report(capsys, tmp_path, [str(dut_csv), "--profile", str(profile), "--reference", str(dut_csv)])
    assert code == 2 and "a device cannot be its own reference" in out  # the reference read with the DUT's profile
