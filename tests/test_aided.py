"""The GNSS-velocity-aided attitude filter (issue 50, imutool/attitude/aided.py): the velocity fixes as Kalman
measurements, velocity and accelerometer-bias states, σ that covers the error."""

from __future__ import annotations

import numpy as np
import pytest

from imutool.attitude import EkfParams
from imutool.attitude.aided import run_aided
from imutool.attitude.recording import gnss_inputs
from imutool.attitude.run import run_ekf
from imutool.filtering import run_filter
from imutool.sim import simulate

G = 9.80665
TURN_START, TURN_END = 40.0, 40.0 + 120.0 + 10.0  # the 360° turn at 3 °/s and its ramp


def voyage(bias=(0.05, -0.05, 0.05), seed: int = 5, **kw):
    """4 minutes of a bridge sensor (20 m above, 12 m aft of the roll centre; roll to 20° significant, heave 2 m,
    sway 1 m) with a good MEMS gyro, a 5 mg accelerometer bias on each axis and a 1 Hz receiver (3 cm/s), a 360°
    turn from 40 s."""
    base = dict(
        duration=240.0,
        seed=seed,
        lever_arm=(-12.0, 0.0, -20.0),
        roll_significant_deg=20.0,
        sway_m=1.0,
        heave_period=7.5,
        turn_start=TURN_START,
        accel_bias_mg=0.0,
        gyro_bias_rw_deg_s=0.0005,
        gnss_vel_noise_mps=0.03,
        gnss_columns="vel",
    )
    rec = simulate("ship-at-sea", **{**base, **kw})
    rec.channels["accel"] = rec["accel"] + np.asarray(bias)
    rec.meta["accel_bias_m_s2"] = list(bias)
    return rec


PRM = EkfParams(gnss_velocity_noise=0.03, aided_gyro_bias_rw=float(np.radians(0.0005)))  # the gyro's figure told


@pytest.fixture(scope="module")
def biased():
    rec = voyage()
    out = run_filter(rec, params=PRM, lever_arm=np.array(rec.meta["lever_arm_m"]))
    return rec, out


def test_the_bias_is_learned_in_a_turn_and_the_tilt_after_it_meets_the_bound(biased):
    rec, res = biased
    out = res.recording
    t = rec.time - rec.time[0]
    after = t > TURN_END
    er, ep = (out["roll"] - rec["ref_roll"])[after], (out["pitch"] - rec["ref_pitch"])[after]
    # measured 0.044° / 0.036° (smoothed, the gyro's bias instability told; the filter's σ 0.042°). Before the
    # lever term's attitude Jacobian (issue 50's unmodelled error) this seed gave 0.015 / 0.012 with that same σ —
    # its luckiest of seeds 0–9 (their mean 0.044 / 0.032, worst 0.086; now mean 0.037 / 0.032, worst 0.084)
    assert np.sqrt(np.mean(er**2)) <= 0.06 and np.sqrt(np.mean(ep**2)) <= 0.06
    assert np.abs(er).max() <= 0.1 and np.abs(ep).max() <= 0.1
    err = np.abs(out["accel_bias"][-1] - np.array(rec.meta["accel_bias_m_s2"])) / G * 1e3  # mg (0.60 / 0.77 / 0.47)
    assert np.all(err < 1.0), err  # the issue's 1 mg after a 360° turn (seeds 0–9: worst 1.38 mg, before 1.57)
    s = res.summary["aided"]
    assert s["velocity_fixes"] > 200 and s["held_rows_skipped"] > 20000 and s["velocity_rejected"] <= 10
    assert s["smoothed"] is True


@pytest.fixture(scope="module")
def forward(biased):
    rec, _ = biased
    prm = EkfParams(gnss_velocity_noise=0.03, aided_gyro_bias_rw=PRM.aided_gyro_bias_rw, aided_smoother=False)
    return run_filter(rec, params=prm, lever_arm=np.array(rec.meta["lever_arm_m"]))


def test_forward_pass_bias_sigma_shrinks_in_the_turn(biased, forward):
    """The forward pass: before the turn the horizontal bias is not observable, its σ says so and shrinks in the
    turn; the smoothed σ before the turn is the one after it (the turn seen from the whole voyage)."""
    rec, smoothed = biased
    t = rec.time - rec.time[0]
    sd = forward.recording["accel_bias_std"]
    i0, i1 = np.searchsorted(t, TURN_START), np.searchsorted(t, TURN_END)
    assert sd[i0, 0] > 2.5e-2 and sd[-1, 0] < 0.5 * sd[i0, 0] and sd[i1, 0] < 0.6 * sd[i0, 0]
    ss = smoothed.recording["accel_bias_std"]
    assert ss[i0, 0] < 0.6 * sd[i0, 0] and abs(ss[i0, 0] - ss[-1, 0]) < 0.3 * ss[-1, 0]
    np.testing.assert_allclose(ss[-1], sd[-1], rtol=1e-6)  # the last node: smoothed = forward


def test_the_smoother_carries_the_turns_bias_back_before_it(biased, forward):
    """Offline the whole voyage is known: the bias the turn reveals corrects the tilt before the turn too (the
    forward pass carries the bias's tilt there), and the bias estimate is the same along the voyage."""
    rec, smoothed = biased
    t = rec.time - rec.time[0]
    before = (t >= 20.0) & (t < TURN_START)
    err = {}
    for name, res in (("forward", forward), ("smoothed", smoothed)):
        out = res.recording
        e = np.concatenate([(out["roll"] - rec["ref_roll"])[before], (out["pitch"] - rec["ref_pitch"])[before]])
        err[name] = np.sqrt(np.mean(e**2))
    # measured 0.049 / 0.37 (before the lever term's Jacobian 0.010 / 0.38, this seed's luck: seeds 0–9 had a mean
    # of 0.071 and a worst of 0.267; now 0.041 and 0.068)
    assert err["smoothed"] < 0.07 and err["smoothed"] < 0.2 * err["forward"], err
    ba = smoothed.recording["accel_bias"]
    truth = np.array(rec.meta["accel_bias_m_s2"])
    assert np.abs(ba[before] - truth).max() / G * 1e3 < 1.0  # mg, as at the end


def test_the_sigma_covers_the_error_before_and_after_the_turn(biased):
    """|error| ≤ 2σ on 90–98 % of the samples, the unobservable bias before the turn included (without its state
    the EKF's σ covered 60 % there)."""
    rec, res = biased
    out = res.recording
    t = rec.time - rec.time[0]
    scored = t >= 20.0
    e = np.concatenate([(out["roll"] - rec["ref_roll"])[scored], (out["pitch"] - rec["ref_pitch"])[scored]])
    s = np.concatenate([out["roll_std"][scored], out["pitch_std"][scored]])
    share = np.mean(np.abs(e) <= 2 * s)
    # a bias-dominated error is nearly constant, so the share is near 0 or 1 on one voyage; the σ must cover it,
    # and not by inflating (the tilt's σ after the turn is measured 0.042°; RMS of error/σ 1.04)
    assert share >= 0.90, share
    assert np.mean(out["roll_std"][t > TURN_END]) < 0.06


def test_without_the_aided_filter_the_tilt_carries_the_bias(biased):
    """The same voyage with the aided filter off (the EKF's velocity aiding alone): the bias stays in the tilt."""
    rec, _ = biased
    off = run_filter(rec, params=EkfParams(aided=False), lever_arm=np.array(rec.meta["lever_arm_m"])).recording
    after = rec.time - rec.time[0] > TURN_END
    ep = (off["pitch"] - rec["ref_pitch"])[after]
    assert np.sqrt(np.mean(ep**2)) > 0.15
    assert "accel_bias" not in off.channels


@pytest.mark.parametrize(("seed", "heave", "bias_z"), [(1, 2.0, 1.0), (3, 2.0, 1.0), (1, 0.0, 1.5)])
def test_noise_free_voyage_errors_fall_inside_sigma(seed, heave, bias_z):
    """Every sensor error-free but a known 5 mg accelerometer bias, a 10 Hz receiver, the filter told nothing of the
    gyro (its bias may wander): what is left is the model's own error, which must lie inside the filter's σ. The lever
    term R (ω × r) (20 m, roll rates of 0.2 rad/s: ~4 m/s) turns with the attitude error; without that Jacobian in H
    the filter was overconfident (bias 3.1 σ off, pitch 4–14 σ on seeds 1 and 3; now ≤ 0.8 σ and ≤ 1.1 σ). Without
    heave (the MRU grid's cell whose pitch is worst) likewise: seed 1 1.11 σ and 1.34 σ; over seeds 0–5 the bias is
    within 1.17 σ and the tilt within 1.34 σ at heave 0, within 1.14 σ and 1.38 σ at 2 m — no model error there."""
    rec = simulate(
        "ship-at-sea",
        duration=240.0,
        seed=seed,
        lever_arm=(-12.0, 0.0, -20.0),
        roll_significant_deg=20.0,
        sway_m=1.0,
        heave_m=heave,
        heave_period=7.5,
        turn_start=TURN_START,
        noise=0,
        gnss_rate_hz=10.0,
        gnss_columns="vel",
    )
    bias = np.array([0.05, -0.05, 0.05])
    rec.channels["accel"] = rec["accel"] + bias
    prm = EkfParams(gnss_velocity_noise=0.03, gnss_min_interval=0.05)
    out = run_filter(rec, params=prm, lever_arm=np.array(rec.meta["lever_arm_m"])).recording
    z = np.abs(out["accel_bias"][-1] - bias) / out["accel_bias_std"][-1]
    assert np.all(z <= bias_z), z
    scored = rec.time - rec.time[0] >= 20.0
    for ch in ("roll", "pitch"):
        e = np.abs(out[ch] - rec[f"ref_{ch}"])[scored]
        assert np.all(e <= 3.0 * out[f"{ch}_std"][scored]), (ch, np.max(e / out[f"{ch}_std"][scored]))


def test_heave_tells_tilt_from_bias_and_the_sigma_says_so():
    """The tilt error enters the velocity through the whole specific force (δv̇ = −[f_n×] ψ), the accelerometer bias
    does not: heave modulates f_n's vertical part (±1.4 m/s² at 2 m and 7.5 s), so its velocity is a tilt reference
    that the bias does not share. Less heave, less information: the smoothed bias σ of the issue's gyro (0.002 °/s/√s,
    where its wander limits the bias) is 1.72 / 1.70 mg at heave 0 and 1.46 / 1.45 at 3 m (measured); a Φ that took
    the vertical force for −g would lose this (the MRU grid's pitch at heave 0 is this limit, not a model error)."""
    prm = EkfParams(gnss_velocity_noise=0.03, aided_gyro_bias_rw=float(np.radians(0.002)))
    sig = {}
    for heave in (0.0, 3.0):
        rec = voyage(heave_m=heave, gyro_bias_rw_deg_s=0.002)
        out = run_filter(rec, params=prm, lever_arm=np.array(rec.meta["lever_arm_m"])).recording
        sig[heave] = out["accel_bias_std"][-1] / G * 1e3
    assert np.all(sig[3.0][:2] < 0.9 * sig[0.0][:2]), sig
    assert sig[0.0][0] < 2.1  # the turn alone (the idealised limit of a level platform: 1.7 mg)


def _issue_voyage(**changes):
    """The issue's 600-s voyage (bridge 20 m up, 12 m aft; roll 20°; sway 1 m; heave at 7.5 s; a turn from 180 s;
    1 Hz GNSS velocity at 3 cm/s), with ``changes`` to the simulator's settings."""
    settings = dict(
        duration=600.0,
        seed=0,
        lever_arm=(-12.0, 0.0, -20.0),
        roll_significant_deg=20.0,
        sway_m=1.0,
        heave_period=7.5,
        turn_start=180.0,
        gnss_vel_noise_mps=0.03,
        gnss_columns="vel",
    )
    return simulate("ship-at-sea", **{**settings, **changes})


@pytest.fixture(scope="module")
def poor_gyro():
    """The issue's voyage with the poor gyro (bias wandering 0.01 °/s/√s), 5 mg per axis, 1 Hz at 3 cm/s."""
    rec = _issue_voyage(accel_bias_mg=0.0, gyro_bias_rw_deg_s=0.01)
    rec.channels["accel"] = rec["accel"] + np.array([0.05, -0.05, 0.05])
    return rec


def test_a_gyro_worse_than_stated_widens_its_bias_instability_instead_of_giving_up(poor_gyro):
    """The issue's voyage with the poor gyro (bias wandering 0.01 °/s/√s) and the filter not told (default 0.0023):
    the aided pass diverges (4–6 restarts) and its output used to be dropped for the EKF's (0.44° / 0.62° RMS after
    the turn on seeds 0–2). Re-run with the bias instability × 4 it follows the gyro (0.15 / 0.09), says so in the
    summary and in a warning; a smoothed track, which is not the hull's velocity, still falls back to the EKF."""
    rec = poor_gyro
    res = run_filter(rec, params=EkfParams(gnss_velocity_noise=0.03), lever_arm=np.array(rec.meta["lever_arm_m"]))
    a = res.summary["aided"]
    assert "not_used" not in a and a["rows_used"] > 0.8 * len(rec), a
    assert a["gyro_bias_rw_used"] == pytest.approx(4 * EkfParams().aided_gyro_bias_rw)
    assert any("state the gyro's figure" in w for w in res.summary["warnings"])
    after = rec.time - rec.time[0] > 180.0 + 130.0
    out = res.recording
    for ch in ("roll", "pitch"):  # measured 0.103 / 0.107 (told the figure 0.100 / 0.118; the EKF alone 0.83 / 0.40)
        assert np.sqrt(np.mean((out[ch] - rec[f"ref_{ch}"])[after] ** 2)) < 0.2, ch


@pytest.fixture(scope="module")
def smoothed_track():
    """The issue's voyage with the receiver's track-smoothed velocity (no sway, no yaw: not the hull's)."""
    return _issue_voyage(speed_source="smoothed")


def test_a_track_smoothed_velocity_still_falls_back_to_the_ekf(smoothed_track):
    """The receiver's track-smoothed velocity diverges at every width: the EKF's output, as before the widening (the
    MRU grid's "SOG/COG smoothed" cell)."""
    rec = smoothed_track
    a = run_filter(rec, params=EkfParams(gnss_velocity_noise=0.03), lever_arm=np.array(rec.meta["lever_arm_m"]))
    a = a.summary["aided"]
    assert a["rows_used"] == 0 and "also with the gyro bias instability × 16" in a["not_used"], a


def test_a_streamed_run_carries_the_widened_instability(poor_gyro, tmp_path):
    """Streamed in chunks (forward only), the widening happens in the first chunk that restarts and its width is
    carried in the state: the same rows as the forward pass in memory."""
    from formats import read, write

    src = tmp_path / "poor.csv"
    write(poor_gyro, src)
    lever = np.array(poor_gyro.meta["lever_arm_m"])
    prm = EkfParams(gnss_velocity_noise=0.03, aided_smoother=False)
    mem = run_filter(src, lever_arm=lever, params=prm)
    streamed = run_filter(src, tmp_path / "s.csv", lever_arm=lever, params=prm, stream_mb=0.0, chunk_rows=20000)
    assert streamed.summary["aided"]["gyro_bias_rw_used"] == mem.summary["aided"]["gyro_bias_rw_used"]
    assert "not_used" not in streamed.summary["aided"]
    assert any("state the gyro's figure" in w for w in streamed.summary["warnings"])  # said as in memory
    np.testing.assert_allclose(read(tmp_path / "s.csv")["roll"], mem.recording["roll"], atol=1e-5)


def test_a_streamed_run_widens_at_most_as_far_as_one_run(smoothed_track, tmp_path):
    """A track-smoothed velocity diverges at every width; streamed in chunks, each chunk that restarts used to widen
    the carried width again (× 64 after three chunks): at most × 16 over the run, as in memory, and no note that it
    was used beside the summary's "not used"."""
    from formats import write

    rec = smoothed_track
    src = tmp_path / "smoothed.csv"
    write(rec, src)
    prm = EkfParams(gnss_velocity_noise=0.03, aided_smoother=False)
    lever = np.array(rec.meta["lever_arm_m"])
    a = run_filter(src, tmp_path / "s.csv", lever_arm=lever, params=prm, stream_mb=0.0, chunk_rows=20000).summary
    a = a["aided"]
    assert a["gyro_bias_rw_used"] <= 16 * prm.aided_gyro_bias_rw * (1 + 1e-12), a
    assert "not_used" in a and "note" not in a, a


def test_held_and_nan_separated_fixes_aid_alike():
    """A held velocity is one fix at its first row; the same fixes between NaN rows give the same result."""
    rec = voyage(duration=120.0)
    t, g, a = rec.time, rec["gyro"], rec["accel"]
    _, _, vel = gnss_inputs(rec)
    lever = np.array(rec.meta["lever_arm_m"])
    res, _ = run_ekf(t, g, a, rec["mag"], PRM, lever_arm=lever, velocity_ne=vel)
    held, _ = run_aided(t, g, a, vel, res.q, res.bias, res.std, PRM, lever)
    start = np.concatenate([[True], np.any(np.diff(vel, axis=0) != 0, axis=1)])
    sparse = np.where(start[:, None], vel, np.nan)
    nan_sep, _ = run_aided(t, g, a, sparse, res.q, res.bias, res.std, PRM, lever)
    np.testing.assert_array_equal(held.q, nan_sep.q)
    assert held.summary["velocity_fixes"] == nan_sep.summary["velocity_fixes"] > 100
    # a held value counted at every row would make 100 fixes a second: the σ would collapse
    every = np.where(np.isfinite(vel), vel + 1e-9 * np.arange(len(t))[:, None], np.nan)
    over, _ = run_aided(t, g, a, every, res.q, res.bias, res.std, EkfParams(gnss_min_interval=0.05), lever)
    used = over.summary["velocity_fixes"] + over.summary["velocity_rejected"]
    assert used > 8 * held.summary["velocity_fixes"]


def test_a_chunked_run_equals_one_run():
    rec = voyage(duration=60.0)
    t, g, a = rec.time, rec["gyro"], rec["accel"]
    _, _, vel = gnss_inputs(rec)
    lever = np.array(rec.meta["lever_arm_m"])
    res, _ = run_ekf(t, g, a, rec["mag"], PRM, lever_arm=lever, velocity_ne=vel)
    one, _ = run_aided(t, g, a, vel, res.q, res.bias, res.std, PRM, lever, dt_nominal=0.01)
    k = 3217
    first, st = run_aided(t[:k], g[:k], a[:k], vel[:k], res.q[:k], res.bias[:k], res.std[:k], PRM, lever, 0.01)
    second, _ = run_aided(
        t[k:], g[k:], a[k:], vel[k:], res.q[k:], res.bias[k:], res.std[k:], PRM, lever, 0.01, state=st
    )
    np.testing.assert_array_equal(one.q, np.concatenate([first.q, second.q]))


def test_outliers_are_gated_and_counted():
    rec = voyage(duration=120.0)
    lever = np.array(rec.meta["lever_arm_m"])
    clean = run_filter(rec, params=PRM, lever_arm=lever).summary["aided"]["velocity_rejected"]
    vn = rec["vel_n"].copy()
    start = np.flatnonzero(np.concatenate([[True], np.diff(vn) != 0]))
    for j in range(50, 100, 10):  # five isolated fixes 3 m/s off, each held for its second
        vn[start[j] : start[j + 1]] += 3.0
    rec.channels["vel_n"] = vn
    res = run_filter(rec, params=PRM, lever_arm=lever)
    assert res.summary["aided"]["velocity_rejected"] == clean + 5
    t = rec.time - rec.time[0]
    er = (res.recording["roll"] - rec["ref_roll"])[t > 30]
    assert np.abs(er).max() < 1.0


def test_without_gnss_the_output_is_the_ekf_alone():
    """No GNSS velocity: the aided filter does not run, and the output is the EKF's, whatever its parameters."""
    rec = voyage(duration=60.0, speed_source="none")
    a = run_filter(rec, lever_arm=np.array(rec.meta["lever_arm_m"])).recording
    b = run_filter(rec, params=EkfParams(aided=False), lever_arm=np.array(rec.meta["lever_arm_m"])).recording
    for ch in ("roll", "pitch", "heading", "roll_std", "pitch_std"):
        np.testing.assert_array_equal(a[ch], b[ch])
    assert "accel_bias" not in a.channels


def test_calibrate_accel_bias_takes_the_estimate_and_applying_it_removes_the_tilt_bias(tmp_path):
    """The user's round trip on a sensor mounted upside down (sensor axes x,-y,-z of the body's): `filter` with the
    mounting estimates the bias in body axes, `calibrate accel-bias` writes it in sensor axes, and the EKF alone
    (no aided pass) run with that calibration no longer carries the bias's tilt (5 mg ≈ 0.29°)."""
    from click.testing import CliRunner

    import formats
    from calibration.file import load_calibration
    from imutool.cli import cli

    body = (0.05, -0.05, 0.05)
    rec = voyage(bias=body)
    flip = np.array([1.0, -1.0, -1.0])  # x,-y,-z: its own inverse
    for ch in ("gyro", "accel", "mag"):
        rec.channels[ch] = rec[ch] * flip
    src, est, cal = tmp_path / "voyage.csv", tmp_path / "est.csv", tmp_path / "cal.toml"
    formats.write(rec, src)
    arm = ",".join(str(x) for x in rec.meta["lever_arm_m"])
    told = f"aided_gyro_bias_rw={PRM.aided_gyro_bias_rw}"
    common = ["--mounting", "x,-y,-z", f"--lever-arm={arm}", "--param", "gnss_velocity_noise=0.03", "-q"]

    def imutool(*args: str) -> None:
        r = CliRunner().invoke(cli, list(args))
        assert r.exit_code == 0, r.output

    imutool("filter", str(src), "-o", str(est), *common, "--param", told)
    imutool("calibrate", "accel-bias", str(est), "-o", str(cal))
    b = np.array(load_calibration(cal).sections["accel"]["bias"])
    np.testing.assert_allclose(b, np.array(body) * flip, atol=1e-2 * G * 0.1)  # within 1 mg, in sensor axes
    errs = {}
    for name, extra in (("raw", []), ("calibrated", ["--calibration", str(cal)])):
        out = tmp_path / f"ekf_{name}.csv"
        imutool("filter", str(src), "-o", str(out), *common, "--param", "aided=false", *extra)
        r = formats.read(out)
        t = r.time - r.time[0]
        after = t > TURN_END
        errs[name] = (np.mean((r["roll"] - r["ref_roll"])[after]), np.mean((r["pitch"] - r["ref_pitch"])[after]))
    raw, calibrated = np.abs(errs["raw"]), np.abs(errs["calibrated"])
    assert max(raw) > 0.15 and max(calibrated) < 0.3 * max(raw), errs
