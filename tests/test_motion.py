"""The motion model (issue 35, item 3): a ship told from hand-held motion by the gyro, and its low-pass."""

from __future__ import annotations

import numpy as np
import pytest

import formats
from imutool.attitude import EkfParams
from imutool.attitude.motion import choose_motion
from imutool.attitude.params import read_params_file
from imutool.filtering import run_filter
from imutool.sim import simulate


@pytest.mark.parametrize(
    "scenario, options, kind",
    [
        ("ship-roll", {}, "ship"),
        ("ship-at-sea", {"roll_significant_deg": 30.0, "sway_m": 1.5, "sway_period": 6.0}, "ship"),
        ("turn", {}, "ship"),
        ("walk", {}, "handheld"),
        ("static", {}, "handheld"),  # still: nothing to tell a ship by
    ],
)
def test_auto_tells_a_ship_from_a_hand(scenario, options, kind):
    rec = simulate(scenario, duration=120.0, seed=0, **options)
    choice = choose_motion(EkfParams(), rec.time, rec.in_unit("gyro", "rad/s"))
    assert choice.kind == kind, choice
    assert choice.lp_tau_s == (EkfParams().ship_lp_tau if kind == "ship" else EkfParams().accel_lp_tau)


@pytest.mark.slow
def test_every_broad_trial_is_hand_held(shared):
    """The 16 BROAD trials (82–1074 °/s, low-frequency share ≤ 0.79): auto keeps the hand-held low-pass, so their
    figures are the hand-held filter's, unchanged."""
    files = sorted(shared("broad").glob("*.csv"))
    assert len(files) >= 16
    for f in files:
        rec = formats.read(f)
        choice = choose_motion(EkfParams(), rec.time, rec.in_unit("gyro", "rad/s"))
        assert choice.kind == "handheld", (f, choice)


def test_a_ship_without_its_full_velocity_gets_the_ship_low_pass():
    """A receiver's smoothed track (no sway in it) on a bridge sensor: with the hand-held low-pass the sway's false
    tilt passes (0.39° RMS, 1.4° max on this corner); with the ship's, the roll meets the bound."""
    rec = simulate(
        "ship-at-sea",
        duration=180.0,
        seed=0,
        lever_arm=(-12.0, 0.0, -30.0),
        roll_significant_deg=30.0,
        sway_m=1.5,
        sway_period=6.0,
        turn_start=40.0,
        speed_source="smoothed",
    )
    after = rec.time - rec.time[0] >= 120.0
    lever = np.array(rec.meta["lever_arm_m"])
    errs = {}
    for motion in ("auto", "handheld"):
        res = run_filter(rec, params=EkfParams(motion=motion), lever_arm=lever)
        e = (res.recording["roll"] - rec["ref_roll"])[after]
        errs[motion] = (np.sqrt(np.mean(e**2)), np.abs(e).max())
        assert res.summary["motion"]["kind"] == ("ship" if motion == "auto" else "handheld")
        assert res.recording.meta["motion"] == res.summary["motion"]
    assert errs["auto"][0] < 0.25 and errs["auto"][1] < 1.0, errs
    assert errs["handheld"][0] > 1.5 * errs["auto"][0], errs


def test_the_motion_is_asked_recorded_and_streamed_alike(tmp_path):
    rec = simulate("ship-roll", duration=60.0, seed=1)
    src = tmp_path / "roll.csv"
    formats.write(rec, src)
    mem = run_filter(src).summary["motion"]
    assert mem["kind"] == "ship" and mem["asked"] == "auto" and 5 < mem["dominant_period_s"] < 20
    streamed = run_filter(src, tmp_path / "s.csv", stream_mb=0.0, chunk_rows=3000).summary["motion"]
    assert streamed["kind"] == "ship"
    assert formats.read(tmp_path / "s.csv").meta["motion"]["kind"] == "ship"
    forced = run_filter(src, params=EkfParams(motion="handheld")).summary["motion"]
    assert forced == {"kind": "handheld", "asked": "handheld", "accel_lp_tau_s": 2.5}
    with pytest.raises(formats.ImutoolError, match="motion 'boat'"):
        EkfParams(motion="boat")


def test_a_parameters_file_from_before_the_motion_model_is_told(tmp_path):
    old = tmp_path / "old.toml"
    old.write_text("version = 1\n[ekf]\naccel_lp_tau = 3.0\n", encoding="utf-8")
    notes = read_params_file(str(old)).notes()
    assert any("motion" in n and "ship_lp_tau" in n for n in notes), notes
    new = tmp_path / "new.toml"
    new.write_text(EkfParams().to_toml(), encoding="utf-8")
    assert read_params_file(str(new)).notes() == []


def test_a_turn_without_any_speed_is_said_and_with_one_is_not():
    """Without a speed a sustained turn's centripetal acceleration reads as roll: said on stderr with its span."""
    for speed in ("none", "gnss"):
        rec = simulate("ship-at-sea", duration=300.0, seed=0, turn_start=60.0, speed_source=speed)
        s = run_filter(rec, lever_arm=np.array(rec.meta["lever_arm_m"])).summary
        said = [w for w in s.get("warnings", []) if "without any speed input" in w]
        if speed == "none":
            assert len(said) == 1 and "0.1° per m/s" in said[0], s.get("warnings")
            (a, b), *_ = s["turns_without_speed_s"]
            assert 55 < a < 90 and 170 < b < 220, (a, b)  # the turn: 60 s + 120 s at 3 °/s + its ramps
        else:
            assert not said and "turns_without_speed_s" not in s


def test_the_motion_of_a_long_recording_is_that_of_its_first_ten_minutes():
    """Issue 52: the motion is judged on the first ANALYSIS_MAX_S only, and now only those rows are looked at (a 2 M-row
    file: 143 → 28 ms per million rows). The statistics are those of the first span cut by hand, with a corrupt or
    missing start (judged from the first usable row); what follows the span changes nothing."""
    from imutool.attitude.motion import ANALYSIS_MAX_S, motion_statistics

    rec = simulate("ship-roll", duration=900.0, seed=2)
    t, g = rec.time, rec.in_unit("gyro", "rad/s")
    t, g = t - t[0] + 100.0, np.array(g)
    g[:50] = np.nan  # a missing start
    g[50:60] = 1e6  # and a corrupt one: the span starts at row 60
    cut = t - t[60] <= ANALYSIS_MAX_S
    cut[:60] = False
    whole, first = motion_statistics(t, g), motion_statistics(t[cut], g[cut])
    assert whole == first and np.isfinite(whole).all(), (whole, first)
    later = t - t[0] > ANALYSIS_MAX_S + 60.0
    g2 = g.copy()
    g2[later] *= 50.0  # rows after the span change nothing
    assert motion_statistics(t, g2) == whole


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_turns_evaluated_every_step_are_those_of_every_sample(seed, monkeypatch):
    """The turn check evaluates its 20-s rate every TURN_STEP_S and at every sample only between two evaluations
    that disagree and around the largest: the same spans (to the sample, unrounded) and the same largest rate as
    the rate evaluated at every sample (TURN_STEP_S = 0, the check before issue 52), in one chunk and in chunks of
    7 001 rows, on ships turning at 3 °/s with waves, a missing gyro sample, and a gap."""
    from imutool.attitude import selfcheck as sc
    from imutool.sim import simulate

    rec = simulate("ship-at-sea", duration=900.0, seed=seed, turn_start=60.0 + 150 * seed, speed_source="none")
    t = np.array(rec.time, dtype=float)
    t[60_000:] += 2.0  # a gap
    q, gyro = np.asarray(rec["ref_q"]), np.array(rec["gyro"], dtype=float)
    gyro[500:510, 1] = np.nan
    bias = np.full_like(gyro, 1e-3)
    found = {}
    step_s = sc.TURN_STEP_S
    for step in (0.0, step_s):
        monkeypatch.setattr(sc, "TURN_STEP_S", step)
        for chunk in (len(t), 7001):
            check = sc.SelfCheck(EkfParams(), 0.01)
            for i in range(0, len(t), chunk):
                check._add_turns(t[i : i + chunk], q[i : i + chunk], gyro[i : i + chunk], bias[i : i + chunk])
            found[step, chunk] = ([tuple(s) for s in check.turns.spans], check.turn_rate_max)
    every = found[0.0, len(t)]
    assert any(b - a >= sc.TURN_MIN_S for a, b in every[0]) and every[1] > 2.0, every  # a turn, at ~3 °/s
    for chunk in (len(t), 7001):  # (chunks add the angle up in another order: the rate's last bits differ)
        assert found[step_s, chunk] == found[0.0, chunk], found
        assert found[0.0, chunk][0] == every[0] and found[0.0, chunk][1] == pytest.approx(every[1], rel=1e-12)
