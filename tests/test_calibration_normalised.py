"""`calibrate mag` on a normalised magnetometer (|m| ≡ 1, unit-less, as RepoIMU and many data sets give it; issue 48,
item 10): no internal error, the calibration information that is absent is said, and a command that fails leaves
no calibration file behind."""

from __future__ import annotations

import errno
import json

import numpy as np
import pytest
from conftest import run_main as run

import formats
from formats import Recording


def _normalised(path, noise: float = 0.0):
    """A smooth tumble through every direction (spiral over the sphere), |m| = 1 exactly (noise: σ per axis)."""
    n = 6000
    s = np.linspace(0.0, 1.0, n)
    th, ph = np.arccos(1 - 2 * s), 2 * np.pi * 30 * s
    m = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=1)
    m += np.random.default_rng(3).normal(size=m.shape) * noise
    formats.write(Recording(np.arange(n) * 0.01, {"mag": m}), path)
    return path


def test_normalised_magnetometer_with_plot_says_what_is_absent(tmp_path, capsys):
    src = _normalised(tmp_path / "norm.csv")
    cal, png = tmp_path / "cal.toml", tmp_path / "cal.png"
    code, out, err = run(["calibrate", "mag", src, "-o", cal, "--plot", png], capsys)
    assert code == 0, err  # was: exit 3, internal error "Too many bins for data range" (|m| has no spread)
    assert "Traceback" not in err and "internal error" not in err
    assert "absent: field strength unknown: the magnetometer is normalised" in out
    assert "absent: hard/soft iron unknown" in out
    assert cal.exists() and png.stat().st_size > 10_000
    code, out, err = run(["calibrate", "mag", src, "-o", tmp_path / "c2.toml", "--json"], capsys)
    s = json.loads(out)
    assert code == 0 and any("normalised" in a for a in s["information_absent"])


def test_a_calibrated_earth_field_is_not_called_normalised(tmp_path, capsys):
    src = tmp_path / "earth.csv"
    _normalised(src, noise=0.01)
    rec = formats.read(src)
    rec.add("mag", rec["mag"] * 48.0 + [12.0, -5.0, 3.0])  # µT, hard iron: a real raw magnetometer
    formats.write(rec, src)
    code, out, err = run(["calibrate", "mag", src, "-o", tmp_path / "c.toml", "--json"], capsys)
    assert code == 0, err
    assert json.loads(out)["information_absent"] == []


def test_failing_plot_leaves_no_calibration_file(tmp_path, capsys, monkeypatch):
    from matplotlib.figure import Figure

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Figure, "savefig", full)
    src = _normalised(tmp_path / "norm.csv", noise=0.002)
    cal, png = tmp_path / "cal.toml", tmp_path / "cal.png"
    code, out, err = run(["calibrate", "mag", src, "-o", cal, "--plot", png], capsys)
    assert code == 2 and "Traceback" not in err and "space" in err.lower()
    assert not cal.exists() and not png.exists()  # was: the TOML written before the plot failed
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left either


@pytest.mark.parametrize("noise", [0.0, 0.002])
def test_absent_information_from_the_fit(tmp_path, noise):
    from calibration.magnetometer import absent_information, calibrate_sphere

    m = formats.read(_normalised(tmp_path / "n.csv", noise))["mag"]
    fit = calibrate_sphere(m, "auto", None, None, 8)
    lines = absent_information(fit)
    assert any(x.startswith("field strength unknown") for x in lines)
    assert absent_information(fit, field_given=True) == [x for x in lines if not x.startswith("field strength")]
