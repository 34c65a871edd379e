"""Allan deviation: noise terms against known densities, the noise/kalibr files, the CLI on real data."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.allan import allan_deviation, analyse
from calibration.noise import load_noise, write_kalibr, write_noise
from formats.errors import ImutoolError


def _white_plus_rw(n_density, k_rw, fs, hours, seed):
    rng = np.random.default_rng(seed)
    n = int(hours * 3600 * fs)
    white = rng.standard_normal((n, 3)) * n_density * np.sqrt(fs)
    walk = np.cumsum(rng.standard_normal((n, 3)) * k_rw / np.sqrt(fs), axis=0)
    return white + walk


def test_arw_and_rrw_recovered_within_10_percent():
    n_d, k_rw, fs = 0.01, 0.01, 20.0  # rad/s/√Hz, rad/s/√s
    res = analyse(_white_plus_rw(n_d, k_rw, fs, 4.0, seed=11), fs, "gyro", "rad/s")
    for t in res.terms:
        assert t["N"] == pytest.approx(n_d, rel=0.10)
        assert t["K"] == pytest.approx(k_rw, rel=0.10)


def test_white_noise_allan_matches_theory_and_bias_instability_factor():
    fs = 100.0
    rng = np.random.default_rng(2)
    y = rng.standard_normal(200_000) * 0.02 * np.sqrt(fs)
    taus, adev, n_eff = allan_deviation(y, fs)
    # white noise: σ(τ) = N / √τ at every τ with enough clusters
    good = n_eff > 100
    assert np.allclose(adev[good], 0.02 / np.sqrt(taus[good]), rtol=0.1)
    res = analyse(y, fs, "gyro", "rad/s")
    t = res.terms[0]
    assert t["B"] == pytest.approx(t["adev_min"] / 0.6643, rel=1e-6)
    assert t["B_upper_bound"]  # pure white noise: the minimum is at the longest τ


def test_overlapping_estimator_matches_direct_formula():
    rng = np.random.default_rng(3)
    y = rng.standard_normal(2000)
    fs = 10.0
    m = np.array([1, 3, 7, 20, 40, 128])
    taus, adev, _ = allan_deviation(y, fs, m=m)
    assert np.allclose(taus * fs, m)  # these sizes are multiples of their sub-sampling step already
    theta = np.concatenate([[0.0], np.cumsum(y - y.mean()) / fs])
    for i, mm in enumerate(m):  # every k for m < 16 (exact); every s-th k beyond (s = 2, 4, 16 here)
        s = 1 if mm < 16 else 2 ** int(np.floor(np.log2(mm // 8)))
        d = (theta[2 * mm:] - 2 * theta[mm:-mm] + theta[:-2 * mm])[::s]
        assert adev[i] == pytest.approx(np.sqrt(np.mean(d ** 2) / (2 * (mm / fs) ** 2)), rel=1e-10)


def test_allan_refuses_nan_and_short_input():
    with pytest.raises(ImutoolError, match="NaN"):
        allan_deviation(np.array([1.0, np.nan] * 20), 10.0)
    with pytest.raises(ImutoolError, match="at least 20"):
        allan_deviation(np.ones(5), 10.0)


def test_noise_yaml_and_kalibr_round_trip(tmp_path):
    vals = {"gyro_noise_density": 1.5e-4, "gyro_bias_instability": 3e-5, "gyro_random_walk": 2e-6,
            "gyro_noise_density_xyz": [1e-4, 2e-4, 1.5e-4], "accel_noise_density": 2e-3, "rate_hz": 100.0,
            "source": 'a "quoted" #name.csv'}
    write_noise(tmp_path / "noise.yaml", vals)
    back = load_noise(tmp_path / "noise.yaml")
    assert back == vals
    write_kalibr(tmp_path / "imu.yaml", vals)
    text = (tmp_path / "imu.yaml").read_text()
    for key in ("gyroscope_noise_density: 0.00015", "gyroscope_random_walk: 2e-06", "update_rate: 100.0",
                "accelerometer_noise_density: 0.002", 'rostopic: "/imu0"'):
        assert key in text
    (tmp_path / "bad.yaml").write_text("foo: 1\n")
    with pytest.raises(ImutoolError, match="none of the keys"):
        load_noise(tmp_path / "bad.yaml")


def test_allan_cli_on_the_real_static_recording(shared, tmp_path, capsys):
    from imutool.cli import main

    d = shared("mag_hmc5883l", "unmoved-with-x-pointing-forward-10min")
    out = tmp_path / "noise.yaml"
    with pytest.raises(SystemExit) as e:
        main(["allan", str(d / "mpu6050_gyroscope.csv"), str(d / "hmc5883l_compass.csv"), "-o", str(out),
              "--kalibr", str(tmp_path / "imu.yaml"), "--plot", str(tmp_path / "allan.png"), "--json"])
    assert e.value.code == 0
    noise = load_noise(out)
    # MPU6050 gyro white noise ~0.005–0.05 deg/s/√Hz; HMC5883L ~0.005–0.05 µT/√Hz at 77 Hz
    assert np.radians(0.005) < noise["gyro_noise_density"] < np.radians(0.05)
    assert 0.005 < noise["mag_noise_density"] < 0.05
    assert (tmp_path / "allan.png").stat().st_size > 10_000
    assert "irregular timestamps" in capsys.readouterr().out
