"""Compass Kalman filter (paper 3): wrap-around, beats the raw heading on compass-swing, deviation/variation."""

import numpy as np

from formats.frames import wrap_deg180
from imutool.compass import CompassParams, compass_recording, wrapped_kf
from imutool.sim import simulate


def test_wraps_359_to_0_without_jump():
    z = np.r_[np.linspace(350.0, 359.9, 100), np.linspace(0.0, 10.0, 100)]
    h, _, _ = wrapped_kf(z)
    assert np.all((h >= 0) & (h < 360))
    assert np.abs(wrap_deg180(np.diff(h))).max() < 1.0
    assert np.abs(wrap_deg180(h[-1] - 10.0)) < 3.0


def test_paper_defaults_converge():
    z = np.full(400, 20.0) + np.random.default_rng(0).normal(0, 1.4, 400)
    h, sd, _ = wrapped_kf(z, params=CompassParams(paper_init=True))  # x0 = 0, P0 = 0
    assert abs(h[-100:].mean() - 20.0) < 0.5
    assert np.std(h[-100:]) < np.std(z[-100:]) / 3


def test_swing_beats_raw_with_calibration_and_variation():
    from calibration.deviation import DeviationCard

    rec = simulate("compass-swing", duration=200, seed=1, variation_deg=-3.0)
    a = np.array(rec.meta["mag_correction_A"])
    b = np.array(rec.meta["mag_hard_iron_ut"])
    rec.channels["mag"] = (rec["mag"] - b) @ a.T
    card = DeviationCard(*rec.meta["deviation_deg"])
    out, s = compass_recording(rec, CompassParams(variation_deg=-3.0), deviation=card)
    assert s["method"] == "compass-gyro"
    e = wrap_deg180(out["heading"] - rec["ref_heading"])
    e_raw = wrap_deg180(out["heading_raw"] - rec["ref_heading"])
    assert np.sqrt(np.mean(e**2)) < 0.5 * np.sqrt(np.mean(e_raw**2))
    assert np.sqrt(np.mean(e**2)) < 0.2
