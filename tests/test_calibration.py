"""Magnetometer calibration (sphere and swing), deviation card, calibration file: accuracy against truth."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibration import Calibration, calibrate_sphere, fit_deviation, load_calibration
from calibration.deviation import DeviationCard
from calibration.file import dumps_toml, loads_toml
from calibration.magnetometer import crosswalk, ellipsoid_fit_li, sphere_coverage
from calibration.swing import calibrate_swing, heading_from_mag, roll_pitch_from_accel
from formats.errors import ImutoolError
from formats.frames import wrap_deg180 as wrap180
from imutool.sim import simulate


def _rel_frob(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.fixture(scope="module")
def sphere():
    return simulate("mag-sphere", seed=3)


@pytest.fixture(scope="module")
def half_sphere():
    return simulate("mag-sphere", seed=4, coverage="half")


@pytest.fixture(scope="module")
def swing():
    return simulate("compass-swing", seed=5)


def _truth(rec):
    return np.array(rec.meta["mag_hard_iron_ut"]), np.array(rec.meta["mag_correction_A"])


# -- sphere -----------------------------------------------------------------------------------------------------
def test_sphere_recovers_b_and_A_at_noise_level(sphere):
    b, a = _truth(sphere)
    assert _rel_frob(a, np.eye(3)) > 0.05 and abs(a[0, 1]) > 0.01  # a non-trivial soft iron
    fit = calibrate_sphere(sphere["mag"], "full", field_ut=50.0)
    assert np.all(np.abs(fit.b - b) < 0.5)
    assert _rel_frob(fit.A, a) < 0.01
    # residual at the noise level: not larger than the residual of the true parameters
    true_res = np.linalg.norm((sphere["mag"] - b) @ a.T, axis=1) - 50.0
    assert fit.residual_rms_ut <= 1.02 * np.sqrt(np.mean(true_res**2))
    assert fit.coverage > 0.95
    # uncertainty from the Jacobian: positive, and the actual error is within a few sigma
    assert np.all(fit.b_std > 0) and np.all(np.abs(fit.b - b) < 6 * fit.b_std + 0.02)
    assert np.allclose(fit.A, fit.A.T)


def test_sphere_default_scale_is_volume_preserving(sphere):
    fit = calibrate_sphere(sphere["mag"], "full")
    _, a = _truth(sphere)
    assert np.linalg.det(fit.A) == pytest.approx(1.0, rel=1e-9)
    # same shape as the truth up to the scale
    assert _rel_frob(fit.A, a / np.cbrt(np.linalg.det(a))) < 0.01
    assert fit.field_ut == pytest.approx(50.0 / np.cbrt(np.linalg.det(a)), rel=0.01)


def test_auto_chooses_full_for_soft_iron_and_offset_for_hard_iron_only():
    fit = calibrate_sphere(simulate("mag-sphere", duration=60, seed=1)["mag"], "auto")
    assert fit.kind == "full" and "auto chose 'full'" in fit.reason
    rec = simulate("mag-sphere", duration=60, seed=1, soft_iron="1,0,0,0,1,0,0,0,1")
    fit = calibrate_sphere(rec["mag"], "auto", field_ut=50.0)
    assert fit.kind == "offset" and "offset" in fit.reason
    assert np.all(np.abs(fit.b - np.array(rec.meta["mag_hard_iron_ut"])) < 0.1)


def test_half_sphere_is_refused_with_a_coverage_message(half_sphere):
    with pytest.raises(ImutoolError, match=r"coverage 5\d% of the sphere.*below the 60% needed for a 'full' fit"):
        calibrate_sphere(half_sphere["mag"], "full")


def test_half_sphere_meets_the_looser_bound_when_allowed(half_sphere):
    b, a = _truth(half_sphere)
    fit = calibrate_sphere(half_sphere["mag"], "full", field_ut=50.0, min_coverage=0.4)
    assert any("coverage only" in w for w in fit.warnings)
    # looser stated bound for half coverage: b within 1 µT, A within 3 %
    assert np.all(np.abs(fit.b - b) < 1.0)
    assert _rel_frob(fit.A, a) < 0.03
    # auto falls back to a kind the coverage supports and says so
    auto = calibrate_sphere(half_sphere["mag"], "auto")
    assert auto.kind in ("offset", "diag") and "not allowed at this coverage" in auto.reason


def test_li_griffiths_exact_on_noise_free_ellipsoid():
    rng = np.random.default_rng(0)
    u = rng.standard_normal((500, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    a_s = np.array([[1.3, 0.2, -0.1], [0.2, 0.8, 0.15], [-0.1, 0.15, 1.1]])
    c = np.array([3.0, -7.0, 2.0])
    m = u @ a_s.T + c
    b, a, _ = ellipsoid_fit_li(m)
    assert np.allclose(b, c, atol=1e-9)
    assert np.allclose(a, np.linalg.inv(a_s), atol=1e-9)


def test_coverage_grid_is_equal_area():
    rng = np.random.default_rng(1)
    u = rng.standard_normal((20000, 3))
    assert sphere_coverage(u) == 1.0
    assert sphere_coverage(u[u[:, 2] > 0]) == pytest.approx(0.5, abs=0.01)
    assert sphere_coverage(u[u[:, 0] > 0]) == pytest.approx(0.5, abs=0.07)


def test_too_few_samples_and_flat_data_are_refused():
    with pytest.raises(ImutoolError, match="at least 20"):
        calibrate_sphere(np.ones((5, 3)), "full")
    with pytest.raises(ImutoolError, match="coverage"):
        calibrate_sphere(
            np.column_stack([np.cos(np.arange(100.0)), np.sin(np.arange(100.0)), np.zeros(100)]) * 40, "full"
        )


def test_crosswalk_forms_state_the_formula():
    b, a = np.array([1.0, 2.0, 3.0]), np.diag([1.1, 0.9, 1.0])
    assert "(D - b) * A" in crosswalk(b, a, "matlab")
    assert "S (m - h)" in crosswalk(b, a, "fusion") and "1.100000f" in crosswalk(b, a, "fusion")
    assert "Combined bias (b)" in crosswalk(b, a, "magneto")
    assert json.loads(crosswalk(b, a, "json"))["b_uT"] == [1.0, 2.0, 3.0]


# -- real data ---------------------------------------------------------------------------------------------------
def test_real_hmc5883l_full_sphere(shared):
    import formats

    m = formats.read(shared("mag_hmc5883l", "full-sphere", "hmc5883l_compass.csv")).get("mag", "uT")
    fit = calibrate_sphere(m, "auto")
    assert fit.raw_rel_std == pytest.approx(0.136, abs=0.005)
    assert fit.cal_rel_std <= 0.006
    assert fit.kind == "full"


def test_real_hmc5883l_ccw_turns_with_the_sphere_calibration(shared, tmp_path):
    from scipy.ndimage import median_filter

    import formats

    m = formats.read(shared("mag_hmc5883l", "full-sphere", "hmc5883l_compass.csv")).get("mag", "uT")
    fit = calibrate_sphere(m, "auto")
    cal = Calibration()
    cal.set_section("mag", fit.to_section())
    cal.save(tmp_path / "cal.toml")
    rec = formats.read(shared("mag_hmc5883l", "rotate-ccw-around-z-pointing-up", "hmc5883l_compass.csv"))
    corrected = load_calibration(tmp_path / "cal.toml").apply(rec)
    assert "mag hard/soft iron (full)" in corrected.meta["calibration"]["applied"][0]

    def sweep_and_backtrack(mag):
        # sensor axes x forward, y left, z up (upstream README): heading angle of the field, unwrapped (deg)
        h = np.degrees(np.unwrap(np.arctan2(mag[:, 1], mag[:, 0])))
        hs = median_filter(h, 38, mode="nearest")  # 0.5 s at 77 Hz
        return h[-1] - h[0], float(np.max(hs - np.minimum.accumulate(hs)))  # CCW: heading decreases

    sweep_cal, back_cal = sweep_and_backtrack(corrected["mag"])
    sweep_raw, back_raw = sweep_and_backtrack(rec["mag"])
    # two CCW turns: the calibrated heading sweeps 2 × 360° within 10°, the raw one loses a turn
    assert abs(sweep_cal + 720.0) <= 10.0
    assert abs(sweep_raw + 720.0) > 10.0
    # monotonic apart from noise and hand wobble (≤ 12° back-steps vs > 100° raw, where the heading wraps back)
    assert back_cal <= 12.0 and back_raw > 100.0


# -- swing and deviation ----------------------------------------------------------------------------------------
def test_swing_recovers_horizontal_hard_and_soft_iron(swing):
    b, a = _truth(swing)
    fit = calibrate_swing(swing["mag"], swing["accel"], horizontal_ut=25.0)
    assert np.all(np.abs(fit.b[:2] - b[:2]) < 0.3)
    assert _rel_frob(fit.A[:2, :2], a[:2, :2]) < 0.01
    assert "bz" in fit.extra["section"]["unobservable"]
    r, p = roll_pitch_from_accel(swing["accel"])
    err = wrap180(heading_from_mag(fit.apply(swing["mag"]), r, p) - swing["ref_compass_heading"])
    assert np.sqrt(np.mean(err**2)) < 0.5


def test_swing_refuses_a_partial_turn(swing):
    part = swing.select(swing["ref_compass_heading"] < 180)
    with pytest.raises(ImutoolError, match="covers only"):
        calibrate_swing(part["mag"], part["accel"])


def test_deviation_card_recovered_from_a_swing(swing):
    truth = np.array(swing.meta["deviation_deg"])
    fit = calibrate_swing(swing["mag"], swing["accel"])
    r, p = roll_pitch_from_accel(swing["accel"])
    compass = heading_from_mag(fit.apply(swing["mag"]), r, p)
    card = fit_deviation(compass, swing["ref_heading"] - swing.meta["variation_deg"])
    assert np.all(np.abs(card.coefficients - truth) < 0.2)
    err = wrap180(card.correct(compass) - swing["ref_heading"])
    assert np.sqrt(np.mean(err**2)) <= 0.5
    raw_err = wrap180(compass - swing["ref_heading"])
    assert np.sqrt(np.mean(raw_err**2)) > 2.0  # the deviation was worth correcting
    assert all(v > 0 for v in card.std.values())


def test_deviation_refuses_partial_circle_and_card_table():
    psi = np.linspace(0, 180, 200)
    with pytest.raises(ImutoolError, match="cover only"):
        fit_deviation(psi, psi + 1.0)
    card = DeviationCard(1.0, 2.0, 0.0, 0.0, 0.0)
    tab = card.table(15.0)
    assert len(tab) == 24 and tab[6][0] == 90.0 and tab[6][1] == pytest.approx(3.0)
    assert DeviationCard(1.0).correct(np.array([359.5]))[0] == pytest.approx(0.5)  # wraps into [0, 360)


# -- calibration file --------------------------------------------------------------------------------------------
def test_toml_writer_round_trip():
    data = {
        "top": 1,
        "mag": {
            "b": [1.5, -2.25e-7, 3.0],
            "A": [[1.0, 0.1], [0.1, 1.0]],
            "kind": 'f"ull\\',
            "provenance": {"input": "a b.csv", "fit": {"n": 3, "ok": True}},
        },
    }
    back = loads_toml(dumps_toml(data))
    assert back == data


def test_calibration_file_apply_all_sections(tmp_path, sphere):
    fit = calibrate_sphere(sphere["mag"], "full", field_ut=50.0)
    cal = Calibration()
    cal.set_section("mag", fit.to_section())
    cal.set_section("gyro", {"bias": [0.01, -0.02, 0.03], "temp_slope": [0.001, 0.0, 0.0], "temp_ref": 20.0})
    cal.set_section("accel", {"bias": [0.1, 0.0, -0.1], "T": np.diag([1.01, 0.99, 1.0]).tolist()})
    cal.set_section("deviation", DeviationCard(0.5, 1.0, -1.0, 0.2, 0.1).to_section())
    cal.set_section("mounting", {"remap": "x,y,z", "misalignment_deg": [0.0, 0.0, 0.0]})
    path = tmp_path / "cal.toml"
    cal.save(path)
    back = load_calibration(path)
    rec = sphere.copy()
    rec.add("temp", np.full(len(rec), 25.0))
    out = back.apply(rec)
    assert np.array_equal(out["mag"], fit.apply(sphere["mag"]))  # bit-exact through TOML
    want = sphere["gyro"] - [0.01, -0.02, 0.03] - np.array([0.001, 0, 0]) * 5.0
    assert np.allclose(out["gyro"], want, atol=1e-15)
    assert np.allclose(out["accel"], (sphere["accel"] - [0.1, 0, -0.1]) * [1.01, 0.99, 1.0])
    assert back.deviation.deviation_deg(np.array([90.0]))[0] == pytest.approx(0.5 + 1.0 - 0.1)
    applied = " ".join(out.meta["calibration"]["applied"])
    assert "gyro bias+temperature slope" in applied and "accel" in applied and "mounting" in applied


def test_calibration_file_errors(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("[mag]\nb = [1, 2]\nA = [[1,0,0],[0,1,0],[0,0,1]]\n")
    with pytest.raises(ImutoolError, match=r"mag.b: shape \(2,\)"):
        load_calibration(p)
    p.write_text("not toml [")
    with pytest.raises(ImutoolError, match="not a valid TOML"):
        load_calibration(p)
    p.write_text("x = 1\n")
    with pytest.raises(ImutoolError, match="no calibration sections"):
        load_calibration(p)
    with pytest.raises(ImutoolError, match="no such calibration file"):
        load_calibration(tmp_path / "missing.toml")
