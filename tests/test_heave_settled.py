"""An honest `settled` for the real-time heave (issue 48, item 9): settled only while the error bound `heave_std`
(the filter's own) is below a stated fraction of the sea; a wave onset after still water restarts the settling; a
run where nothing settles (a drift) is warned; two heaves that disagree beyond their σ are warned."""

from __future__ import annotations

import json

import numpy as np

import formats
from imutool import heave as H
from imutool.sim.sea import sea_state

COLS = ["acc_heave_sb", "acc_heave_ps"]


def test_flume_run_from_still_water_is_settled_only_where_the_bound_holds(shared):
    """NTNU 3012_1 (25 s of still water, then regular waves, camera heave truth) at 100 Hz: the first frequency
    estimate is made on still-water noise (1.37 Hz), the corner sits at 0.62 × the 0.66-Hz waves that follow and
    the real-time heave comes out twice the camera's. Before issue 48 it was `settled` from 13.8 s on: 7.3 mm RMS
    over the settled samples (24 % of Hs 30 mm), 13–17 mm while the waves grew. Now the onset restarts the settling
    and heave_std shows the error: nothing is settled while the waves grow, and what is settled is within 3 mm."""
    rec = formats.read(str(shared("ntnu_waves", "3012_1.csv")))
    rec = rec.select(np.arange(len(rec)) % 2 == 0)
    out, summ = H.heave_recording(rec, vertical=COLS)
    t, cam = rec.time, rec["heave"]
    m = out["settled"] > 0.5
    e = out["heave"] - cam
    hs = 4 * float(np.std(cam))
    assert m.sum() > 100
    assert float(np.sqrt(np.mean(e[m] ** 2))) <= 0.1 * hs  # 0.3 mm measured; 7.3 mm before
    growing = (t >= 27.5) & (t < 42.5)  # the waves arrive: real-time error 7–17 mm RMS
    assert not m[growing].any()
    # the bound is the error's size where the error is large (σ RMS 11 mm vs 10 mm RMS error there)
    sig = float(np.sqrt(np.mean(out["heave_std"][growing] ** 2)))
    assert float(np.sqrt(np.mean(e[growing] ** 2))) <= 2.0 * sig
    assert "heave_std" in summ["settle_rule"] and out.units["heave_std"] == "m"


def _drifting(seconds: float = 44.0, hz: float = 50.0) -> formats.Recording:
    """A short record with no waves: a vertical accelerometer whose first sample is off its mean and whose offset
    wanders (a boat in a harbour, a sensor not levelled) — the real-time heave runs away by metres."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, seconds, 1.0 / hz)
    a = 0.03 + 0.02 * np.sin(2 * np.pi * t / 30.0) + 0.005 * rng.standard_normal(len(t))
    a[0] = 0.0
    rec = formats.Recording(t)
    rec.add("acc_up", a, "m/s^2")
    return rec


def test_a_short_drifting_record_never_settles_and_is_warned(tmp_path, capsys):
    from conftest import run_main

    rec = _drifting()
    out, summ = H.heave_recording(rec, vertical=["acc_up"])
    assert np.abs(out["heave"]).max() > 1.0  # the drift this is about
    assert out["settled"].max() == 0
    assert any("no sample settled" in w and "drifts to" in w for w in summ["warnings"]), summ.get("warnings")
    src = tmp_path / "drift.csv"
    formats.write(rec, src)
    code, stdout, err = run_main(
        ["heave", src, "-o", tmp_path / "h.csv", "--vertical", "acc_up", "--json", "--force"], capsys
    )
    assert code == 0, err
    assert "warning: real-time heave: no sample settled" in err
    assert any("no sample settled" in w for w in json.loads(stdout)["warnings"])
    written = formats.read(tmp_path / "h.csv")
    assert "no sample settled" in str(written.meta.get("warnings"))
    assert written["settled"].max() == 0


def _pair(gain_b: float) -> formats.Recording:
    rec = sea_state(duration=400, rate_hz=10, hs=2.0, tp=8.0, seed=5)
    rng = np.random.default_rng(3)
    acc = rec["ref_heave_accel"]
    out = formats.Recording(rec.time.copy())
    out.add("acc_a", acc + 0.01 * rng.standard_normal(len(acc)), "m/s^2")
    out.add("acc_b", gain_b * acc + 0.01 * rng.standard_normal(len(acc)), "m/s^2")
    return out


def test_two_vertical_accelerometers_that_disagree_are_warned():
    """Two vertical accelerometers: the heave of each is compared with the σ the two claim; one reading twice
    (a range error) or mounted upside down is said, two sound ones are not. (The σ is the integrator's, ~10 % of
    Hs at the settle limit: a 30 % gain error stays within it.)"""
    _, good = H.heave_recording(_pair(1.0), vertical=["acc_a", "acc_b"])
    assert good["plausibility_accelerometers"]["consistent"] is True
    assert not any("differ by" in w for w in good.get("warnings", []))
    for gain in (2.0, -1.0):
        _, bad = H.heave_recording(_pair(gain), vertical=["acc_a", "acc_b"])
        p = bad["plausibility_accelerometers"]
        assert p["consistent"] is False and p["rms_difference_m"] > 2.0 * p["rms_heave_std_m"]
        assert any("acc_a and acc_b differ by" in w for w in bad["warnings"])


def test_real_time_against_delayed_beyond_sigma_is_warned():
    n = 2000
    hd = np.sin(np.arange(n) * 0.05)
    settled = np.ones(n)
    std = np.full(n, 0.01)
    assert H.realtime_warnings(hd + 0.01 * np.sin(np.arange(n)), std, settled, hd, settled, 0.1) == []
    w = H.realtime_warnings(hd + 0.1, std, settled, hd, settled, 0.1)
    assert len(w) == 1 and "disagrees with the delayed heave" in w[0]


def test_onset_after_still_water_restarts_the_settling():
    """Still water (noise) until 200 s, then a sea: the samples from the onset until a frequency estimate made on
    the new sea (plus the settle periods) are unsettled, causally."""
    t = np.arange(0.0, 500.0, 0.1)
    rng = np.random.default_rng(1)
    a = 0.002 * rng.standard_normal(len(t)) + (t >= 200) * 0.5 * np.sin(2 * np.pi * 0.1 * t)
    tr = H.track_frequencies(t, a, 1, 240.0, 10.0, 10.0, 0.03, 2.0, "centroids")
    mask = H.onset_unsettled(t, a, tr, float(tr.dominant[0]), 4.0)
    assert not mask[t < 199.0].any()
    assert mask[(t >= 201.0) & (t < 240.0)].all()
    assert not mask[t > 400].any()
