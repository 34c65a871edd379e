"""imutool.evaluation.evaluate: the comparison behind `imutool evaluate`, from Python, equals the CLI's summary."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_main

import formats
from formats.errors import ImutoolError
from imutool.evaluation import evaluate, run_evaluate
from imutool.filtering import run_filter
from imutool.sim import simulate


def test_python_evaluate_equals_cli(tmp_path, capsys):
    src, est = tmp_path / "roll.csv", tmp_path / "est.csv"
    formats.write(simulate("ship-roll", duration=30, seed=5), src)
    run_filter(str(src), str(est))
    code, out, err = run_main(["evaluate", est, "--reference", src, "--json", "--max-lag", "0.5"], capsys)
    assert code == 0, err
    route = run_evaluate(est, src, max_lag_s=0.5).full_summary()  # the CLI's route: the estimate's validation too
    assert json.loads(json.dumps(route, default=str)) == json.loads(out)
    s = evaluate(est, src, max_lag_s=0.5)
    assert s["angles"] == route["angles"] and s["quaternion"] == route["quaternion"]
    assert s["angles"]["roll"]["rmse"] < 1.0 and s["quaternion"]["total"]["rmse"] < 5.0
    # Recordings in memory: same figures (the estimate carries ref_* itself, so no reference is needed)
    r = evaluate(formats.read(est), max_lag_s=0.5)
    assert r["angles"]["roll"]["rmse"] == pytest.approx(s["angles"]["roll"]["rmse"], abs=1e-4)
    # a wrong estimate is caught: 2° of roll bias shows up as ≥ 1.5° RMSE
    biased = formats.read(est)
    biased.channels["roll"] = biased["roll"] + 2.0
    assert evaluate(biased)["angles"]["roll"]["rmse"] > 1.5


def test_refusals(tmp_path):
    rec = formats.Recording(np.arange(10) * 0.1)
    rec.add("gyro", np.zeros((10, 3)))
    with pytest.raises(ImutoolError, match="nothing to compare"):
        evaluate(rec)
    with pytest.raises(ImutoolError, match="channel"):
        evaluate(rec, channel="yaw")


def test_evaluate_defaults_live_once():
    """evaluate, run_evaluate and the command's route take their defaults from EVALUATE_DEFAULTS."""
    import inspect

    from imutool.cli.evaluate import evaluate_route
    from imutool.evaluation import EVALUATE_DEFAULTS

    for func in (evaluate, run_evaluate):
        params = inspect.signature(func).parameters
        assert {k: params[k].default for k in EVALUATE_DEFAULTS} == EVALUATE_DEFAULTS
    cli_names = {"channel": "channel", "max_lag_s": "max_lag", "plot": "plot_path", "align_heading": "align_heading"}
    params = inspect.signature(evaluate_route).parameters
    assert {k: params[cli_names[k]].default for k in EVALUATE_DEFAULTS} == EVALUATE_DEFAULTS
