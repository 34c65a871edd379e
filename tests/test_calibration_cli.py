"""The `imutool calibrate` command line: files written, summaries, refusals as one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_main as run

import formats
from calibration import load_calibration
from imutool.sim import simulate


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cal")
    formats.write(simulate("mag-sphere", duration=60, seed=7), d / "sphere.csv")
    formats.write(simulate("mag-sphere", duration=60, seed=8, coverage="half"), d / "half.csv")
    formats.write(simulate("compass-swing", duration=200, rate_hz=5, seed=9), d / "swing.csv")
    return d


def test_mag_sphere_then_show_in_every_form(files, tmp_path, capsys):
    cal, png = tmp_path / "cal.toml", tmp_path / "cal.png"
    code, out, err = run(["calibrate", "mag", files / "sphere.csv", "-o", cal, "--plot", png, "--json"], capsys)
    assert code == 0, err
    s = json.loads(out)
    truth = formats.read(files / "sphere.csv").meta
    assert s["kind"] == "full" and np.allclose(s["b_uT"], truth["mag_hard_iron_ut"], atol=0.5)
    assert png.stat().st_size > 20_000
    c = load_calibration(cal)
    prov = c.sections["mag"]["provenance"]
    assert len(prov["input_sha256"]) == 64 and prov["date_utc"].endswith("Z") and prov["fit"]["coverage"] > 0.9
    for form, needle in (
        ("matlab", "(D - b) * A"),
        ("fusion", "softIronMatrix"),
        ("magneto", "Combined bias"),
        ("text", "m_true = A (m_meas - b)"),
    ):
        code, out, _ = run(["calibrate", "show", cal, "--as", form], capsys)
        assert code == 0 and needle in out
    code, out, _ = run(["calibrate", "show", cal, "--as", "json"], capsys)
    assert np.allclose(json.loads(out)["mag"]["A"], c.sections["mag"]["A"])


def test_half_sphere_refused_in_one_line(files, tmp_path, capsys):
    code, out, err = run(["calibrate", "mag", files / "half.csv", "-o", tmp_path / "c.toml", "--kind", "full"], capsys)
    assert code == 2 and "coverage" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "c.toml").exists()
    code, out, err = run(
        [
            "calibrate",
            "mag",
            files / "half.csv",
            "-o",
            tmp_path / "c.toml",
            "--kind",
            "full",
            "--min-coverage",
            "0.4",
            "--field",
            "50",
        ],
        capsys,
    )
    assert code == 0 and "warning: coverage only" in out


def test_swing_then_deviation_card_with_calibration_applied(files, tmp_path, capsys):
    cal = tmp_path / "cal.toml"
    code, out, err = run(["calibrate", "mag", files / "swing.csv", "-o", cal, "--method", "swing"], capsys)
    assert code == 0, err
    assert "not observable in a swing" in out
    card = tmp_path / "card.pdf"
    code, out, err = run(
        ["calibrate", "deviation", files / "swing.csv", "--calibration", cal, "-o", card, "-o", cal, "--json"], capsys
    )
    assert code == 0, err
    s = json.loads(out)
    truth = formats.read(files / "swing.csv").meta["deviation_deg"]
    assert np.allclose([s["coefficients_deg"][n] for n in "ABCDE"], truth, atol=0.3)
    assert card.read_bytes()[:4] == b"%PDF"
    c = load_calibration(cal)
    assert set(c.sections) == {"mag", "deviation"}  # appended next to the mag section
    assert c.deviation.coefficients == pytest.approx([s["coefficients_deg"][n] for n in "ABCDE"], abs=1e-4)


def test_deviation_from_a_separate_bearings_csv(files, tmp_path, capsys):
    rec = formats.read(files / "swing.csv")
    ref = formats.Recording(rec.time[::50].copy())
    ref.add("bearing", rec["ref_heading"][::50], "deg")
    formats.write(ref, tmp_path / "bearings.csv")
    code, out, err = run(
        [
            "calibrate",
            "deviation",
            files / "swing.csv",
            "--heading-column",
            "ref_compass_heading",
            "--reference",
            tmp_path / "bearings.csv",
            "-o",
            tmp_path / "card.png",
            "--json",
            "--variation",
            "0",
        ],
        capsys,
    )  # a true reference needs the variation (simulated: 0)
    assert code == 0, err
    s = json.loads(out)
    assert "bearing" in s["reference"]
    assert np.allclose([s["coefficients_deg"][n] for n in "ABCDE"], rec.meta["deviation_deg"], atol=0.05)


def test_deviation_from_bearings_without_a_clock(files, tmp_path, capsys):
    """A hand-written bearings log (one every 10 s, no time column): --ref-rate and --ref-start give it its times."""
    rec = formats.read(files / "swing.csv")
    (tmp_path / "bearings.csv").write_text("bearing\n" + "".join(f"{b:.3f}\n" for b in rec["ref_heading"][::50]))
    args = ["calibrate", "deviation", files / "swing.csv", "--heading-column", "ref_compass_heading"]
    args += ["--reference", tmp_path / "bearings.csv", "-o", tmp_path / "card.txt", "--json", "--variation", "0"]
    code, out, err = run([*args, "--ref-rate", "0.1", "--ref-start", f"{rec.time[0]:.3f}"], capsys)
    assert code == 0, err
    s = json.loads(out)
    assert np.allclose([s["coefficients_deg"][n] for n in "ABCDE"], rec.meta["deviation_deg"], atol=0.05)
    assert s["reference_loading"]["options"] == {"--ref-rate": 0.1, "--ref-start": float(f"{rec.time[0]:.3f}")}
    assert "time from --ref-rate 0.1 Hz" in s["reference_loading"]["time"]
    code, out, err = run([*args[:5], "-o", tmp_path / "c.txt", "--ref-rate", "0.1"], capsys)
    assert code == 2 and "--ref-rate: say how to read a reference file; give the file with --reference" in err


def test_gyro_and_accel_append_sections(files, tmp_path, capsys):
    cal = tmp_path / "cal.toml"
    from imutool.sim.sensor import imu_recording

    t = np.arange(0, 30, 0.01)
    q = np.tile([1.0, 0, 0, 0], (len(t), 1))
    rec = imu_recording(t, q, np.zeros((len(t), 3)), np.random.default_rng(0), mag_errors=None)
    formats.write(rec, tmp_path / "static.csv")
    code, out, err = run(["calibrate", "gyro", tmp_path / "static.csv", "-o", cal, "--json"], capsys)
    assert code == 0, err
    assert np.allclose(json.loads(out)["bias_rad_s"], rec["ref_gyro_bias"].mean(axis=0), atol=2e-4)
    code, out, err = run(["calibrate", "accel", tmp_path / "static.csv", "-o", cal, "--append"], capsys)
    assert code == 2 and "static poses" in err  # one pose is not a six-position calibration
    code, out, err = run(["calibrate", "mag", files / "sphere.csv", "-o", cal, "--append"], capsys)
    assert code == 0
    assert set(load_calibration(cal).sections) == {"gyro", "mag"}
    code, out, err = run(["calibrate", "gyro", tmp_path / "static.csv", "-o", tmp_path / "x.json"], capsys)
    assert code == 2 and ".toml" in err


def test_deviation_against_an_nmea_gyrocompass_log(tmp_path, capsys):
    rec = simulate("compass-swing", duration=120, rate_hz=10, seed=12)
    formats.write(rec, tmp_path / "swing.csv")
    ref = formats.Recording(rec.time.copy())
    ref.add("heading", rec["ref_heading"], "deg")
    formats.write(ref, tmp_path / "gyro.nmea")  # $HEHDT at 10 Hz (read back on the sentence-index clock)
    code, out, err = run(
        [
            "calibrate",
            "deviation",
            tmp_path / "swing.csv",
            "--heading-column",
            "ref_compass_heading",
            "--reference",
            tmp_path / "gyro.nmea",
            "-o",
            tmp_path / "c.toml",
            "--json",
            "--variation",
            "0",
        ],
        capsys,
    )  # true reference: variation required
    assert code == 0, err
    s = json.loads(out)
    assert "gyro.nmea:heading (true)" in s["reference"]
    assert np.allclose([s["coefficients_deg"][n] for n in "ABCDE"], rec.meta["deviation_deg"], atol=0.1)


def test_fitting_refuses_mounting_and_an_already_applied_section(files, tmp_path, capsys):
    cal = tmp_path / "cal.toml"
    code, _, err = run(["calibrate", "mag", files / "sphere.csv", "-o", cal, "--mounting", "x,-y,-z"], capsys)
    assert code == 2 and "sensor axes" in err
    assert run(["calibrate", "mag", files / "sphere.csv", "-o", cal], capsys)[0] == 0
    code, _, err = run(
        ["calibrate", "mag", files / "sphere.csv", "-o", tmp_path / "c2.toml", "--calibration", cal], capsys
    )
    assert code == 2 and "already has a [mag] section" in err
