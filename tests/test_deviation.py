"""Deviation card: a true reference needs the variation (given, or from the World Magnetic Model checked against
NOAA's published WMM2025 test values); E/W card text with both tables (magnetic → compass solved), residuals,
limits and warnings; narrow swings refused; an absurd card from a mismatched calibration flagged."""

from __future__ import annotations

import json
from datetime import date

import numpy as np
import pytest
from click.testing import CliRunner

import formats
from calibration.deviation import DeviationCard, card_text, ew, fit_deviation
from calibration.file import update_calibration
from imutool.cli import cli
from imutool.sim import simulate

TRUTH = [1.5, 3.0, -2.0, 0.8, -0.6]  # the simulator's default card


def run(args):
    r = CliRunner().invoke(cli, [str(a) for a in args])
    err = "" if r.exception is None or isinstance(r.exception, SystemExit) else str(r.exception)
    return r.exit_code, r.stdout, err


@pytest.fixture(scope="module")
def swing(tmp_path_factory):
    """A simulated swing with −3.5° variation and a gyro (true heading) reference in its own CSV."""
    d = tmp_path_factory.mktemp("swing")
    rec = simulate("compass-swing", duration=150, rate_hz=5, seed=3, variation_deg=-3.5)
    formats.write(rec, d / "swing.csv")
    ref = formats.Recording(rec.time.copy())
    ref.add("heading", rec["ref_heading"], "deg")
    formats.write(ref, d / "gyro.csv")
    return d


def test_true_reference_without_variation_is_refused(swing, tmp_path):
    code, out, err = run(
        [
            "calibrate",
            "deviation",
            swing / "swing.csv",
            "--heading-column",
            "ref_compass_heading",
            "--reference",
            swing / "gyro.csv",
            "-o",
            tmp_path / "c.toml",
        ]
    )
    assert code != 0 and "TRUE heading" in err and "--variation" in err
    assert not (tmp_path / "c.toml").exists()
    # with the variation the card is right (the case: A came out −2.0° instead of +1.5°)
    code, out, err = run(
        [
            "calibrate",
            "deviation",
            swing / "swing.csv",
            "--heading-column",
            "ref_compass_heading",
            "--reference",
            swing / "gyro.csv",
            "-o",
            tmp_path / "c.toml",
            "--variation",
            "-3.5",
            "--json",
        ]
    )
    assert code == 0, err
    s = json.loads(out)
    assert np.allclose([s["coefficients_deg"][n] for n in "ABCDE"], TRUTH, atol=0.02)


# NOAA WMM2025 report test values (height 0): decimal year, lat, lon, declination (deg, published to 0.01)
WMM2025_TEST = [
    (2025.0, 80.0, 0.0, 1.28),
    (2025.0, 0.0, 120.0, -0.16),
    (2025.0, -80.0, 240.0, 68.78),
    (2027.5, 80.0, 0.0, 2.59),
    (2027.5, 0.0, 120.0, -0.24),
    (2027.5, -80.0, 240.0, 68.49),
]


def test_wmm_declination_matches_the_published_test_values():
    pytest.importorskip("pygeomag", reason="optional extra imutool[wmm] not installed")
    from calibration.wmm import wmm_variation

    for y, lat, lon, d in WMM2025_TEST:
        v = wmm_variation(lat, lon, y)
        assert v.model == "WMM-2025"
        assert abs(v.deg - d) <= 0.0051, (y, lat, lon, v.deg, d)
    with pytest.raises(formats.ImutoolError, match="no World Magnetic Model"):
        wmm_variation(59.0, 24.0, 2031.0)


def test_true_reference_corrected_from_the_wmm(tmp_path):
    pytest.importorskip("pygeomag", reason="optional extra imutool[wmm] not installed")
    from calibration.wmm import wmm_variation

    lat, lon, day = 59.44, 24.75, date(2026, 6, 1)
    var = wmm_variation(lat, lon, day).deg  # simulate the swing where the model says the variation is
    rec = simulate("compass-swing", duration=150, rate_hz=5, seed=4, variation_deg=var)
    formats.write(rec, tmp_path / "swing.csv")
    ref = formats.Recording(rec.time.copy())
    ref.add("heading", rec["ref_heading"], "deg")
    formats.write(ref, tmp_path / "gyro.csv")
    code, out, err = run(
        [
            "calibrate",
            "deviation",
            tmp_path / "swing.csv",
            "--heading-column",
            "ref_compass_heading",
            "--reference",
            tmp_path / "gyro.csv",
            "-o",
            tmp_path / "card.txt",
            "-o",
            tmp_path / "c.toml",
            "--position",
            f"{lat},{lon}",
            "--date",
            day.isoformat(),
            "--vessel",
            "MV Aurora",
            "--place",
            "Tallinn roads",
            "--json",
        ]
    )
    assert code == 0, err
    s = json.loads(out)
    assert s["variation_deg"] == pytest.approx(var) and "WMM-2025" in s["variation_source"]
    assert np.allclose([s["coefficients_deg"][n] for n in "ABCDE"], TRUTH, atol=0.02)
    txt = (tmp_path / "card.txt").read_text()
    assert "MV Aurora" in txt and "Tallinn roads" in txt and "59.440° N" in txt and "2026-06-01" in txt
    assert f"{ew(var)} (WMM-2025" in txt and "Signature" in txt
    from calibration.file import load_calibration  # the card's header lives in the calibration file too

    card = load_calibration(tmp_path / "c.toml").deviation
    assert card.header["vessel"] == "MV Aurora" and card.header["latitude"] == pytest.approx(lat)


def test_card_tables_and_ew_text():
    card = DeviationCard(1.5, 3.0, -2.0, 0.8, -0.6)
    assert ew(3.04) == "3.0° E" and ew(-1.46) == "1.5° W" and ew(0.01) == "0.0°" and ew(None) == "—"
    comp = card.table(15.0)
    mag = card.table_magnetic(15.0)
    assert len(comp) == len(mag) == 24
    for m, d, p in mag:  # steering the compass course p gives the magnetic course m
        assert abs(((p + float(card.deviation_deg(p)) - m + 180) % 360) - 180) < 1e-9
        assert d == pytest.approx(float(card.deviation_deg(p)))
    for p, d, m in comp:
        assert m == pytest.approx((p + d) % 360.0)
    txt = card_text(card, {"vessel": "MV Test", "latitude": -33.9, "variation": 12.8, "compass": "Plath 2060"})
    assert "COMPASS → MAGNETIC" in txt and "MAGNETIC → COMPASS (course to steer)" in txt
    assert "33.900° S" in txt and "12.8° E" in txt and "Plath 2060" in txt
    assert "A = 1.50° E" in txt and "B = 3.00° E" in txt and "C = 2.00° W" in txt
    row000 = next(ln for ln in txt.splitlines() if ln.strip().startswith("0°"))
    assert row000.split()[1:3] == ["1.1°", "W"]  # δ(000) = A + C + E = 1.5 − 2.0 − 0.6 = −1.1° (W)
    assert "Adjusted / swung by:" in txt


def test_residuals_and_warnings():
    psi = np.linspace(0, 360, 2000, endpoint=False)
    card = DeviationCard(*TRUTH)
    ok = fit_deviation(psi, psi + card.deviation_deg(psi))
    assert len(ok.quality["residuals_15deg"]) == 24 and ok.quality["residual_rms_deg"] < 1e-9
    assert any("should be adjusted" in w for w in ok.warnings)  # |δ| reaches 5.1° > 5°
    small = fit_deviation(psi, psi + 0.5 * card.deviation_deg(psi))
    assert small.warnings == []
    # a local disturbance the five-term model cannot follow
    bump = 3.0 * np.exp(-0.5 * ((psi - 90.0) / 6.0) ** 2)
    bad = fit_deviation(psi, psi + 0.5 * card.deviation_deg(psi) + bump)
    assert any("does not fit" in w and "090°" in w for w in bad.warnings)
    # an absurd card (±56°, what a mismatched calibration gave)
    absurd = fit_deviation(psi, psi + 56.0 * np.sin(np.radians(psi)) * 0.9)
    assert any(w.startswith("absurd card") for w in absurd.warnings)


def test_narrow_span_is_refused_whatever_min_span_says():
    psi = np.linspace(0, 120, 500)
    with pytest.raises(formats.ImutoolError, match="cover only"):
        fit_deviation(psi, psi + 1.0)
    with pytest.raises(formats.ImutoolError, match="too narrow"):
        fit_deviation(psi, psi + 1.0, min_span_deg=0.0)  # the B = −76° case
    psi = np.linspace(0, 300, 500)
    card = fit_deviation(psi, psi + DeviationCard(*TRUTH).deviation_deg(psi), min_span_deg=0.0)
    assert np.allclose(card.coefficients, TRUTH, atol=1e-6)


def test_mismatched_calibration_gives_a_flagged_absurd_card(swing, tmp_path):
    cal = tmp_path / "wrong.toml"  # a hard iron that is not this sensor's (near the 25 µT horizontal field)
    update_calibration(
        str(cal),
        "mag",
        {"model": "m_true = A (m_meas - b)", "A": np.eye(3).tolist(), "b": [20.0, 0.0, 0.0], "field_ut": 50.0},
        False,
    )
    r = CliRunner().invoke(
        cli,
        [
            "calibrate",
            "deviation",
            str(swing / "swing.csv"),
            "--calibration",
            str(cal),
            "-o",
            str(tmp_path / "c.txt"),
            "--json",
        ],
    )
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    assert s["max_abs_deviation_deg"] > 20.0
    assert any(w.startswith("absurd card") for w in s["warnings"]) and "absurd card" in r.stderr
    assert "WARNING: absurd card" in (tmp_path / "c.txt").read_text()


def test_position_and_date_from_an_nmea_reference_log(tmp_path):
    from calibration.wmm import parse_position, position_from_nmea

    log = tmp_path / "gyro.nmea"
    log.write_text(
        "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n"
        "$HEHDT,84.4,T*17\r\n"
        "$GPRMC,123520,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*60\r\n"
    )
    lat, lon, day = position_from_nmea(str(log))
    assert lat == pytest.approx(48.1173, abs=1e-4) and lon == pytest.approx(11.5167, abs=1e-4)
    assert day == date(1994, 3, 23)
    void = tmp_path / "void.nmea"  # status V and fix 0: no position
    void.write_text(
        "$GPRMC,123520,V,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*77\r\n"
        "$GPGGA,123519,4807.038,N,01131.000,E,0,08,0.9,545.4,M,46.9,M,,*46\r\n"
    )
    assert position_from_nmea(str(void))[:2] == (None, None)
    assert parse_position("-33.87,151.21") == (-33.87, 151.21)
    with pytest.raises(formats.ImutoolError, match="latitude"):
        parse_position("95,10")
