"""Allan deviation: noise terms against known densities, the noise/kalibr files, the CLI on real data."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.allan import allan_deviation, analyse
from calibration.noise_file import load_noise, write_kalibr, write_noise
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
        d = (theta[2 * mm :] - 2 * theta[mm:-mm] + theta[: -2 * mm])[::s]
        assert adev[i] == pytest.approx(np.sqrt(np.mean(d**2) / (2 * (mm / fs) ** 2)), rel=1e-10)


def test_allan_refuses_nan_and_short_input():
    with pytest.raises(ImutoolError, match="NaN"):
        allan_deviation(np.array([1.0, np.nan] * 20), 10.0)
    with pytest.raises(ImutoolError, match="at least 20"):
        allan_deviation(np.ones(5), 10.0)


def test_noise_yaml_and_kalibr_round_trip(tmp_path):
    vals = {
        "gyro_noise_density": 1.5e-4,
        "gyro_bias_instability": 3e-5,
        "gyro_random_walk": 2e-6,
        "gyro_noise_density_xyz": [1e-4, 2e-4, 1.5e-4],
        "accel_noise_density": 2e-3,
        "rate_hz": 100.0,
        "source": 'a "quoted" #name.csv',
    }
    write_noise(tmp_path / "noise.yaml", vals)
    back = load_noise(tmp_path / "noise.yaml")
    assert back == vals
    # the accelerometer random walk is not resolved: refused, never written as 0.0
    with pytest.raises(ImutoolError, match="accelerometer_random_walk not resolved"):
        write_kalibr(tmp_path / "imu.yaml", vals)
    assert not (tmp_path / "imu.yaml").exists()
    with pytest.raises(ImutoolError, match="accelerometer_random_walk"):
        write_kalibr(tmp_path / "imu.yaml", {**vals, "accel_random_walk": 0.0})
    write_kalibr(tmp_path / "imu.yaml", {**vals, "accel_random_walk": 3e-4})
    text = (tmp_path / "imu.yaml").read_text()
    for key in (
        "gyroscope_noise_density: 0.00015",
        "gyroscope_random_walk: 2e-06",
        "update_rate: 100.0",
        "accelerometer_noise_density: 0.002",
        "accelerometer_random_walk: 0.0003",
        'rostopic: "/imu0"',
    ):
        assert key in text
    assert "UPPER BOUND" not in text
    # the explicit fallback writes the labelled upper bound and says so
    w = write_kalibr(tmp_path / "imu2.yaml", {**vals, "accel_random_walk_upper_bound": 4e-4}, fallback="upper-bound")
    text = (tmp_path / "imu2.yaml").read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith("accelerometer_random_walk:"))
    assert "0.0004" in line and "UPPER BOUND" in line and "WARNING" in text
    assert len(w) == 1 and "upper bound" in w[0]
    with pytest.raises(ImutoolError, match="gyroscope_noise_density"):  # no fallback for a noise density
        write_kalibr(
            tmp_path / "imu3.yaml", {"accel_noise_density": 1e-3, "accel_random_walk": 1e-4}, fallback="upper-bound"
        )
    (tmp_path / "bad.yaml").write_text("foo: 1\n")
    with pytest.raises(ImutoolError, match="none of the keys"):
        load_noise(tmp_path / "bad.yaml")


def test_white_plus_random_walk_minimum_is_labelled_a_crossover():
    # no flicker: σ² = N²/τ + K² τ/3, minimum 2NK/√3 at τ = √3 N/K (≈ 17 s) — not a bias instability
    n_d, k_rw, fs = 0.01, 0.001, 20.0
    res = analyse(_white_plus_rw(n_d, k_rw, fs, 1.0, seed=5), fs, "gyro", "rad/s")
    for t in res.terms:
        assert t["B_kind"] == "crossover" and t["B_upper_bound"] and t["K_resolved"]
        assert t["adev_min"] == pytest.approx(np.sqrt(2 * n_d * k_rw / np.sqrt(3)), rel=0.15)
        assert t["tau_min_s"] == pytest.approx(np.sqrt(3) * n_d / k_rw, rel=0.6)
        assert t["flat_B_fit"] < 0.3 * t["B"]
        assert 0.9 * k_rw < t["K_upper"] < 2.0 * k_rw  # the fallback bound is near K, not below it by much


def _flicker(n, fs, level, rng):
    """1/f noise scaled to a flat Allan deviation ≈ level (σ = 0.664 B)."""
    f = np.fft.rfftfreq(n, 1 / fs)
    x = np.fft.rfft(rng.standard_normal(n))
    x[1:] /= np.sqrt(f[1:])
    x[0] = 0
    y = np.fft.irfft(x, n)
    taus, adev, _ = allan_deviation(y, fs, m=np.array([int(20 * fs)]))
    return y * level / adev[0]


def test_flicker_floor_is_labelled_bias_instability():
    rng = np.random.default_rng(9)
    fs, n = 20.0, int(3600 * 20)
    y = rng.standard_normal(n) * 0.01 * np.sqrt(fs) + _flicker(n, fs, 0.003, rng)
    t = analyse(y, fs, "gyro", "rad/s").terms[0]
    assert t["B_kind"] == "bias instability" and not t["B_upper_bound"]
    assert t["B"] * 0.6643 == pytest.approx(0.003, rel=0.25)


def test_allan_cli_labels_and_refuses_unresolved_kalibr(tmp_path):
    from click.testing import CliRunner

    import formats
    from imutool.cli import cli

    rng = np.random.default_rng(4)
    fs, n = 50.0, 3000  # 60 s: no +1/2 slope can be seen
    t = np.arange(n) / fs
    rec = formats.Recording(t)
    rec.add("gyro", rng.standard_normal((n, 3)) * 1e-3 * np.sqrt(fs), "rad/s")
    rec.add("accel", rng.standard_normal((n, 3)) * 2e-3 * np.sqrt(fs) + [0, 0, -9.81], "m/s^2")
    formats.write(rec, tmp_path / "static.csv")
    r = CliRunner().invoke(
        cli,
        [
            "allan",
            str(tmp_path / "static.csv"),
            "-o",
            str(tmp_path / "noise.yaml"),
            "--kalibr",
            str(tmp_path / "imu.yaml"),
        ],
    )
    assert r.exit_code != 0 and "random_walk not resolved" in str(r.exception)
    assert not (tmp_path / "imu.yaml").exists()
    r = CliRunner().invoke(
        cli,
        [
            "allan",
            str(tmp_path / "static.csv"),
            "-o",
            str(tmp_path / "noise2.yaml"),
            "--kalibr",
            str(tmp_path / "imu.yaml"),
            "--kalibr-fallback",
            "upper-bound",
        ],
    )
    assert r.exit_code == 0, r.output
    assert "not resolved (<=" in r.stdout and "bias inst. B" not in r.stdout and "warning: kalibr" in r.stderr
    text = (tmp_path / "imu.yaml").read_text()
    assert text.count("UPPER BOUND") == 2 and "random_walk: 0.0\n" not in text
    noise = load_noise(tmp_path / "noise2.yaml")
    assert "gyro_random_walk" not in noise and noise["gyro_random_walk_upper_bound"] > 0
    assert "gyro_bias_instability" not in noise and noise["gyro_bias_instability_upper_bound"] > 0


@pytest.mark.slow
def test_allan_cli_on_the_real_static_recording(shared, tmp_path, capsys):
    from imutool.cli import main

    d = shared("mag_hmc5883l", "unmoved-with-x-pointing-forward-10min")
    out = tmp_path / "noise.yaml"
    with pytest.raises(SystemExit) as e:
        main(
            [
                "allan",
                str(d / "mpu6050_gyroscope.csv"),
                str(d / "hmc5883l_compass.csv"),
                "-o",
                str(out),
                "--plot",
                str(tmp_path / "allan.png"),
                "--json",
            ]
        )
    assert e.value.code == 0
    noise = load_noise(out)
    kinds = noise["gyro_allan_minimum_xyz"]
    assert set(kinds) <= {"bias instability", "crossover", "upper bound"} and len(kinds) == 3
    assert ("gyro_bias_instability" in noise) == all(k == "bias instability" for k in kinds)
    # MPU6050 gyro white noise ~0.005–0.05 deg/s/√Hz; HMC5883L ~0.005–0.05 µT/√Hz at 77 Hz
    assert np.radians(0.005) < noise["gyro_noise_density"] < np.radians(0.05)
    assert 0.005 < noise["mag_noise_density"] < 0.05
    assert (tmp_path / "allan.png").stat().st_size > 10_000
    assert "irregular timestamps" in capsys.readouterr().out
    # no accelerometer in these files: a kalibr file would need made-up accelerometer terms — refused
    with pytest.raises(SystemExit) as e:
        main(
            [
                "allan",
                str(d / "mpu6050_gyroscope.csv"),
                "-o",
                str(tmp_path / "n2.yaml"),
                "--kalibr",
                str(tmp_path / "imu.yaml"),
                "--kalibr-fallback",
                "upper-bound",
            ]
        )
    assert e.value.code == 2 and "accelerometer_noise_density" in capsys.readouterr().err
    assert not (tmp_path / "imu.yaml").exists()
