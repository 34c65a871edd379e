"""Evaluation metrics: wrapped heading errors, lag search, SNR (paper eq. 20), BROAD quaternion metrics."""

import numpy as np
from click.testing import CliRunner

import formats
from formats import Recording
from formats.frames import euler_to_quat
from imutool.metrics import evaluate_angle, quat_errors, snr_db


def test_heading_wrap_and_lag():
    t = np.arange(0, 60, 0.01)
    ref = (355 + 10 * np.sin(2 * np.pi * t / 10)) % 360
    est = (355 + 10 * np.sin(2 * np.pi * (t - 0.12) / 10)) % 360
    s = evaluate_angle(t, est, t, ref, wrap=True, max_lag_s=0.5)
    assert s["max_abs"] < 1.0
    assert abs(s["lag_s"] - 0.12) < 0.01 and s["rmse_lag_removed"] < 0.02


def test_snr_definition():
    s = np.ones(100)
    assert abs(snr_db(s, s + 0.1) - 20.0) < 1e-9


def test_broad_metric_split():
    q_ref = euler_to_quat(np.radians(20.0), np.radians(-10.0), np.radians(100.0))
    yaw = euler_to_quat(0.0, 0.0, np.radians(2.0))
    from formats.frames import quat_multiply

    q_est = quat_multiply(yaw, q_ref)  # a pure heading error of 2° in the world frame
    tot, hd, inc = (np.degrees(x) for x in quat_errors(q_est[None], q_ref[None]))
    assert abs(tot[0] - 2.0) < 1e-9 and abs(hd[0] - 2.0) < 1e-9 and inc[0] < 1e-4  # acos near 1: float precision


def test_evaluate_missing_heave_module_is_one_line(tmp_path):
    from imutool.cli import cli

    rec = Recording(np.arange(5.0), {"roll": np.zeros(5), "ref_roll": np.ones(5)})
    p = tmp_path / "e.csv"
    formats.write(rec, p)
    r = CliRunner().invoke(cli, ["evaluate", str(p), "--json"])
    assert r.exit_code == 0 and '"rmse": 1.0' in r.output
