"""Heave: accuracy against simulator truth, the paper's platform, filter properties, real NTNU data, CLI."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

import formats
from formats.errors import ImutoolError
from imutool import heave as H
from imutool.sim.sea import heave_platform, sea_state


def _rmse(out, ref, flag="settled", ch="heave"):
    m = out[flag] > 0.5
    e = (out[ch] - ref)[m]
    return float(np.sqrt(np.mean(e**2)))


@pytest.fixture(scope="module")
def sea():
    return sea_state(duration=600, rate_hz=10, hs=2.0, tp=9.0, seed=3)


def test_platform_paper_method_within_4mm_and_envelope_reported():
    rec = heave_platform(duration=200, rate_hz=50, amplitude=0.04, seed=1)
    out, summ = H.heave_recording(rec, method="paper")
    assert _rmse(out, rec["ref_heave"]) <= 0.004
    env, _ = H.heave_recording(rec, method="envelope")
    assert np.isfinite(_rmse(env, rec["ref_heave"]))
    assert summ["heave_convention"] == "m, positive UP"


def test_sea_state_delayed_and_realtime_bounds_beat_bandpass(sea):
    ref = sea["ref_heave"]
    sig = 4 * np.std(ref)
    rt, _ = H.heave_recording(sea, method="realtime")  # vertical from the tilt filter (no truth used)
    bp, _ = H.heave_recording(sea, method="bandpass")
    e_rt = _rmse(rt, ref)
    e_del = _rmse(rt, ref, "settled_delayed", "heave_delayed")
    assert e_del <= max(0.02, 0.02 * sig)
    assert e_rt <= max(0.05, 0.05 * sig)
    assert e_rt < _rmse(bp, ref) and e_del < _rmse(bp, ref)


def test_discretisation_is_the_matrix_exponential_of_the_oscillator():
    w, dt = 0.9, 0.05
    f = H.oscillator_matrix(np.array([w]))
    phi, qd = H.discretise(f, np.diag([0.0, 2.0, 0.5]), dt)
    closed = np.array([[np.cos(w * dt), np.sin(w * dt) / w], [-w * np.sin(w * dt), np.cos(w * dt)]])
    assert np.allclose(phi[:2, :2], closed) and phi[2, 2] == pytest.approx(1.0)
    assert np.allclose(phi, expm(f * dt))
    assert np.allclose(qd, qd.T) and np.all(np.linalg.eigvalsh(qd) >= -1e-15)
    assert qd[2, 2] == pytest.approx(0.5 * dt)


def test_bandpass_integrator_rejects_bias_and_needs_order_3():
    fs = 20.0
    t = np.arange(0, 600, 1 / fs)
    a = 0.3 * np.sin(2 * np.pi * 0.1 * t)
    a[t > 100] -= 0.022  # a bias step of −0.022 m/s² (the paper's value) at 100 s
    h, _ = H.heave_bandpass(a, fs, 0.02)
    late = t > 500  # the filter has forgotten the step: no t² drift, only the (phase-led) wave remains
    assert np.max(np.abs(h[late])) < 1.2 * 0.3 / (2 * np.pi * 0.1) ** 2
    with pytest.raises(ImutoolError, match="order"):
        H.bandpass_integrator(fs, 0.02, order=2)


def test_phase_lead_is_cancelled_per_harmonic():
    fs = 10.0
    sos = H.bandpass_integrator(fs, 0.03, 3)
    g = H.integrator_response(sos, fs, [0.1])[0]
    assert np.angle(g) > 0.1  # the band-pass leads
    om = 2 * np.pi * 0.1
    rot = expm(H.oscillator_matrix(np.array([om]), residual=False) * (-np.angle(g) / om)) / abs(g)
    # a unit cosine seen through G: state (|g|cos φ, −|g|ω sin φ) → rotated back to (1, 0)
    x = np.array([abs(g) * np.cos(np.angle(g)), -abs(g) * om * np.sin(np.angle(g))])
    assert np.allclose(rot @ x, [1.0, 0.0], atol=1e-9)


def test_lever_arm_transfer_matches_rigid_body_truth(sea):
    from formats.frames import quat_to_matrix

    r = np.array([12.0, -3.5, 4.0])
    out, summ = H.heave_recording(sea, method="realtime", lever_arm=r, attitude="ref")
    pz = np.einsum("nj,j->n", quat_to_matrix(sea["ref_q"])[:, 2, :], r)
    truth = sea["ref_heave"] - (pz - pz.mean())
    assert summ["lever_arm_m"] == [12.0, -3.5, 4.0]
    e = _rmse(out, truth, "settled_delayed", "heave_delayed")
    assert e < 0.02
    assert e < 0.2 * np.std(truth - sea["ref_heave"])  # the lever arm mattered and was transferred


def test_evaluate_heave_finds_lag_and_excludes_unsettled(sea):
    out, _ = H.heave_recording(sea, method="realtime")
    shifted = out.copy()
    shifted.time = shifted.time + 0.05  # estimate lags the reference by 0.05 s
    ev = H.evaluate_heave(shifted, sea, max_lag_s=0.1)
    assert ev["heave_delayed"]["lag_s"] == pytest.approx(0.05, abs=0.01)
    assert ev["heave"]["excluded_unsettled"] > 0
    with pytest.raises(ImutoolError, match="heave"):
        H.evaluate_heave(out, formats.Recording(sea.time.copy()), 0.1)


@pytest.mark.parametrize(("name", "quoted"), [("3012_1.csv", 0.0015), ("4061_1.csv", 0.0044)])
def test_ntnu_delayed_no_worse_than_zero_phase_bandpass(shared, name, quoted):
    from imutool.metrics import best_lag, interp_to

    rec = formats.read(str(shared("ntnu_waves", name)))
    cols = ["acc_heave_sb", "acc_heave_ps"]
    out, _ = H.heave_recording(rec, vertical=cols)
    a = np.mean([rec[c] for c in cols], axis=0)
    base = H.heave_zero_phase_bandpass(a, rec.rate_hz, 0.3, 3.0)
    cam = rec["heave"]

    def err(x, mask):
        lag, _ = best_lag(rec.time[mask], x[mask], rec.time, cam, 0.1)
        return float(np.sqrt(np.nanmean((x[mask] - interp_to(rec.time[mask] - lag, rec.time, cam)) ** 2)))

    md = out["settled_delayed"] > 0.5
    mr = out["settled"] > 0.5
    # vs the quoted baseline figures, and within 5 % of our own run of that baseline on the same samples
    # (3012_1: 1.26 mm vs 1.22 mm — the camera's own amplitude response favours the baseline's gain slope)
    assert err(out["heave_delayed"], md) <= quoted
    assert err(out["heave_delayed"], md) <= err(base, md) * 1.05
    # real time: within 25 % of the quoted baseline figure (on the short settled tail of 3012_1 our own
    # zero-phase baseline does better than that; docs/heave.md gives both numbers)
    assert err(out["heave"], mr) <= 1.25 * quoted


def test_cli_heave_writes_positive_up_and_reports_bad_column(tmp_path):
    from click.testing import CliRunner

    from imutool.cli import cli

    rec = heave_platform(duration=120, rate_hz=20, seed=2)
    src = tmp_path / "p.csv"
    formats.write(rec, str(src))
    res = CliRunner().invoke(cli, ["heave", str(src), "-o", str(tmp_path / "h.csv"), "--method", "paper",
                                   "--json"])
    assert res.exit_code == 0, res.output
    text = (tmp_path / "h.csv").read_text()
    assert "positive UP" in text.split("time,")[0]
    with pytest.raises(ImutoolError, match="nope"):
        H.heave_recording(rec, vertical=["nope"])
