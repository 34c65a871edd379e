"""The three readings of "heave accuracy 5 cm or 5 %" (imutool.metrics.heave_accuracy) and `evaluate --channel
heave` reporting them."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

import formats
from imutool.cli import cli
from imutool.metrics import heave_accuracy

T = np.arange(0.0, 300.0, 0.1)
REF = np.sqrt(2.0) * 0.5 * np.sin(2 * np.pi * T / 9.0)  # σ = 0.5 m → Hs = 2.0 m, significant amplitude 1.0 m


def test_readings_separate_a_constant_8cm_error():
    r = heave_accuracy(T, REF + 0.08, T, REF)
    assert r["hs_ref_m"] == pytest.approx(2.0, rel=1e-3) and r["rmse_m"] == pytest.approx(0.08)
    assert r["significant"]["tolerance_m"] == pytest.approx(0.10, rel=1e-3) and r["significant"]["pass"]
    assert r["amplitude"]["tolerance_m"] == pytest.approx(0.05, rel=1e-3) and not r["amplitude"]["pass"]
    # per sample: 8 cm > max(5 cm, 5 % of |h|) everywhere (|h| ≤ 0.71 m)
    assert r["per_sample"]["fraction_within"] == 0.0 and not r["per_sample"]["pass"]


def test_readings_all_pass_for_a_small_error_and_the_floor_counts():
    r = heave_accuracy(T, REF + 0.01 * np.sin(T), T, REF)
    assert r["significant"]["pass"] and r["amplitude"]["pass"] and r["per_sample"]["pass"]
    small = REF * 0.02  # Hs 4 cm: every tolerance is the 5 cm floor
    r = heave_accuracy(T, small + 0.045, T, small)
    assert r["amplitude"]["tolerance_m"] == pytest.approx(0.05) and r["amplitude"]["pass"]
    assert r["per_sample"]["fraction_within"] == 1.0


def test_per_sample_reading_is_a_95_percent_bound():
    e = np.where(np.arange(len(T)) % 10 == 0, 0.2, 0.0)  # 10 % of samples 20 cm out
    r = heave_accuracy(T, REF + e, T, REF)
    assert r["per_sample"]["fraction_within"] == pytest.approx(0.9, abs=1e-3) and not r["per_sample"]["pass"]
    e = np.where(np.arange(len(T)) % 50 == 0, 0.2, 0.0)  # 2 %: within the 95 % bound
    assert heave_accuracy(T, REF + e, T, REF)["per_sample"]["pass"]


def test_lag_and_mask_are_applied():
    lagged = np.sqrt(2.0) * 0.5 * np.sin(2 * np.pi * (T - 0.5) / 9.0)
    assert heave_accuracy(T, lagged, T, REF)["rmse_m"] > 0.1
    assert heave_accuracy(T, lagged, T, REF, lag_s=0.5)["rmse_m"] < 1e-3
    bad = REF.copy()
    bad[:500] += 1.0  # unsettled start
    assert heave_accuracy(T, bad, T, REF, mask=T >= 50.0)["rmse_m"] == pytest.approx(0.0, abs=1e-12)
    assert heave_accuracy(T[:5], REF[:5], T, REF)["significant"] is None  # too few samples: no verdict


def test_evaluate_reports_the_readings(tmp_path):
    rec = formats.Recording(T.copy())
    rec.add("heave", REF + 0.08, "m")
    rec.add("settled", np.ones(len(T)), "1")
    rec.add("ref_heave", REF, "m")
    formats.write(rec, tmp_path / "h.csv")
    r = CliRunner().invoke(cli, ["evaluate", str(tmp_path / "h.csv"), "--channel", "heave", "--json"])
    assert r.exit_code == 0, r.output
    rd = json.loads(r.stdout)["heave"]["heave"]["readings"]
    assert rd["significant"]["pass"] and not rd["amplitude"]["pass"] and not rd["per_sample"]["pass"]


def test_evaluate_compares_a_positive_down_file_as_positive_up(tmp_path):
    rec = formats.Recording(T.copy())
    rec.add("heave", -(REF + 0.01), "m")  # an SBG-style file: heave positive down
    rec.add("settled", np.ones(len(T)), "1")
    rec.meta["heave_positive"] = "down"
    formats.write(rec, tmp_path / "down.csv")
    ref = formats.Recording(T.copy())
    ref.add("ref_heave", REF, "m")
    formats.write(ref, tmp_path / "ref.csv")
    r = CliRunner().invoke(
        cli,
        [
            "evaluate",
            str(tmp_path / "down.csv"),
            "--reference",
            str(tmp_path / "ref.csv"),
            "--channel",
            "heave",
            "--max-lag",
            "0",
            "--json",
        ],
    )
    assert r.exit_code == 0, r.output
    h = json.loads(r.stdout)["heave"]
    assert h["heave"]["rmse"] == pytest.approx(0.01, abs=1e-6) and "estimate down" in h["compared"]
    assert h["heave"]["readings"]["amplitude"]["pass"]
