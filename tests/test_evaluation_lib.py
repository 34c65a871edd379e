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
    cli_names |= {"ref_frame": "ref_frame", "ref_mounting": "ref_mounting", "start": "t_start", "end": "t_end"}
    params = inspect.signature(evaluate_route).parameters
    assert {k: params[cli_names[k]].default for k in EVALUATE_DEFAULTS} == EVALUATE_DEFAULTS


def test_a_reference_of_a_few_rows_is_refused(tmp_path, capsys):
    """Fewer than MIN_REFERENCE_ROWS reference rows within the estimate's span (e.g. two) compare the estimate
    with the line between them: refused in one line naming the reference; a reference of one row at one time
    is refused by require_samples (as every input is)."""
    from formats import Recording
    from imutool.evaluation import MIN_REFERENCE_ROWS

    t = np.arange(0.0, 20.0, 0.1)
    est = Recording(t, meta={"source": "est"})
    for k in ("roll", "pitch", "heading"):
        est.add(k, np.sin(t) + 10.0, "deg")

    def ref_of(times):
        r = Recording(np.asarray(times, float), meta={"source": "ref"})
        for k in ("roll", "pitch", "heading"):
            r.add(f"ref_{k}", np.sin(r.time) + 10.0, "deg")
        return r

    with pytest.raises(ImutoolError, match=r"2 row\(s\) within the estimate's span") as ei:
        evaluate(est, ref_of([1.0, 15.0]))
    assert ei.value.path == "ref"
    with pytest.raises(ImutoolError, match="at least two rows at different times"):
        evaluate(est, ref_of([3.0, 3.0]))
    assert evaluate(est, ref_of(np.linspace(0, 19, MIN_REFERENCE_ROWS)))["angles"]["roll"]["rmse"] < 0.5
    e, r = tmp_path / "est.csv", tmp_path / "ref.csv"
    formats.write(est, str(e))
    formats.write(ref_of([1.0, 15.0]), str(r))
    code, _, err = run_main(["evaluate", e, "--reference", r], capsys)
    lines = [x for x in err.splitlines() if x.strip() and "compiling" not in x]
    assert code == 2 and len(lines) == 1 and str(r) in lines[0] and "at least 10" in lines[0], err
