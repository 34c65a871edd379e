"""Calibrations refused when the data cannot determine them, and calibration files no real sensor has."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import run_main as run

import formats
from calibration import calibrate_sphere, load_calibration
from calibration.magnetometer import check_soft_iron, field_direction_coverage, sphere_fit_linear
from formats.errors import ImutoolError
from imutool.sim import simulate


@pytest.fixture(scope="module")
def static():
    return simulate("static", duration=60, seed=3)


def test_motionless_recording_is_refused_not_100_percent(static, tmp_path, capsys):
    m = static["mag"]
    c, r = sphere_fit_linear(m)  # a sphere fitted to the noise cloud: the old measure said 100 %
    assert field_direction_coverage(m, c, np.eye(3) / r, 1.0) < 0.05
    for kind in ("auto", "offset", "full"):
        with pytest.raises(ImutoolError, match=r"coverage \d% of the sphere.*rotate the sensor"):
            calibrate_sphere(m, kind)
    p = tmp_path / "static.csv"
    formats.write(static, p)
    out = tmp_path / "cal.toml"
    code, so, err = run(["calibrate", "mag", p, "-o", out], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "rotate the sensor" in err
    assert not out.exists()


def test_full_sphere_simulation_still_covers_everything():
    m = simulate("mag-sphere", duration=60, seed=1)["mag"]
    fit = calibrate_sphere(m, "auto")
    assert fit.coverage > 0.9 and 45 < fit.field_ut < 55


def test_real_static_hmc5883l_is_refused(shared):
    m = formats.read(shared("mag_hmc5883l", "unmoved-with-x-pointing-forward-10min", "hmc5883l_compass.csv")).get(
        "mag", "uT"
    )
    with pytest.raises(ImutoolError, match=r"coverage \d% of the sphere"):
        calibrate_sphere(m, "auto")
    with pytest.raises(ImutoolError, match="coverage"):
        calibrate_sphere(m, "full", field_ut=50.0)


def test_real_full_sphere_hmc5883l_is_accepted(shared):
    m = formats.read(shared("mag_hmc5883l", "full-sphere", "hmc5883l_compass.csv")).get("mag", "uT")
    fit = calibrate_sphere(m, "auto")
    assert fit.coverage >= 0.6 and 45 < fit.field_ut < 60 and fit.cal_rel_std < 0.01


def test_flat_heading_turn_is_refused_for_a_sphere_fit(shared):
    m = formats.read(shared("mag_hmc5883l", "rotate-ccw-around-z-pointing-up", "hmc5883l_compass.csv")).get("mag", "uT")
    with pytest.raises(ImutoolError, match="--method swing"):
        calibrate_sphere(m, "auto")


def test_check_soft_iron():
    b = np.zeros(3)
    assert check_soft_iron(b, np.eye(3)) is None
    assert "positive-definite" in check_soft_iron(b, np.zeros((3, 3)))
    assert "rank 1" in check_soft_iron(b, np.ones((3, 3)))
    assert "badly conditioned" in check_soft_iron(b, np.diag([1.0, 1.0, 10.0]))
    assert "not finite" in check_soft_iron(np.array([np.nan, 0, 0]), np.eye(3))


GOOD_MAG = "[mag]\nb = [1.0, 2.0, 3.0]\nA = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\n"
BAD = {
    "zero_A": (
        "[mag]\nb = [1.0, 2.0, 3.0]\nA = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]\n",
        r"\[mag\] A .*singular \(rank 0\)",
    ),
    "rank1_A": (
        "[mag]\nb = [1.0, 2.0, 3.0]\nA = [[1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0]]\n",
        r"\[mag\] A .*rank 1",
    ),
    "ill_A": (
        "[mag]\nb = [1.0, 2.0, 3.0]\nA = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 20.0]]\n",
        r"\[mag\] A .*badly conditioned",
    ),
    "mirror_A": (
        "[mag]\nb = [1.0, 2.0, 3.0]\nA = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]\n",
        "negative determinant",
    ),
    "nan_b": (GOOD_MAG.replace("1.0, 2.0, 3.0", "nan, 2.0, 3.0"), r"mag\.b: non-finite"),
    "inf_b": (GOOD_MAG.replace("1.0, 2.0, 3.0", "inf, 2.0, 3.0"), r"mag\.b: non-finite"),
    "neg_field": (GOOD_MAG + "field_ut = -50.0\n", r"\[mag\] field_ut = -50.0"),
    "nan_field": (GOOD_MAG + "field_ut = nan\n", r"\[mag\] field_ut is not finite"),
    "version": ("imutool_calibration = 7\n" + GOOD_MAG, "unknown calibration file version"),
    "version2": ("version = 99\n" + GOOD_MAG, "unknown calibration file version"),
    "unknown_section": (GOOD_MAG + "[magnetometer]\nb = [0, 0, 0]\n", r"unknown section \[magnetometer\]"),
    "dev_list": ("[deviation]\nA = 0.5\nB = [1, 2]\n", r"\[deviation\] B must be a number"),
    "dev_text": ('[deviation]\nA = "x"\n', r"\[deviation\] A must be a number"),
    "dev_nan": ("[deviation]\nA = nan\n", r"\[deviation\] A is not finite"),
    "dev_huge": ("[deviation]\nB = -176.0\n", r"\[deviation\] B = -176.0° is beyond"),
    "gyro_nan": ("[gyro]\nbias = [nan, 0.0, 0.0]\n", r"gyro\.bias: non-finite"),
    "gyro_dps": ("[gyro]\nbias = [5.0, 0.0, 0.0]\n", r"\[gyro\] bias .*deg/s written as rad/s"),
    "gyro_scale0": (
        "[gyro]\nbias = [0.0, 0.0, 0.0]\nscale = [[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\n",
        r"\[gyro\] scale is singular",
    ),
    "accel_T": (
        "[accel]\nbias = [0.0, 0.0, 0.0]\nT = [[3.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 3.0]]\n",
        r"\[accel\] T scales by 3…3",
    ),
    "mount": ('[mounting]\nremap = "x,x,z"\n', r"\[mounting\] remap"),
    "mount_mis": ('[mounting]\nremap = "x,y,z"\nmisalignment_deg = [0.0, 90.0, 0.0]\n', r"\[mounting\] misalignment"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_calibration_file_refused_on_load(case, tmp_path):
    text, pattern = BAD[case]
    p = tmp_path / f"{case}.toml"
    p.write_text(text)
    with pytest.raises(ImutoolError, match=pattern) as e:
        load_calibration(p)
    assert str(e.value).startswith(str(p)) and "\n" not in str(e.value)


@pytest.mark.parametrize("case", ["zero_A", "nan_b", "version", "dev_list", "neg_field"])
def test_bad_calibration_refused_by_filter_and_append(case, tmp_path, capsys):
    text, _ = BAD[case]
    cal = tmp_path / "cal.toml"
    cal.write_text(text)
    rec = simulate("ship-roll", duration=10, seed=1)
    p = tmp_path / "roll.csv"
    formats.write(rec, p)
    code, out, err = run(["filter", p, "-o", tmp_path / "o.csv", "--calibration", cal, "-q"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and str(cal) in err
    assert not (tmp_path / "o.csv").exists()
    code, out, err = run(["calibrate", "gyro", p, "-o", cal, "--append"], capsys)
    assert code == 2 and cal.read_text() == text  # not rewritten


def test_heading_swing_coverage_counts_field_headings_not_noise(static, shared):
    from calibration.swing import calibrate_swing

    with pytest.raises(ImutoolError, match=r"covers only \d+°"):
        calibrate_swing(static["mag"], static["accel"])
    swing = simulate("compass-swing", duration=200, rate_hz=5, seed=9)
    assert calibrate_swing(swing["mag"], swing["accel"]).coverage > 0.95
    d = ("mag_hmc5883l", "unmoved-with-x-pointing-forward-10min", "hmc5883l_compass.csv")
    with pytest.raises(ImutoolError, match="turn the vessel through a full circle"):
        calibrate_swing(formats.read(shared(*d)).get("mag", "uT"), None)
    turn = formats.read(shared("mag_hmc5883l", "rotate-ccw-around-z-pointing-up", "hmc5883l_compass.csv"))
    assert calibrate_swing(turn.get("mag", "uT"), None).coverage > 0.9


def test_impossible_field_strengths_refused_before_fitting():
    from calibration.swing import calibrate_swing

    m = simulate("mag-sphere", duration=20, seed=2)["mag"]
    for bad in (-50.0, 0.0, float("nan"), float("inf")):
        with pytest.raises(ImutoolError, match="must be a positive number"):
            calibrate_sphere(m, "auto", field_ut=bad)
        with pytest.raises(ImutoolError, match="must be a positive number"):
            calibrate_swing(m, None, horizontal_ut=bad)
