"""Quaternion EKF: accuracy vs truth, honest sigmas (NEES), invariants, robustness, smoother, CLI, BROAD."""

import json
import re
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import run_main

import formats
from formats.errors import ImutoolError
from formats.frames import quat_to_euler, quat_to_matrix, wrap_deg180
from imutool.attitude import (
    F_ACC_USED,
    F_MAG_NEW,
    F_MAG_REJ,
    F_MAG_USED,
    EkfParams,
    ekf_recording,
    initial_state,
    quat_error_metrics,
    rts_smooth,
    run_ekf,
    zero_lag_smooth,
)
from imutool.attitude.layout import S_NIS_A, S_QI, S_WY
from imutool.attitude.smoother import zero_phase_lp_kernel
from imutool.baseline import lpf_attitude
from imutool.sim import simulate


@pytest.fixture(scope="module")
def roll_rec():
    return simulate("ship-roll", duration=90, seed=7)


def _rmse(a, b, wrap=False):
    e = np.asarray(a) - np.asarray(b)
    if wrap:
        e = wrap_deg180(e)
    return float(np.sqrt(np.mean(e**2)))


def test_ship_roll_accuracy_beats_paper_and_lpf(roll_rec):
    est, _ = ekf_recording(roll_rec)
    lpf, _ = lpf_attitude(roll_rec, 0.5)
    ekf_rmse = _rmse(est["roll"], roll_rec["ref_roll"])
    lpf_rmse = _rmse(lpf["roll"], roll_rec["ref_roll"])
    assert ekf_rmse <= 0.4  # paper: 0.78°
    assert lpf_rmse > 3 * ekf_rmse
    assert _rmse(est["heading"], roll_rec["ref_heading"], wrap=True) < 1.0


def test_nees_and_invariants(roll_rec):
    res, _ = run_ekf(roll_rec.time, roll_rec["gyro"], roll_rec["accel"], roll_rec["mag"], EkfParams(), keep_cov=True)
    assert np.allclose(np.linalg.norm(res.q, axis=1), 1.0, atol=1e-9)
    P = res.cov[::500]
    assert np.allclose(P, np.transpose(P, (0, 2, 1)), atol=1e-15)
    assert np.all(np.linalg.eigvalsh(P) > 0)
    r, p, _ = (np.degrees(x) for x in quat_to_euler(res.q))
    sd = np.degrees(res.std)
    s = slice(len(r) // 10, None)
    nees = ((r - roll_rec["ref_roll"]) / sd[:, 0]) ** 2 + ((p - roll_rec["ref_pitch"]) / sd[:, 1]) ** 2
    assert 1.0 <= nees[s].mean() <= 4.0, nees[s].mean()
    sm = rts_smooth(res, roll_rec["gyro"], EkfParams())
    r2, p2, _ = (np.degrees(x) for x in quat_to_euler(sm.q))
    assert _rmse(r2, roll_rec["ref_roll"]) < 0.6 * _rmse(r, roll_rec["ref_roll"])


def test_updates_every_n_samples_are_the_same_filter(roll_rec):
    """The default updates at ≥ 50 Hz (every 4th sample at 200 Hz, every 2nd at 100 Hz, every sample with the raw
    accelerometer). The noise figures are per sample (an update stands for its n samples: R = σ²/n), so the
    estimate, its σ and the self-check are those of an update every sample. The scaling is what makes it so: with σ
    per update (as before) the roll σ at N = 4 is 1.5× that of N = 1. A magnetometer at half the IMU rate and
    accelerometer NaN rows on the update rows are used at the next usable sample, never aliased away."""
    t, g, a, m, ref = roll_rec.time, roll_rec["gyro"], roll_rec["accel"], roll_rec["mag"], roll_rec["ref_roll"]
    late = slice(len(t) // 3, None)

    def run(prm, a=a, m=m):
        res, _ = run_ekf(t, g, a, m, prm)
        roll = np.degrees(quat_to_euler(res.q)[0])
        return res, _rmse(roll, ref), np.median(res.std[late], axis=0)

    one, rmse1, sd1 = run(EkfParams(update_every=1))
    assert one.summary["update_every"] == 1
    for prm, n in ((EkfParams(), 4), (EkfParams(update_every=10), 10)):
        res, rmse, sd = run(prm)
        assert res.summary["update_every"] == n
        assert np.count_nonzero(res.flags & F_ACC_USED) == np.count_nonzero(res.flags & F_MAG_USED) == len(t) // n
        assert abs(rmse - rmse1) < 0.02, (n, rmse, rmse1)
        assert np.allclose(sd, sd1, rtol=0.03), (n, sd, sd1)  # roll, pitch, heading σ
        assert res.summary["inconsistent_samples"] == 0
    # the self-check's NIS is taken against σ², not the σ²/n of the update: with R = σ²/4 it would read ~4×
    nis1, nis4 = (run_ekf(t, g, a, m, EkfParams(update_every=n))[1][S_NIS_A] for n in (1, 4))
    assert nis4 == pytest.approx(nis1, rel=0.1), (nis4, nis1)
    d = EkfParams()
    per_update = replace(
        d,
        update_every=4,
        accel_noise=2 * d.accel_noise,
        accel_noise_gain=2 * d.accel_noise_gain,
        mag_noise_deg=40.0,
        rest_noise=2 * d.rest_noise,
    )  # σ per update: each ×√4
    assert run(per_update)[2][0] > 1.3 * sd1[0]
    a2, m2 = a.copy(), m.copy()
    a2[1::2] = np.nan  # every update row of N = 4 (rows 3, 7, ...) without an accelerometer sample
    m2[1::2] = np.nan  # a magnetometer at half the rate
    one, rmse1, sd1 = run(EkfParams(update_every=1), a2, m2)
    res, rmse, sd = run(EkfParams(), a2, m2)
    assert min(np.count_nonzero(res.flags & F_ACC_USED), np.count_nonzero(res.flags & F_MAG_USED)) >= len(t) // 5
    assert abs(rmse - rmse1) < 0.03 and np.allclose(sd, sd1, rtol=0.03), (rmse, rmse1, sd, sd1)
    # an interference at the update rate averages out over the samples an update stands for (read from one sample
    # it aliased into a constant error: 5 µT at 50 Hz on the magnetometer gave 9.3° of heading; a 50 Hz vibration
    # on a still gyro, 0.14 °/s of bias)
    mi = m.copy()
    mi[:, 0] += 5.0 * np.sin(2 * np.pi * 50.0 * t)
    head = np.degrees(quat_to_euler(run_ekf(t, g, a, mi)[0].q)[2])
    assert abs(wrap_deg180(head - roll_rec["ref_heading"])[late].mean()) < 0.3
    still = simulate("static", duration=120, seed=3)
    gi = still["gyro"].copy()
    gi[:, 2] += 0.02 * np.sin(2 * np.pi * 50.0 * still.time)
    bias = run_ekf(still.time, gi, still["accel"], still["mag"])[0].bias[-1, 2]
    assert abs(np.degrees(bias - still["ref_gyro_bias"][-1, 2])) < 0.03
    half = run_ekf(t[::2], g[::2], a[::2], m[::2])[0]  # 100 Hz
    assert half.summary["update_every"] == 2
    raw = run_ekf(t, g, a, m, EkfParams(accel_lp_tau=0.0, accel_noise_gain=0.0))[0]
    assert raw.summary["update_every"] == 1  # one raw sample is not an average of N


def test_multirate_paper_schedule(roll_rec):
    est, s = ekf_recording(roll_rec, EkfParams(update_every=40))
    assert s["updates"] == len(roll_rec) // 40
    assert _rmse(est["roll"], roll_rec["ref_roll"]) < 0.78  # no worse than the paper's figure


def test_turn_with_gnss_compensation():
    rec = simulate("turn", duration=100, seed=4, straight_s=15, ramp_s=5)
    late = rec.time > 40
    est, s = ekf_recording(rec)
    assert s["gnss_compensation"]
    acc_only, _ = lpf_attitude(rec, None)
    assert np.abs(est["roll"][late] - rec["ref_roll"][late]).max() < 1.0
    assert np.abs(acc_only["roll"][late] - rec["ref_roll"][late]).mean() > 2.0


def _lag_matrix(st: np.ndarray) -> np.ndarray:
    """M = R_Iᵀ W from a filter state: the low-passed measurement's tilt error per unit gyro-bias error (s)."""
    return quat_to_matrix(st[S_QI : S_QI + 4]).T @ st[S_WY : S_WY + 9].reshape(3, 3)


def test_the_low_pass_lag_of_a_bias_error_is_modelled():
    """The low-pass in the gyro-integrated frame delays gravity's apparent drift by τ, so a bias error δb shows in
    the measurement as a tilt of M·δb: M = τ·I on a still sensor; about a horizontal axis it averages out when the
    body spins about the vertical (the drift turns with the body), to the low-pass's |(1 − H(jω))/jω| at the spin.
    With M in H the bridge sensor's roll error is lower on every summary of eight seeds (start-up above all), and
    it fails without the term."""
    tau = EkfParams().accel_lp_tau
    rec = simulate("static", duration=30, seed=0)
    _, st = run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"])
    assert np.allclose(_lag_matrix(st), tau * np.eye(3), atol=0.01 * tau)
    n = 6000
    t, g = np.arange(n) / 200.0, np.zeros((n, 3))
    g[:, 2] = 2.0  # 2 rad/s about the vertical
    _, st = run_ekf(t, g, np.tile([0.0, 0.0, -9.81], (n, 1)), None)
    m = _lag_matrix(st)
    wc, jw = np.sqrt(2) / tau, 2.0j  # the Butterworth's cut-off (rad/s); the spin
    g_spin = abs((jw + np.sqrt(2) * wc) / (jw * jw + np.sqrt(2) * wc * jw + wc * wc))  # |(1 − H)/s| at 2 rad/s
    assert abs(np.hypot(m[0, 0], m[0, 1]) - g_spin) < 0.02 * g_spin and g_spin < 0.25 * tau
    assert abs(m[2, 2] - tau) < 0.01 * tau
    a = rec["accel"].copy()
    a[1::2] = np.nan  # every other row skips the low-pass, whose content then ages twice as long per update
    _, st = run_ekf(rec.time, rec["gyro"], a, rec["mag"])
    assert np.allclose(_lag_matrix(st), 2 * tau * np.eye(3), atol=0.01 * tau)  # τ·I if skipped rows were lost
    rms = {True: [], False: []}
    for seed in range(8):
        r = simulate("ship-roll", duration=90, seed=seed)
        for lag in rms:
            res, _ = run_ekf(r.time, r["gyro"], r["accel"], r["mag"], EkfParams(accel_lp_lag=lag), keep_cov=False)
            rms[lag].append(_rmse(np.degrees(quat_to_euler(res.q)[0]), r["ref_roll"]))
    # measured 0.382 vs 0.436 and 0.545 vs 0.657 (τ 2.5 s; with two first-order stages of τ 3 s: 0.381 vs 0.511,
    # 0.609 vs 0.939 — a shorter delay leaves less for the term to model)
    assert np.mean(rms[True]) < 0.92 * np.mean(rms[False]), rms
    assert max(rms[True]) < 0.88 * max(rms[False]), rms


def test_gyro_scale_noise_is_tilt_only():
    """The rate-proportional (scale-factor) process noise widens the tilt's σ, not the heading's: the heading
    has its own (heading_scale_noise), and the magnetometer must not be trusted less because the body turns."""
    rec = simulate("ship-roll", duration=60, seed=3)
    sd = {}
    for gs in (0.0, 0.01):
        res, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"], EkfParams(gyro_scale_noise=gs))
        sd[gs] = np.degrees(res.std[len(rec) // 2 :]).mean(axis=0)
    ratio = sd[0.01] / sd[0.0]
    assert ratio[0] > 1.1 and ratio[1] > 1.1, ratio  # roll, pitch: measured 1.20, 1.16
    assert abs(ratio[2] - 1.0) < 0.005, ratio  # heading: 1.0006 (isotropic noise gave 1.05)


def test_the_smoother_restarts_its_low_pass_after_a_gap():
    """The zero-phase low-pass of the smoother restarts after a data gap, as the filter's does: carried across a
    2 s gap on a rolling ship it put 1.6° of roll error into the 3 s after it (0.62° in the rest of the run)."""
    rec = simulate("ship-roll", duration=40, seed=2, jitter_s=0.0005)
    keep = np.ones(len(rec), bool)
    keep[3000:3400] = False
    rec = rec.select(keep)
    res, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"], keep_cov=True)
    sm = zero_lag_smooth(res, rec["gyro"], rec["accel"], rec["mag"])
    r = np.degrees(quat_to_euler(sm.q)[0])
    assert _rmse(r[3000:3600], rec["ref_roll"][3000:3600]) < 0.4  # measured 0.18
    assert _rmse(r[3600:], rec["ref_roll"][3600:]) < 0.3  # 0.17


def test_nan_rows_gaps_and_shocks():
    rec = simulate("ship-roll", duration=40, seed=2, jitter_s=0.0005)
    keep = np.ones(len(rec), bool)
    keep[3000:3400] = False  # a 2 s gap
    rec = rec.select(keep)
    g, a, m = rec["gyro"].copy(), rec["accel"].copy(), rec["mag"].copy()
    g[100:110] = np.nan
    a[500:520] = np.nan
    m[700:800, 1] = np.nan
    a[5000:5005, 0] += 30.0  # a knock: ±30 m/s² for 25 ms each way (the velocity returns to zero, as a real one)
    a[5005:5010, 0] -= 30.0
    res, st = run_ekf(rec.time, g, a, m)
    assert np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.std))
    assert res.summary["gaps"] == 1 and res.summary["gyro_nan_samples"] == 10
    r = np.degrees(quat_to_euler(res.q)[0])
    # no shock gate by default: the quasi-inertial low-pass averages a physical shock out (a gate that drops
    # samples biases that average: on BROAD 16 it makes the filter diverge, docs/attitude.md)
    assert np.abs(r[5000:5600] - rec["ref_roll"][5000:5600]).max() < 1.0
    # the quasi-inertial low-pass restarts after the gap (its frame lost the gap's rotation): 0.38°; carried
    # across it, the 2 s of roll the frame missed stayed in the low-pass for τ: 1.37°
    assert _rmse(r[4000:], rec["ref_roll"][4000:]) < 0.5
    gated, _ = run_ekf(rec.time, g, a, m, EkfParams(accel_gate=15.0))  # the optional gate still flags them
    assert np.all(gated.flags[5000:5010] & 1)


def test_heading_only_mag_keeps_disturbance_out_of_roll():
    rec = simulate("ship-roll", duration=60, seed=5)
    m = rec["mag"].copy()
    m[6000:9000] += np.array([15.0, -10.0, 0.0])  # a magnet nearby, norm change small enough to pass the gate
    prm = EkfParams(mag_norm_gate=0, mag_dip_gate_deg=0)
    a, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"], prm)
    b, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], m, prm)
    ra, rb = (np.degrees(quat_to_euler(x.q)[0]) for x in (a, b))
    # the correction itself is vertical; only the vertical-bias update (tilted body) leaks, < 0.02°
    assert np.abs(ra - rb).max() < 0.02
    full = EkfParams(mag_norm_gate=0, mag_dip_gate_deg=0, mag_mode="full")
    c, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"], full)
    d, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], m, full)
    rc, rd = (np.degrees(quat_to_euler(x.q)[0]) for x in (c, d))
    assert np.abs(rc - rd).max() > 10 * np.abs(ra - rb).max()


def test_roll_and_pitch_do_not_depend_on_the_magnetometer():
    """With the magnetometer kept off the bias (mag_bias false), roll and pitch must be the same whether the
    magnetometer is there, disturbed (a magnet for 40 s), or absent: gravity cannot see heading, so heading
    information cannot change the tilt. The error-state reset after each tilt correction (_reset_cov) keeps
    the heading variance about the world vertical: measured 0.003° apart; without it 12.6° apart on this run."""
    rec = simulate("ship-at-sea", seed=3, duration=120)
    g, a, m = rec.get("gyro", "rad/s"), rec.get("accel", "m/s^2"), np.array(rec["mag"], dtype=float)
    md = m.copy()
    win = (rec.time > 30) & (rec.time < 70)
    md[win] += 0.4 * np.median(np.linalg.norm(m, axis=1)) * np.array([0.6, -0.7, 0.4])
    prm = EkfParams(mag_bias=False)
    none, _ = run_ekf(rec.time, g, a, None, prm)
    for mag in (m, md):
        res, _ = run_ekf(rec.time, g, a, mag, prm)
        assert np.degrees(quat_error_metrics(res.q, none.q)[2].max()) < 0.01
        assert np.degrees(quat_error_metrics(res.q, none.q)[1].max()) > 5.0  # the heading itself does differ


def test_streaming_chunks_equal_one_pass(roll_rec):
    n = 7000
    one, _ = run_ekf(roll_rec.time, roll_rec["gyro"], roll_rec["accel"], roll_rec["mag"])
    st = initial_state(roll_rec["accel"], roll_rec["mag"], EkfParams())
    parts = []
    for i in range(0, len(roll_rec), n):
        sl = slice(i, i + n)
        r, st = run_ekf(
            roll_rec.time[sl],
            roll_rec["gyro"][sl],
            roll_rec["accel"][sl],
            roll_rec["mag"][sl],
            state=st,
            dt_nominal=0.005,
        )
        parts.append(r.q)
    assert np.allclose(np.vstack(parts), one.q, atol=1e-12)


def test_initialisation_skips_leading_nan_rows_and_heading_stays_below_360():
    rec = simulate("ship-roll", duration=20, seed=3)
    acc, mag = rec["accel"].copy(), rec["mag"].copy()
    acc[:1500] = np.nan  # more than the first scan block
    mag[:2000, 1] = np.nan
    st = initial_state(acc, mag, EkfParams())
    ref = initial_state(rec["accel"][2000:], rec["mag"][2000:], EkfParams())
    assert np.array_equal(st, ref, equal_nan=True)  # the last GNSS velocity: NaN, none yet
    with pytest.raises(Exception, match="no valid accelerometer"):
        initial_state(np.full((5000, 3), np.nan), None, EkfParams())
    from imutool.attitude import result_recording

    res, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"])
    res.q[:] = np.array([np.cos(-1e-9), 0.0, 0.0, np.sin(-1e-9)])  # heading 359.9999999°
    h = result_recording(rec, res)["heading"]
    assert np.all((h >= 0) & (h < 360)) and np.all(h == 0.0)


@pytest.mark.slow
def test_cli_streamed_filter_equals_in_memory(tmp_path):
    """Large CSVs are filtered in chunks (parse, EKF and write overlapping in threads): the output must equal the
    in-memory run value for value (mounting applied in both), and a malformed row is counted, not fatal."""
    from imutool.cli import cli

    src = tmp_path / "roll.csv"
    formats.write(simulate("ship-roll", duration=40, seed=2), src)
    lines = src.read_text().splitlines(keepends=True)
    lines[3000] = "12.5,oops\n"  # one malformed row
    src.write_text("".join(lines))
    outs = {}
    for name, extra in (("memory", []), ("stream", ["--stream-mb", "0", "--chunk-rows", "997"])):
        outs[name] = tmp_path / f"{name}.csv"
        run = CliRunner().invoke(
            cli, ["filter", str(src), "-o", str(outs[name]), "--json", "--mounting", "x,-y,-z", *extra]
        )
        assert run.exit_code == 0, run.output
        summary = json.loads(run.stdout)
    assert summary["method"] == "ekf (streamed)" and summary["skipped_rows"] == 1
    a, b = formats.read(outs["memory"]), formats.read(outs["stream"])
    assert len(a) == len(b) == 8000
    assert a.meta["csv_decimals"]["roll"] == 6
    for ch in ("roll", "pitch", "heading", "q", "gyro_bias", "roll_std", "heading_std", "accel_rejected", "ref_roll"):
        assert np.array_equal(a[ch], b[ch]), ch


def test_cli_filter_and_evaluate(tmp_path):
    from imutool.cli import cli

    src = tmp_path / "roll.csv"
    formats.write(simulate("ship-roll", duration=30, seed=1), src)
    out = tmp_path / "est.csv"
    run = CliRunner().invoke(cli, ["filter", str(src), "-o", str(out), "--json"])
    assert run.exit_code == 0, run.output
    est = formats.read(out)
    for c in ("roll", "roll_std", "q", "gyro_bias", "accel_rejected", "mag_rejected", "ref_roll"):
        assert c in est.channels
    ev = CliRunner().invoke(cli, ["evaluate", str(out), "--reference", str(src), "--json", "--max-lag", "0.5"])
    assert ev.exit_code == 0, ev.output
    s = json.loads(ev.stdout)
    assert s["angles"]["roll"]["rmse"] < 1.0 and "snr_db" in s["angles"]["roll"]
    bad = CliRunner().invoke(cli, ["filter", str(src), "-o", str(tmp_path / "x.csv"), "--update-every", "-1"])
    assert bad.exit_code == 2 and "update-every" in bad.output


BROAD = [
    "02_undisturbed_slow_rotation_B",
    "05_undisturbed_slow_rotation_with_breaks_B",
    "07_undisturbed_fast_rotation_B",
    "24_disturbed_tapping_A",
]


def test_broad_real_data_meets_vqf(shared):
    """The four BROAD trials the first defaults were tuned on, now scored with the defaults chosen on all 16: mean
    causal total within VQF's 1.45°, inclination within 0.02° of VQF's 0.60° (reached: 1.28° / 0.603°; the
    all-16 test below is the one that decides). The smoother must do better still."""
    from imutool.metrics import evaluate_quaternion

    causal, smoothed = [], []
    for trial in BROAD:
        rec = formats.read(shared("broad", f"{trial}.csv"))
        moving = rec["movement"] > 0
        res, _ = run_ekf(rec.time, rec.get("gyro", "rad/s"), rec.get("accel", "m/s^2"), rec["mag"], keep_cov=True)
        m = evaluate_quaternion(res.q, rec["ref_q"], moving)
        causal.append((m["total"]["rmse"], m["inclination"]["rmse"]))
        sm = zero_lag_smooth(res, rec.get("gyro", "rad/s"), rec.get("accel", "m/s^2"), rec["mag"])
        m = evaluate_quaternion(sm.q, rec["ref_q"], moving)
        smoothed.append((m["total"]["rmse"], m["inclination"]["rmse"]))
    causal, smoothed = np.array(causal), np.array(smoothed)
    assert np.all(causal[:, 1] < 1.1) and np.all(causal[:, 0] < 2.0), causal
    assert causal[:, 1].mean() <= 0.62 and causal[:, 0].mean() <= 1.45, causal.mean(axis=0)
    assert np.all(smoothed < causal), (smoothed, causal)


def test_cli_gnss_from_nmea_file(tmp_path):
    """Turn without sog/cog columns: `--gnss x.nmea` (RMC/VTG speed and course) removes the centripetal error."""
    from formats.nmea import checksum
    from imutool.cli import cli

    rec = simulate("turn", duration=100, seed=4, straight_s=15, ramp_s=5)
    imu = formats.Recording(rec.time, {c: rec[c] for c in ("gyro", "accel", "mag", "ref_roll")})
    src = tmp_path / "imu.csv"
    formats.write(imu, src)
    lines = []
    for i in np.flatnonzero(np.diff(np.floor(rec.time), prepend=-1) > 0):  # 1 Hz fixes, alternating RMC / VTG
        kn, cog = rec["ref_sog"][i] / (1852 / 3600), rec["ref_cog"][i] % 360
        body = f"GPRMC,000000,A,,,,,{kn:.2f},{cog:.2f},010125,,,A" if i % 2 else f"GPVTG,{cog:.2f},T,,M,{kn:.2f},N,,K,A"
        lines.append(f"{rec.time[i]:.3f};A;${body}*{checksum(body)}")
    gnss = tmp_path / "gnss.nmea"
    gnss.write_text("\n".join(lines) + "\n")
    late = rec.time > 40
    errs = {}
    for name, extra in (("none", []), ("gnss", ["--gnss", str(gnss)])):
        out = tmp_path / f"{name}.csv"
        run = CliRunner().invoke(cli, ["filter", str(src), "-o", str(out), "--json", *extra])
        assert run.exit_code == 0, run.output
        assert json.loads(run.stdout)["gnss_compensation"] is (name == "gnss")
        est = formats.read(out)
        errs[name] = np.abs(est["roll"][late] - rec["ref_roll"][late]).max()
    assert errs["gnss"] < 1.0 < errs["none"], errs


def test_learned_accel_noise_and_raw_mode():
    """The online white-noise estimate finds the simulator's σ_f = g·rad(1.5°); shocks do not inflate it; the
    paper's raw-accelerometer update (accel_lp_tau = 0, fixed σ) still runs and is worse on roll than the default."""
    from imutool.attitude.layout import S_AVAR

    rec = simulate("ship-roll", duration=30, seed=3)
    a = rec["accel"].copy()
    a[3000:3005] += 40.0
    res, st = run_ekf(rec.time, rec["gyro"], a, rec["mag"])
    assert np.sqrt(st[S_AVAR]) == pytest.approx(9.80665 * np.radians(1.5), rel=0.05)
    raw, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"], EkfParams(accel_lp_tau=0, accel_noise_gain=0))
    clean, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"])
    s = rec.time > 10
    r_def, r_raw = (np.degrees(quat_to_euler(x.q)[0]) for x in (clean, raw))
    assert _rmse(r_def[s], rec["ref_roll"][s]) < _rmse(r_raw[s], rec["ref_roll"][s])


# ------------------------------------------------------------ issue 13: robustness on motion never tuned on


def _roll_pitch_err(res, rec, after_s: float) -> tuple[np.ndarray, np.ndarray]:
    r, p, _ = (np.degrees(x) for x in quat_to_euler(res.q))
    late = rec.time > rec.time[0] + after_s
    return r[late] - rec["ref_roll"][late], p[late] - rec["ref_pitch"][late]


def test_ship_at_sea_bridge_sensor_meets_msc363_with_lever_arm_and_gnss():
    """Bridge sensor 20 m above and 30 m aft of the roll centre, irregular roll to 19°, heave ±2 m, a 360° turn at
    3 °/s and 8 m/s: with --lever-arm and SOG/COG, roll and pitch RMSE ≤ 0.5° and |error| ≤ 1.0° after the first
    minute (MSC.363(92)); without the lever arm the same filter misses that by far (what the lever arm buys)."""
    rec = simulate("ship-at-sea", duration=300, seed=3, turn_start=100)
    r = np.array(rec.meta["lever_arm_m"])
    res, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"], None, rec["sog"], rec["cog"], lever_arm=r)
    er, ep = _roll_pitch_err(res, rec, 60)
    assert _rmse(er, 0) <= 0.5 and np.abs(er).max() <= 1.0, (_rmse(er, 0), np.abs(er).max())
    assert _rmse(ep, 0) <= 0.5 and np.abs(ep).max() <= 1.0, (_rmse(ep, 0), np.abs(ep).max())
    no_lever, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"], None, rec["sog"], rec["cog"])
    er0, _ = _roll_pitch_err(no_lever, rec, 60)
    assert _rmse(er0, 0) > 2 * _rmse(er, 0) and np.abs(er0).max() > 1.5


def test_zero_lag_smoother_on_the_bridge_low_passes_the_compensated_force():
    """The smoother's second pass low-passes the specific force the filter compensated (lever arm, SOG/COG), not the
    raw accelerometer: on the bridge sensor its roll error after the first minute is below the causal filter's and
    the RTS pass's (measured 0.16° RMS vs 0.26° causal, 0.18° RTS alone); fed the raw force it would be 1.79°."""
    rec = simulate("ship-at-sea", duration=300, seed=3, turn_start=100)
    r = np.array(rec.meta["lever_arm_m"])
    res, _ = run_ekf(
        rec.time, rec["gyro"], rec["accel"], rec["mag"], None, rec["sog"], rec["cog"], lever_arm=r, keep_cov=True
    )
    assert not np.allclose(res.force, rec["accel"], atol=0.05)  # the lever arm and the turn were taken out
    sm = zero_lag_smooth(res, rec["gyro"], rec["accel"], rec["mag"], None, rec["sog"], rec["cog"], r)
    rts = rts_smooth(res, rec["gyro"])
    er, ep = _roll_pitch_err(sm, rec, 60)
    assert _rmse(er, 0) <= 0.2 and np.abs(er).max() <= 0.8, (_rmse(er, 0), np.abs(er).max())
    assert _rmse(ep, 0) <= 0.15, _rmse(ep, 0)
    assert _rmse(er, 0) < _rmse(_roll_pitch_err(rts, rec, 60)[0], 0) < _rmse(_roll_pitch_err(res, rec, 60)[0], 0)
    assert np.array_equal(sm.flags, res.flags)  # the self-check stays the causal run's
    # gravity observes no heading: the heading and its σ are the first RTS pass's, only the inclination is new
    # (BROAD's split of the difference sm ⊗ rts*: no rotation about the world vertical, some about the horizontal)
    from imutool.attitude import quat_error_metrics

    _, heading, incl = quat_error_metrics(sm.q, rts.q)
    assert np.degrees(heading).max() < 1e-6 and np.degrees(incl).max() > 0.05, np.degrees(heading).max()
    assert np.array_equal(sm.std[:, 2], rts.std[:, 2])


def test_smoother_that_cannot_fit_in_memory_is_refused_in_one_line(tmp_path, monkeypatch, capsys):
    """`filter --smooth` keeps every sample's covariance (~1.4 kB/sample): where the memory available cannot hold
    it, one line naming the input and the need, exit 2, before anything is allocated or written."""
    import imutool.attitude.recording as att

    src = tmp_path / "roll.csv"
    formats.write(simulate("ship-roll", duration=20, seed=1), src)
    monkeypatch.setattr(att, "available_memory", lambda: 1_000_000)  # 1 MB free
    out = tmp_path / "sm.csv"
    code, _, err = run_main(["filter", src, "-o", out, "--smooth"], capsys)
    assert code == 2, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "roll.csv" in lines[0] and "4001 samples need about 6.0 MB" in lines[0], err
    assert not out.exists()
    monkeypatch.setattr(att, "available_memory", lambda: None)  # unknown (not Linux): no refusal
    code, _, err = run_main(["filter", src, "-o", out, "--smooth", "-q"], capsys)
    assert code == 0 and out.exists(), err


def test_zero_phase_lowpass_has_no_lag_follows_the_body_and_skips_missing_rows():
    """zero_phase_lp_kernel: (1) a tilted body spinning at 1 rad/s about z sees gravity turn in the body; in the
    gyro frame it is constant, so the low-pass returns it unchanged (a frame or transpose error would not); (2) a
    slow horizontal oscillation comes out without lag (the causal two-stage low-pass of the filter lags it by
    ≈ τ = 1.5 s); (3) a NaN row stays NaN and does not spread."""
    dt, tau = 0.01, 1.5
    t = np.arange(0, 60, dt)
    n = len(t)
    w = 1.0
    gyro = np.tile([0.0, 0.0, w], (n, 1))
    g0 = np.array([3.0, 0.0, -9.3])  # body at rest at t = 0, tilted
    ang = w * t  # body z turns by +ang: a fixed vector seen in the body turns by −ang
    f = np.stack([g0[0] * np.cos(ang), -g0[0] * np.sin(ang), np.full(n, g0[2])], axis=1)
    out = np.empty_like(f)
    zero_phase_lp_kernel(t, gyro, np.zeros((n, 3)), f, tau, 0.0, 1.0, out)
    assert np.abs(out - f).max() < 1e-6, np.abs(out - f).max()
    # (2) no rotation, x oscillates with a 20-s period
    x = np.sin(2 * np.pi * t / 20.0)
    f = np.stack([x, np.zeros(n), np.full(n, -9.8)], axis=1)
    f[3000] = np.nan
    zero_phase_lp_kernel(t, np.zeros((n, 3)), np.zeros((n, 3)), f, tau, 0.0, 1.0, out)
    mid = slice(1000, n - 1000)
    lags = np.arange(-300, 301)
    xc = [np.nansum(out[mid, 0] * np.roll(x, k)[mid]) for k in lags]
    assert abs(lags[int(np.argmax(xc))]) <= 2, lags[int(np.argmax(xc))]
    al = dt / (tau / 2 + dt)  # the filter's causal two stages, for comparison
    s1 = s2 = 0.0
    causal = np.empty(n)
    for k in range(n):
        s1 += al * (x[k] - s1)
        s2 += al * (s1 - s2)
        causal[k] = s2
    xc = [np.sum(causal[mid] * np.roll(x, k)[mid]) for k in lags]
    assert lags[int(np.argmax(xc))] >= 100  # 1 s or more behind: what the smoother removes
    assert np.isnan(out[3000]).all() and np.isfinite(out[2999]).all() and np.isfinite(out[3001]).all()


def test_lever_arm_cli_metadata_and_sign(tmp_path):
    """`filter --lever-arm` is recorded in the output; the wrong sign of the lever arm is worse than none; none
    given, it is estimated from the ship's motion (said on stderr) unless lever_arm_estimate=false."""
    from imutool.cli import cli

    rec = simulate("ship-at-sea", duration=200, seed=5, turn_rate_dps=0)
    src = tmp_path / "bridge.csv"
    formats.write(rec, src)
    x, y, z = rec.meta["lever_arm_m"]
    errs = {}
    cases = {
        "right": ["--lever-arm", f"{x},{y},{z}"],
        "estimated": [],
        "none": ["--param", "lever_arm_estimate=false"],
        "flipped": ["--lever-arm", f"{-x},{-y},{-z}"],
    }
    for name, extra in cases.items():
        out = tmp_path / f"{name}.csv"
        run = CliRunner().invoke(cli, ["filter", str(src), "-o", str(out), "-q", *extra])
        assert run.exit_code == 0, run.output
        assert ("no lever arm given: estimated" in run.output) == (name == "estimated"), run.output
        arm = extra[1] if extra and extra[0] == "--lever-arm" else None
        est = formats.read(out)
        late = est.time > 60
        errs[name] = _rmse(est["roll"][late], rec["ref_roll"][late])
        if arm:
            assert est.meta["lever_arm_m"] == pytest.approx([float(v) for v in arm.split(",")])
    assert errs["right"] < 0.5 < errs["none"] < errs["flipped"], errs
    assert errs["estimated"] < errs["right"] + 0.1, errs


@pytest.mark.parametrize("fault", ["flip_x", "scale_3"])
def test_self_check_says_when_the_filter_cannot_be_trusted(tmp_path, fault):
    """A recording built to break the filter (a gyro axis reversed, a gyro in the wrong unit
    scale): the self-check flags it — warning on stderr, spans in the JSON summary, a warning in the output's
    metadata and an `inconsistent` column. The same recording intact: no flag, no warning.

    With the error-state reset the gyro ×3 run is 27° RMS off in roll yet agrees with its own low-passed
    accelerometer (which rotates with the same wrong gyro), so no innovation check fires. Its tilt error is an
    oscillation at the roll period with zero mean, which the check of the vertical (the 20-s world-frame mean of the
    specific force) sees only through its correlation with the heading error: it read 4.0–5.1° on seeds 1–8 with
    the magnetometer's reference from the first sample, 2.5–3.7° (limit 3°) once the reference became the mean of
    the accepted field, with the same roll error. So the ×3 run is said by the gyro scale check (2.9× named, whole
    run: stderr, summary, metadata), not per sample. The reversed axis is said by the gyro axis check, which
    finds the axis whose reversal makes the gyro agree with gravity (whole run, the axis named); per sample only
    where the phase of the tilt error against the roll moves the vertical's 20-s mean: the check of the vertical
    read 4.4–5.1° on seeds 1–8 with two first-order low-pass stages, 3.2–3.7° with the Butterworth (limit 3°; seed 6
    here flags no sample), so a whole-run check that does not hang on the filter's phase says it."""
    from imutool.cli import cli

    rec = simulate("ship-roll", duration=90, seed=6)
    good = tmp_path / "good.csv"
    formats.write(rec, good)
    g = rec["gyro"].copy()
    g = {"flip_x": g * [-1, 1, 1], "scale_3": g * 3}[fault]
    bad_rec = rec.copy()
    bad_rec.channels["gyro"] = g
    bad = tmp_path / "bad.csv"
    formats.write(bad_rec, bad)
    for path, broken in ((good, False), (bad, True)):
        out = tmp_path / f"est_{path.stem}.csv"
        run = CliRunner().invoke(cli, ["filter", str(path), "-o", str(out), "--json"])
        assert run.exit_code == 0, run.output
        summary = json.loads(run.stdout)
        est = formats.read(out)
        if broken and fault == "scale_3":
            # said by the gyro scale check (whole run: stderr, summary, metadata), not per sample: see the docstring
            assert summary["gyro_scale_check"]["flagged"] and 2.5 < 1 / summary["gyro_scale_check"]["scale"] < 3.5
            assert "gyro scale check" in run.stderr and any("gyro scale check" in w for w in est.meta["warnings"])
        elif broken:
            c = summary["gyro_scale_check"]
            assert c["flagged"] and c["reversed_axes"] == "x" and c["discrepancy_deg"] > 10.0, c
            assert "gyro axis check: the gyro's x axis looks reversed" in run.stderr
            assert any("gyro axis check" in w for w in est.meta["warnings"])
            assert summary["tilt_check_max_deg"] > 3.0  # the vertical's largest error: beyond its limit
        else:
            assert summary["inconsistent_samples"] == 0 and "self-check" not in run.stderr
            assert est["inconsistent"].max() == 0
            assert summary["tilt_check_samples"] == 0 and summary["tilt_check_max_deg"] < 1.0
            assert "disagrees with gravity" not in run.stderr


def test_the_tilt_check_does_not_average_across_a_gap():
    """An intact bridge-sensor recording with 30 s missing in the middle: the world-frame mean restarts after the
    gap instead of collapsing onto the first sample after it (which flagged 228 samples 1–3 s after the gap, up to
    3.1°, before the restart), so the check of the vertical stays silent; the gap itself is counted."""
    rec = simulate("ship-at-sea", duration=180, seed=3)
    t = rec.time.copy()
    t[t > 90] += 30.0
    res, _ = run_ekf(t, rec["gyro"], rec["accel"], rec["mag"])
    assert res.summary["gaps"] == 1
    assert res.summary["tilt_check_samples"] == 0 and res.summary["tilt_check_max_deg"] < 3.0


def test_streamed_self_check_finds_the_same_samples_and_spans(tmp_path):
    """Streamed in chunks, the self-check flags the same samples as in memory, and its spans (flagged samples
    less than 1 s apart joined, across chunk edges) cover every in-memory span."""
    from imutool.cli import cli

    rec = simulate("ship-roll", duration=90, seed=1)  # flags 14 % of its samples (seed 6, none: see above)
    rec.channels["gyro"] = rec["gyro"] * [-1, 1, 1]
    src = tmp_path / "flip.csv"
    formats.write(rec, src)
    got = {}
    for name, extra in (("memory", []), ("streamed", ["--stream-mb", "0", "--chunk-rows", "5000"])):
        run = CliRunner().invoke(cli, ["filter", str(src), "-o", str(tmp_path / f"{name}.csv"), "--json", *extra])
        assert run.exit_code == 0, run.output
        got[name] = json.loads(run.stdout)
    assert got["streamed"]["inconsistent_samples"] == got["memory"]["inconsistent_samples"] > 1000
    # the check of the vertical carries its low-pass across chunks: the same samples, the same largest tilt
    assert got["streamed"]["tilt_check_samples"] == got["memory"]["tilt_check_samples"] > 1000
    assert got["streamed"]["tilt_check_max_deg"] == got["memory"]["tilt_check_max_deg"]
    for run in got.values():
        assert any("disagrees with gravity" in w for w in run["warnings"])
    # one accumulator (SelfCheck) for both: the streamed spans are the in-memory ones, run on across chunk edges
    assert got["streamed"]["inconsistent_spans_s"] == got["memory"]["inconsistent_spans_s"]
    assert len(got["memory"]["inconsistent_spans_s"]) > 0


@pytest.mark.parametrize("streamed", [pytest.param(False, marks=pytest.mark.slow), True])
def test_a_heading_without_its_magnetometer_is_said(tmp_path, streamed):
    """The field changes for good 40 s in (×1.3: a new mounting, steel nearby): the magnetometer is rejected from
    then on and the heading is the gyro's alone. That is said — on stderr, as spans in the JSON summary and in the
    output's metadata — in memory and streamed alike. The intact recording says nothing of it."""
    from imutool.cli import cli

    rec = simulate("ship-roll", duration=150, seed=1)
    changed = rec.copy()
    changed.channels["mag"] = np.where((rec.time > 40)[:, None], rec["mag"] * 1.3, rec["mag"])
    for name, r, broken in (("intact", rec, False), ("changed", changed, True)):
        src, out = tmp_path / f"{name}.csv", tmp_path / f"{name}_est.csv"
        formats.write(r, src)
        extra = ["--stream-mb", "0", "--chunk-rows", "7000"] if streamed else []
        run = CliRunner().invoke(cli, ["filter", str(src), "-o", str(out), "--json", *extra])
        assert run.exit_code == 0, run.output
        summary = json.loads(run.stdout)
        said = [w for w in formats.read(out).meta.get("warnings", []) if "magnetometer was rejected" in w]
        if broken:
            ((a, b),) = summary["mag_rejected_spans_s"]  # one span across the chunk edges, from the change to the end
            assert 40.0 <= a < 41.0 and b == pytest.approx(rec.time[-1])
            assert "magnetometer was rejected for 110 s" in run.stderr and len(said) == 1
        else:
            assert "mag_rejected_spans_s" not in summary and "magnetometer" not in run.stderr and not said


@pytest.mark.parametrize("streamed", [pytest.param(False, marks=pytest.mark.slow), True])
def test_sog_cog_without_a_magnetometer_heading_is_said(tmp_path, streamed):
    """Velocity aiding needs the heading: without a magnetometer nothing holds it, so only the speed is used,
    along the bow (gnss_heading_check; the velocity turned with the unheld heading gave 3.0° RMS on seed 0, along
    the bow 0.64°, with the magnetometer 0.09°). One warning,
    on stderr and in the output's metadata, in memory and streamed, also where the `mag` column is there but
    empty; none with the magnetometer, none without SOG/COG."""
    from imutool.cli import cli

    rec = simulate("ship-at-sea", duration=60, seed=0)
    nomag = rec.copy()
    del nomag.channels["mag"]
    nanmag = rec.copy()
    nanmag.channels["mag"] = np.full_like(rec["mag"], np.nan)  # the column is there, no field in it
    extra = ["--stream-mb", "0", "--chunk-rows", "2500"] if streamed else []
    for name, r, gnss, said in (
        ("with_mag", rec, [], False),
        ("no_mag", nomag, [], True),
        ("nan_mag", nanmag, [], True),
        ("no_mag_no_gnss", nomag, ["--no-gnss"], False),
    ):
        src, out = tmp_path / f"{name}.csv", tmp_path / f"{name}_est.csv"
        formats.write(r, src)
        run = CliRunner().invoke(cli, ["filter", str(src), "-o", str(out), *gnss, *extra])
        assert run.exit_code == 0, run.output
        key = "GNSS velocity without a heading"
        in_meta = [w for w in formats.read(out).meta.get("warnings", []) if key in w]
        assert (run.stderr.count(key) == 1 and len(in_meta) == 1) == said, run.stderr
        assert said or (key not in run.stderr and not in_meta)


def test_flag_spans_join_across_chunks_and_forget_short_ones():
    from imutool.attitude import FlagSpans

    t = np.arange(0.0, 100.0, 0.5)
    mask = ((t >= 10) & (t < 12)) | ((t >= 20) & (t < 40.5)) | ((t >= 41) & (t < 75)) | (t >= 90)
    spans = FlagSpans(min_s=30.0)
    for sl in (slice(0, 50), slice(50, 51), slice(51, 137), slice(137, None)):  # chunk edges inside spans
        spans.add(t[sl], mask[sl])
    assert spans.long_spans() == [(20.0, 74.5)]  # 40.5 → 41: a 0.5 s hole joins; 10–12 and 90–99.5 too short
    assert len(spans.spans) == 2  # the closed short span was dropped; only the last, still open one is kept
    whole = FlagSpans(min_s=9.0)
    whole.add(t, mask)
    assert whole.long_spans() == [(20.0, 74.5), (90.0, 99.5)]


def test_params_toml_round_trip_and_cli(tmp_path, capsys):
    """EkfParams is the one parameter set: TOML out and back equal; --params/--param/--save-params on the CLI;
    the parameters used are in the output metadata; unknown names and out-of-range values are one-line errors."""
    from imutool.attitude import PARAM_DOC
    from imutool.cli import cli

    p = EkfParams(mag_noise_deg=12.5, init_bias=(0.001, 0.0, -0.002), mag_mode="full", mag_bias=False)
    f = tmp_path / "ekf.toml"
    f.write_text(p.to_toml())
    assert EkfParams.from_toml(str(f)) == p
    assert set(PARAM_DOC) == set(vars(EkfParams()))  # every constant documented, nothing undocumented
    rec = simulate("ship-roll", duration=20, seed=1)
    src = tmp_path / "roll.csv"
    formats.write(rec, src)
    run = CliRunner().invoke(
        cli,
        [
            "filter",
            str(src),
            "-o",
            str(tmp_path / "e.csv"),
            "-q",
            "--params",
            str(f),
            "--param",
            "bias_rw=3e-5",
            "--save-params",
            str(tmp_path / "used.toml"),
        ],
    )
    assert run.exit_code == 0, run.output
    used = EkfParams.from_toml(str(tmp_path / "used.toml"))
    assert used.mag_noise_deg == 12.5 and used.bias_rw == 3e-5 and used.mag_mode == "full"
    assert formats.read(tmp_path / "e.csv").meta["filter"]["bias_rw"] == 3e-5
    for args, needle in (
        (["--param", "nonsense=1"], "nonsense"),
        (["--param", "gyro_noise=nan"], "gyro_noise"),
        (["--param", "accel_lp_tau=-1"], "accel_lp_tau"),
    ):
        code, _, err = run_main(["filter", src, "-o", tmp_path / "x.csv", *args], capsys)
        assert code == 2 and needle in err and len(err.strip().splitlines()) == 1
        assert not (tmp_path / "x.csv").exists()
    f.write_text("[ekf]\nmag_noise_deg = 'ten'\n")
    code, _, err = run_main(["filter", src, "-o", tmp_path / "y.csv", "--params", f], capsys)
    assert code == 2 and "mag_noise_deg" in err
    # a file saved before updates every N samples became the default pins N = 1, and one saved before the
    # magnetometer's σ became a density pins σ per sample (every saved file had both): kept, and each said once
    old = tmp_path / "old.toml"
    old.write_text("[ekf]\nupdate_every = 1\nmag_noise_deg = 20.0\n")
    code, out, err = run_main(["filter", src, "-o", tmp_path / "o1.csv", "--params", old, "--json"], capsys)
    assert code == 0 and json.loads(out)["update_every"] == 1
    assert "note:" in err and "update_every = 1" in err and "--update-every 0" in err
    assert "mag_noise_deg = 20" in err and "--param mag_noise_deg=0" in err and "mag_reference_tau = 0" in err
    assert "mag_new_time" in err and "mag_bias_gate" in err  # saved before the new-field acceptance and the gate
    assert err.count("note:") == 7  # and the motion model's, the lever-arm estimate's, the aided smoother's (v0)
    code, out, err = run_main(
        ["filter", src, "-o", tmp_path / "o2.csv", "--params", old, "--update-every", "0", "--json"], capsys
    )
    assert code == 0 and json.loads(out)["update_every"] == 4  # 200 Hz: every 4th
    assert "update_every = 1" not in err and err.count("note:") == 6 and "mag_noise_deg = 20" in err
    code, out, err = run_main(
        [
            "filter",
            src,
            "-o",
            tmp_path / "o2b.csv",
            "--params",
            old,
            "--update-every",
            "0",
            "--param",
            "mag_noise_deg=0",
        ],
        capsys,
    )
    assert code == 0 and err.count("note:") == 4 and "mag_new_time" in err
    last_release = tmp_path / "last_release.toml"  # saved with mag_heading_density, before mag_new_time
    last_release.write_text("[ekf]\nmag_heading_density = 1.2\nmag_noise_deg = 0.0\n")
    code, out, err = run_main(["filter", src, "-o", tmp_path / "o2c.csv", "--params", last_release], capsys)
    assert code == 0 and err.count("note:") == 4 and "mag_new_time" in err
    two_stage = tmp_path / "two_stage.toml"  # saved before the Butterworth: every key of its day, no smoother_lp_tau
    two_stage.write_text(
        "[ekf]\naccel_lp_tau = 3.0\ngyro_scale_noise = 0.003\naccel_noise_gain = 2.8\n"
        "mag_new_time = 20.0\nmag_heading_density = 1.2\nmag_noise_deg = 0.0\n"
    )
    code, out, err = run_main(["filter", src, "-o", tmp_path / "o2d.csv", "--params", two_stage], capsys)
    assert code == 0 and err.count("note:") == 4 and "Butterworth" in err and "has no smoother_lp_tau" in err
    code, out, err = run_main(
        ["filter", src, "-o", tmp_path / "o2e.csv", "--params", f.with_name("used.toml"), "--param", "accel_lp_tau=2"],
        capsys,
    )  # a file saved now, one override: no note
    assert code == 0 and "Butterworth" not in err
    meta = formats.read(tmp_path / "o2b.csv").meta["filter"]
    assert meta["mag_noise_deg"] == 0 and meta["mag_heading_density"] == EkfParams().mag_heading_density
    code, out, err = run_main(
        ["filter", src, "-o", tmp_path / "o3.csv", "--params", f.with_name("used.toml"), "--json"], capsys
    )
    # a file saved now carries its version: nothing in it predates a change, so nothing is said (it pins σ at 12.5
    # because its user chose to; an unversioned file that pins σ is told about the density, as above)
    assert code == 0 and json.loads(out)["update_every"] == 4
    assert "note:" not in err


def test_smooth_summary_reports_both_errors(tmp_path):
    """`filter --smooth` on a recording with truth: causal and smoothed RMSE are printed, and smoothing helps."""
    from imutool.cli import cli

    src = tmp_path / "roll.csv"
    formats.write(simulate("ship-roll", duration=40, seed=1), src)
    run = CliRunner().invoke(cli, ["filter", str(src), "-o", str(tmp_path / "s.csv"), "--smooth", "--json"])
    assert run.exit_code == 0, run.output
    gain = json.loads(run.stdout)["smoother_gain"]
    assert gain["smoothed_rmse_deg"]["roll"] < gain["causal_rmse_deg"]["roll"] < 1.0


BROAD_VQF = {  # VQF 2.1.2 causal 9D, default parameters, total / inclination RMSE (deg): ../shared/data/broad/MANIFEST
    "01": (1.99, 0.60),
    "02": (1.38, 0.43),
    "04": (1.07, 0.79),
    "05": (0.99, 0.35),
    "06": (4.03, 0.80),
    "07": (1.75, 1.02),
    "10": (1.80, 0.30),
    "11": (0.90, 0.42),
    "16": (0.74, 0.54),
    "21": (4.08, 1.72),
    "24": (1.55, 0.61),
    "26": (1.75, 0.56),
    "28": (4.04, 1.21),
    "29": (2.38, 1.06),
    "33": (3.75, 0.60),
    "35": (1.09, 0.66),
}


@pytest.mark.slow
def test_broad_all_16_trials_no_divergence(shared):
    """All 16 shared BROAD trials, one default parameter set (chosen on all of them and on the simulator, never on
    one file; benchmarks/attitude_broad.py). Issue 13's acceptance: no trial above the ceiling max(2 × VQF,
    VQF + 2°) (the old shock gate gave 129.9° on trial 16), causal mean total and inclination ≤ VQF's 2.08° /
    0.729° (1.96 / 0.727; 0.739° with two first-order low-pass stages), smoother mean total ≤ offline VQF's
    1.95°, smoother mean inclination at offline VQF's 0.53° (0.530° against 0.529° in the same run: the zero-lag
    smoother; the RTS pass alone gave 0.594°)."""
    from imutool.metrics import evaluate_quaternion

    folder = shared("broad")
    rows = []
    for f in sorted(folder.glob("*.csv")):
        rec = formats.read(f)
        gyro = rec.get("gyro", "rad/s")
        res, _ = run_ekf(rec.time, gyro, rec.get("accel", "m/s^2"), rec["mag"], keep_cov=True)
        # no false alarm on intact recordings: neither the innovation check nor the check of the vertical (the
        # 20-s world-frame mean force within 1.23° of it on all 16; its limit is 3°)
        assert res.summary["inconsistent_samples"] == 0 and res.summary["tilt_check_max_deg"] < 1.5, f.name
        moving = rec["movement"] > 0
        m = evaluate_quaternion(res.q, rec["ref_q"], moving)
        sm = zero_lag_smooth(res, gyro, rec.get("accel", "m/s^2"), rec["mag"])
        ms = evaluate_quaternion(sm.q, rec["ref_q"], moving)
        tot, inc = m["total"]["rmse"], m["inclination"]["rmse"]
        vt, vi = BROAD_VQF[f.name[:2]]
        rows.append(
            (
                tot,
                inc,
                tot / max(2 * vt, vt + 2),
                inc / max(2 * vi, vi + 2),
                ms["total"]["rmse"],
                ms["inclination"]["rmse"],
            )
        )
    r = np.array(rows)
    assert len(r) == 16
    assert r[:, 2:4].max() <= 1.0, r  # no trial above its ceiling
    assert r[:, 0].mean() <= 2.08 and r[:, 4].mean() <= 1.95, r.mean(axis=0)  # VQF / offline VQF totals
    assert r[:, 1].mean() <= 0.729, r.mean(axis=0)  # VQF's inclination
    assert r[:, 5].mean() <= 0.535 and r[:, 5].max() <= 1.0, r.mean(axis=0)  # smoother (offline VQF 0.529 / 0.96)


def _boxcar(x: np.ndarray, k: int) -> np.ndarray:
    n = (len(x) // k) * k
    return x[:n].reshape(-1, k, *x.shape[1:]).mean(axis=1)


# VQF 2.1.2 causal 9D, default parameters, per trial total / inclination RMSE (deg) on the 16 BROAD trials
# boxcar-averaged by 3 (95 Hz) and by 6 (48 Hz), truth at each block's last sample; the means 2.28 / 0.861 and
# 2.77 / 1.156 (`python benchmarks/attitude_broad.py --rates`)
BROAD_VQF_LOWER_RATES = {
    3: {
        "01": (1.97, 0.68),
        "02": (1.43, 0.45),
        "04": (1.16, 0.89),
        "05": (1.02, 0.38),
        "06": (4.20, 0.82),
        "07": (2.55, 1.05),
        "10": (1.79, 0.30),
        "11": (0.89, 0.42),
        "16": (0.74, 0.53),
        "21": (4.47, 2.46),
        "24": (1.60, 0.61),
        "26": (1.94, 0.57),
        "28": (4.79, 1.67),
        "29": (3.05, 1.31),
        "33": (3.73, 0.76),
        "35": (1.24, 0.88),
    },
    6: {
        "01": (1.98, 0.82),
        "02": (1.49, 0.51),
        "04": (1.30, 1.05),
        "05": (1.09, 0.44),
        "06": (4.75, 0.87),
        "07": (4.75, 1.48),
        "10": (1.77, 0.29),
        "11": (0.87, 0.41),
        "16": (0.93, 0.60),
        "21": (4.87, 3.82),
        "24": (1.67, 0.62),
        "26": (2.29, 0.59),
        "28": (6.16, 2.56),
        "29": (4.85, 2.15),
        "33": (3.77, 1.04),
        "35": (1.72, 1.24),
    },
}


@pytest.mark.slow
def test_broad_at_lower_sample_rates(shared):
    """Other recordings come at other rates. The 16 BROAD trials averaged down to 95 and 48 Hz (as a sensor with a
    lower output rate averages): the causal mean total and inclination stay at or below VQF's at the same rate, no
    trial goes above its ceiling, and no run diverges. Measured 2.12 / 0.852 (VQF 2.28 / 0.861) and 2.66 / 1.152
    (VQF 2.77 / 1.156); with two first-order low-pass stages of 3 s (before the Butterworth) 2.14 / 0.865 and
    2.71 / 1.170, the inclination above VQF's at both rates. With the magnetometer's σ fixed per sample (the old
    mag_noise_deg = 20) the 48 Hz total was 2.92, above VQF's: the heading's time constant grew from 21 s to 49 s
    (test_heading_follows_the_magnetometer_...)."""
    from imutool.metrics import evaluate_quaternion

    files = sorted(shared("broad").glob("*.csv"))
    trials = [formats.read(f) for f in files]
    assert len(trials) == 16
    for k, vqf in BROAD_VQF_LOWER_RATES.items():
        rows = []
        for f, rec in zip(files, trials, strict=True):
            t = rec.time[: (len(rec.time) // k) * k].reshape(-1, k)[:, -1]
            q_ref = rec["ref_q"][: len(t) * k].reshape(-1, k, 4)[:, -1]
            moving = (rec["movement"][: len(t) * k].reshape(-1, k)[:, -1]) > 0
            res, _ = run_ekf(
                t, _boxcar(rec.get("gyro", "rad/s"), k), _boxcar(rec.get("accel", "m/s^2"), k), _boxcar(rec["mag"], k)
            )
            assert res.summary["inconsistent_samples"] == 0, (k, f.name)
            m = evaluate_quaternion(res.q, q_ref, moving)
            tot, inc = m["total"]["rmse"], m["inclination"]["rmse"]
            vt, vi = vqf[f.name[:2]]
            assert tot <= max(2 * vt, vt + 2) and inc <= max(2 * vi, vi + 2), (k, f.name, tot, inc)
            rows.append((tot, inc, vt, vi))
        r = np.array(rows)
        assert r[:, 0].mean() <= r[:, 2].mean() and r[:, 1].mean() <= r[:, 3].mean(), (k, r.mean(axis=0))


@pytest.mark.slow
def test_broad_started_beside_steel(shared):
    """The 16 BROAD trials as if each recording had started beside steel: a world-fixed field added to the
    magnetometer over the first 10 s (the sensor is still then; BROAD's motion starts after 27–46 s;
    benchmarks/attitude_stress.py has both cases beside VQF).
    - 15 µT north, 10 µT up (the start's dip 24° flat, the heading right): the gates then reject the true field.
      With that rejection for the whole run (mag_new_time = 0) the mean total was 3.89° (worst 11.0°); the field
      is now taken as the reference once it has held for 5 s of turning (on all 16), 1.99° (intact 1.97°).
    - 20 µT east (the start's norm 10 % strong, its dip 11° flat; the heading starts ≈ 50° off): while the
      heading converged the
      magnetometer taught the gyro bias its error, and the turning put that into the tilt: mean inclination 0.91°
      with the bias learning ungated (mag_bias_gate = 0), 0.78° with the 3σ gate (intact 0.74°, VQF 0.73°). Its
      total, 8.7°, is VQF's 4.0° twice over: our heading is held to the first field while the sensor is still,
      VQF's takes no reference until the sensor turns (docs/attitude.md)."""
    from imutool.metrics import evaluate_quaternion

    files = sorted(shared("broad").glob("*.csv"))
    assert len(files) == 16
    rows = []
    for f in files:
        rec = formats.read(f)
        gyro, acc, q_ref = rec.get("gyro", "rad/s"), rec.get("accel", "m/s^2"), rec["ref_q"]
        first = rec.time < rec.time[0] + 10.0
        q0 = q_ref[first].copy()
        q0[~np.all(np.isfinite(q0), axis=1)] = q_ref[np.flatnonzero(np.all(np.isfinite(q_ref), axis=1))[0]]
        row = []
        for offset in ((15.0, 0.0, -10.0), (0.0, 20.0, 0.0)):
            m = np.array(rec["mag"], dtype=float)
            m[first] += np.einsum("nji,j->ni", quat_to_matrix(q0), np.array(offset))
            res, _ = run_ekf(rec.time, gyro, acc, m)
            e = evaluate_quaternion(res.q, q_ref, rec["movement"] > 0)
            row += [e["total"]["rmse"], e["inclination"]["rmse"], res.summary["mag_new_field"]]
        rows.append(row)
    r = np.array(rows)
    assert r[:, 0].mean() <= 2.2 and r[:, 0].max() <= 4.5 and np.sum(r[:, 2] > 0) >= 12, r  # 1.99 / 4.18 / 16
    assert r[:, 4].mean() <= 0.80, r  # 0.785


def test_broad_attached_magnet_6d_heading_does_not_follow_the_accelerometer(shared):
    """Trial 33 without the magnetometer: gravity observes no heading, so the accelerometer update must not move it
    (accel_heading = false). Before that projection the 6D heading swung by 260° within 50 s of fast motion (the
    linearised cross-covariance of a 20°-uncertain heading leaked into it); VQF 6D drifts 5.3° over the trial.
    Measured 7.9° before the error-state reset after tilt corrections and 8.6° with it (mean over the 16 trials
    6.4° → 7.1°, better on 5 of them; docs/attitude.md). The reset removes that leak at its root (the heading
    variance stays about the world vertical), so even without the projection (accel_heading = true) the heading
    now holds: 8.0° where it swung by 53.7° before the reset, so removing the reset fails here; the projection
    alone is tested in test_accel_update_leaves_heading_alone_in_6d."""
    rec = formats.read(shared("broad", "33_disturbed_attached_magnet_2cm.csv"))
    ok = np.isfinite(rec["ref_q"]).all(axis=1)
    qr = np.where(ok[:, None], rec["ref_q"], [1.0, 0, 0, 0])

    def drift(prm):
        res, _ = run_ekf(rec.time, rec.get("gyro", "rad/s"), rec.get("accel", "m/s^2"), None, prm)
        e = _heading_error_deg(res.q, qr)[ok]
        return np.abs(wrap_deg180(e - e[0])).max()

    assert drift(EkfParams(mag_mode="off")) <= 9.0
    assert drift(EkfParams(mag_mode="off", accel_heading=True)) <= 9.0  # the reset alone (30°+ without it)


def _heading_error_deg(q: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """Signed heading error (deg): the rotation about the world vertical of q ⊗ q_ref*."""
    from formats.frames import quat_multiply

    d = quat_multiply(q, q_ref * np.array([1.0, -1.0, -1.0, -1.0]))
    return wrap_deg180(np.degrees(2 * np.arctan2(d[:, 3], d[:, 0])))


def test_accel_update_leaves_heading_alone_in_6d():
    """Simulated sea state without a magnetometer: with the projected accelerometer update the gyro-only heading
    drifts half as much as with the raw EKF update (which lets tilt corrections leak into heading)."""
    rec = simulate("sea-state", duration=120, seed=1)
    qr = rec["ref_q"]

    def drift(ah):
        res, _ = run_ekf(
            rec.time,
            rec.get("gyro", "rad/s"),
            rec.get("accel", "m/s^2"),
            None,
            EkfParams(mag_mode="off", accel_heading=ah, init_heading_sigma_deg=30),
        )
        e = _heading_error_deg(res.q, qr)
        return np.abs(wrap_deg180(e - e[0])).max()

    projected, raw = drift(False), drift(True)
    assert projected <= 10.0 and projected <= 0.6 * raw, (projected, raw)


def test_magnetic_disturbance_is_a_state_not_a_sample():
    """40 s of a field turned by 40°: 9 samples in 10 are off in norm (gated), every 10th passes the gates. With the
    disturbance hold (default 0.5 s) those chance passes stay de-weighted: heading error ≤ 15° instead of ~40°."""
    rec = simulate("turn", duration=120, seed=3)
    t, m = rec.time, np.array(rec["mag"], dtype=float)
    win = (t > 40) & (t < 80)
    c, s = np.cos(np.radians(40)), np.sin(np.radians(40))
    md = m.copy()
    md[win, 0], md[win, 1] = c * m[win, 0] - s * m[win, 1], s * m[win, 0] + c * m[win, 1]
    md[win & (np.arange(len(t)) % 10 != 0)] *= 1.5

    def worst(hold):
        res, _ = run_ekf(
            t, rec.get("gyro", "rad/s"), rec.get("accel", "m/s^2"), md, EkfParams(mag_disturbance_hold=hold)
        )
        return np.abs(_heading_error_deg(res.q, rec["ref_q"])[win]).max()

    held, per_sample = worst(EkfParams().mag_disturbance_hold), worst(0.0)
    assert held <= 15.0 and per_sample >= 2.5 * held, (held, per_sample)


def _heading_follows_a_turned_field(
    rate_hz: float, prm: EkfParams, turn_deg: float = 15.0, first_second_scale: float = 1.0, mag_every: int = 1
) -> np.ndarray:
    """Fraction of a 15° turn of the earth's field about the vertical (norm and dip kept, so no gate sees it; at
    60 s of a rolling ship) that the heading has followed 5, 10 and 20 s later: the heading's time constant.
    ``first_second_scale``: the field's norm over the first second (a start beside steel); ``mag_every``: the
    magnetometer on every n-th row only (NaN between: a magnetometer slower than the IMU)."""
    rec = simulate("ship-roll", duration=90, seed=1, rate_hz=rate_hz)
    c = quat_to_matrix(rec["ref_q"])  # body → NED
    after = rec.time >= rec.time[0] + 60.0
    ct, st = np.cos(np.radians(turn_deg)), np.sin(np.radians(turn_deg))
    rz = np.array([[ct, -st, 0.0], [st, ct, 0.0], [0.0, 0.0, 1.0]])
    m = rec["mag"].copy()
    m[rec.time < rec.time[0] + 1.0] *= first_second_scale
    m[after] = np.einsum("nji,nj->ni", c[after], np.einsum("nij,nj->ni", c[after], m[after]) @ rz.T)
    m[np.arange(len(m)) % mag_every != 0] = np.nan
    res, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], m, prm)
    e = _heading_error_deg(res.q, rec["ref_q"])
    t = rec.time - rec.time[0]
    return np.array([abs(np.mean(e[(t >= 60 + s - 0.5) & (t < 60 + s + 0.5)])) / turn_deg for s in (5, 10, 20)])


def test_heading_follows_the_magnetometer_at_the_same_pace_at_any_rate():
    """The magnetometer's σ is a density (deg·√s; σ per sample = density / √dt of the magnetometer's own interval):
    its heading error is not white from sample to sample, so a faster magnetometer must not be trusted more per
    second. The heading then follows a field change at the same pace at 20, 50 and 200 Hz, and with the
    magnetometer on every 4th row of a 200 Hz IMU: with the gates' reference held at the first sample (to see the
    σ alone) 0.35 / 0.59 / 0.91 of the turn after 5 / 10 / 20 s at 200 Hz, within 0.02 in the others. With the old
    fixed σ per sample (mag_noise_deg = 20) the pace fell with the rate (0.34 → 0.29 after 5 s from 200 to 10 Hz;
    this test fails on it, and on a run that takes the IMU's interval for a slower magnetometer's); on BROAD
    averaged down to 48 Hz that cost 0.19° of total (test_broad_at_lower_sample_rates). Below ≈ 17 Hz the σ per
    sample is held at mag_heading_floor_deg (5°, one sample's white noise): a 1 Hz magnetometer with 2 µT of
    noise leaves the self-check silent (the density alone, 1.2° per sample there, flagged such runs)."""
    fixed_ref = EkfParams(mag_reference_tau=0.0)
    ref = _heading_follows_a_turned_field(200.0, fixed_ref)
    assert 0.3 < ref[0] < ref[1] < ref[2] < 1.05, ref  # it follows, with a time constant of seconds, not a step
    for rate in (50.0, 20.0):
        assert np.abs(_heading_follows_a_turned_field(rate, fixed_ref) - ref).max() <= 0.02, rate
    assert np.abs(_heading_follows_a_turned_field(200.0, fixed_ref, mag_every=4) - ref).max() <= 0.02
    old = EkfParams(mag_noise_deg=20.0, mag_reference_tau=0.0)
    assert (
        np.abs(_heading_follows_a_turned_field(10.0, old) - _heading_follows_a_turned_field(200.0, old)).max() >= 0.05
    )
    defaults = [_heading_follows_a_turned_field(rate, EkfParams()) for rate in (200.0, 20.0)]
    assert np.abs(defaults[0] - defaults[1]).max() <= 0.04, defaults
    # a slow, noisy magnetometer: σ per sample held at the floor, no false alarm
    rec = simulate("ship-roll", duration=120, seed=2, rate_hz=100.0)
    m = np.full_like(rec["mag"], np.nan)
    m[::100] = rec["mag"][::100] + np.random.default_rng(0).normal(0.0, 2.0, m[::100].shape)
    res, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], m)
    assert res.summary["inconsistent_samples"] == 0 and res.summary["heading_inconsistent_samples"] == 0
    res, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], m, EkfParams(mag_heading_floor_deg=0.0))
    assert res.summary["heading_inconsistent_samples"] > 0  # the density alone over-trusts it: the heading's check
    assert res.summary["inconsistent_samples"] == 0  # roll and pitch are not the magnetometer's (mag_mode heading)


def test_the_magnetometer_interval_and_its_sigma_per_sample():
    """σ per sample comes from the magnetometer's own interval: every 4th row of a 100 Hz IMU is 0.04 s; a 70 Hz
    magnetometer on 100 Hz rows (steps of 0.01 and 0.02 s) is 1/70 s, not the median 0.01 s; one lost row leaves
    a regular interval exact (a stream's first chunk and the whole file agree); no usable interval falls back to
    the IMU's. σ = density / √dt, held at the floor for a slow magnetometer, pinned by mag_noise_deg."""
    from imutool.attitude import mag_interval
    from imutool.attitude.layout import P_MAG_NOISE

    t = np.arange(10000) * 0.01
    m = np.ones((10000, 3))
    every4 = np.full_like(m, np.nan)
    every4[::4] = 1.0
    assert mag_interval(t, every4) == pytest.approx(0.04)
    at70 = np.full_like(m, np.nan)
    at70[np.unique(np.floor(np.arange(0, 10000, 100 / 70)).astype(int))] = 1.0
    assert mag_interval(t, at70) == pytest.approx(1 / 70, rel=2e-3)
    assert mag_interval(np.delete(t, 3000), np.ones((9999, 3))) == pytest.approx(0.01, abs=1e-12)
    assert mag_interval(t, None) is None and mag_interval(t, np.full_like(m, np.nan)) is None
    p = EkfParams()
    sigma = np.degrees(p.vector(0.01)[P_MAG_NOISE])
    assert sigma == pytest.approx(1.2 / np.sqrt(0.01))
    assert np.degrees(p.vector(0.01, 0.04)[P_MAG_NOISE]) == pytest.approx(1.2 / np.sqrt(0.04))
    for bad in (None, 0.0, -1.0, float("nan")):
        assert np.degrees(p.vector(0.01, bad)[P_MAG_NOISE]) == pytest.approx(sigma)
    assert np.degrees(p.vector(0.01, 1.0)[P_MAG_NOISE]) == pytest.approx(5.0)  # 1 Hz: the floor
    assert np.degrees(EkfParams(mag_noise_deg=20.0).vector(0.01, 0.04)[P_MAG_NOISE]) == pytest.approx(20.0)
    with pytest.raises(ImutoolError):
        EkfParams(mag_noise_deg=0.001)


def test_the_magnetometer_gates_compare_with_the_mean_field_not_the_first_sample():
    """The reference norm and dip that the magnetometer's gates and de-weighting compare with is the mean of the
    accepted field (a running mean, forgetting over mag_reference_tau = 1 h), not the first sample. A first second
    read 12 % strong (a start beside steel) used to set the reference for the whole run: every later sample looked
    11 % off and was de-weighted ×5.6, and the heading followed a field change more slowly (0.31 of the turn after
    5 s against 0.38; with the mean reference 0.38 either way). On BROAD, trial 01's first samples read 5 % below
    the trial's median field, so 1 µT of white noise on the magnetometer tripped the 15 % norm gate 640 times
    (2.82° total instead of 1.72°); with the mean reference the 16 trials with that noise score 1.96° (2.16° before;
    benchmarks/attitude_stress.py). A start more than 15 % off used to lock the magnetometer out for the run; a
    field that holds while the sensor turns is now taken as the new reference
    (test_a_new_field_is_taken_once_it_has_held_while_the_sensor_turned); a still or slowly turning sensor (a
    ship's 5 °/s) never shows one, and the run says so (test_a_heading_without_its_magnetometer_is_said)."""
    ref = _heading_follows_a_turned_field(200.0, EkfParams())
    start = _heading_follows_a_turned_field(200.0, EkfParams(), first_second_scale=1.12)
    assert np.abs(start - ref).max() <= 0.02, (start, ref)
    first_sample = _heading_follows_a_turned_field(200.0, EkfParams(mag_reference_tau=0.0), first_second_scale=1.12)
    assert first_sample[0] <= 0.88 * ref[0], (first_sample, ref)


def test_a_zero_first_magnetometer_sample_sets_no_reference():
    """A first magnetometer row of zeros (a sensor still starting) gives no reference field: the gates wait for the
    first accepted samples instead of comparing every later sample with a placeholder dip of 60°. A field of
    dip 75° was rejected on every sample before (heading 64° off); now it is used from the first update."""
    rec = simulate("ship-roll", duration=60, seed=1, rate_hz=100.0)
    c = quat_to_matrix(rec["ref_q"])
    field = 50.0 * np.array([np.cos(np.radians(75.0)), 0.0, np.sin(np.radians(75.0))])  # NED, µT
    m = np.einsum("nji,j->ni", c, field)
    m[0] = 0.0
    res, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], m)
    assert res.summary["mag_rejected"] <= 1
    e = _heading_error_deg(res.q, rec["ref_q"])
    assert np.abs(e[rec.time > rec.time[0] + 30.0]).max() < 2.0


def _hand_held(seed: int, still_s: float = 10.0, duration: float = 120.0, rate_hz: float = 100.0):
    """A sensor held still for ``still_s`` s, then turned by hand about every axis (sums of sines, 30–90 °/s
    typical); gravity, a 50 µT field of dip 65°, white noise (gyro 0.002 rad/s, accel 0.02 m/s², mag 0.2 µT).
    Returns t (s), gyro (rad/s), accel (m/s²), mag (µT), the field in NED (N×3, to be disturbed) and ref_q."""
    from imutool.sim.accel_array import integrate_quaternion

    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1.0 / rate_hz)
    w = np.zeros((len(t), 3))
    for i in range(3):
        for f, a in zip(rng.uniform(0.05, 0.4, 3), rng.uniform(0.3, 0.8, 3), strict=True):
            w[:, i] += a * np.sin(2 * np.pi * f * (t - still_s) + rng.uniform(0, 2 * np.pi))
    w *= np.clip((t - still_s) / 2.0, 0.0, 1.0)[:, None]
    q = integrate_quaternion(t, w)
    c = quat_to_matrix(q)
    field = np.broadcast_to(50.0 * np.array([np.cos(np.radians(65)), 0.0, np.sin(np.radians(65))]), w.shape).copy()
    gyro = w + rng.normal(0, 0.002, w.shape)
    accel = np.einsum("nji,j->ni", c, np.array([0.0, 0.0, -9.80665])) + rng.normal(0, 0.02, w.shape)
    noise = rng.normal(0, 0.2, w.shape)
    return t, gyro, accel, lambda f: np.einsum("nji,nj->ni", c, f) + noise, field, q


def _inclination_error_deg(q, q_ref):
    """BROAD's inclination error per sample (deg): quat_error_metrics, the project's own."""
    return np.degrees(quat_error_metrics(q, q_ref)[2])


def test_a_new_field_is_taken_once_it_has_held_while_the_sensor_turned():
    """No lock-out of the magnetometer (VQF's new-field acceptance): a recording that starts beside steel (for the
    first 8 s a field 8 % weak with its dip 24° flat, the heading taken from it 26° off) used to reject the
    true field for the whole run, its heading 26° off to the end. A rejected field that stays within the gates
    of itself while the sensor turns faster than 20 °/s becomes the reference: after 5 s of turning before a
    first reference has held while turning, 20 s after. Taken at 15–17 s here (seeds 0–3). The heading held to
    the old reference then gets a σ of at least its disagreement with the new field and loses its
    covariance with the bias, so it converges to the new field at once without teaching the bias: within 0.8°
    from 2 s after (without that it wandered by 5° for a minute, the bias taught 1 °/s by the convergence). A
    magnetometer on every 4th row is taken at the same time (its time counts the rows between its samples). The
    run says where (summary, warning). What must not be
    taken: a magnet riding with the sensor (a body-fixed 30 µT for 40 s: its norm and dip change as the body
    turns) and a magnet beside a still sensor (nothing turned)."""
    for seed in (0, 1):
        t, g, a, mag_of, field, q = _hand_held(seed)
        f = field.copy()
        f[t < 8.0] += np.array([10.0, 15.0, -15.0])
        m = mag_of(f)
        old, _ = run_ekf(t, g, a, m, EkfParams(mag_new_time=0.0))
        assert np.mean(old.flags[t > 10] & F_MAG_REJ > 0) > 0.99
        assert np.abs(_heading_error_deg(old.q, q)[t > 40]).min() > 20.0  # locked out: the start's heading
        res, _ = run_ekf(t, g, a, m, EkfParams())
        taken = t[(res.flags & F_MAG_NEW) > 0]
        assert len(taken) == 1 and 14.0 < taken[0] < 18.0 and res.summary["mag_new_field"] == 1, taken
        assert np.abs(_heading_error_deg(res.q, q)[t > taken[0] + 2.0]).max() < 1.0
        slow = m.copy()
        slow[np.arange(len(t)) % 4 != 0] = np.nan  # a magnetometer at a quarter of the IMU's rate
        res, _ = run_ekf(t, g, a, slow, EkfParams())
        assert abs(t[(res.flags & F_MAG_NEW) > 0][0] - taken[0]) < 0.5
        # a magnet riding with the sensor for 40 s: rejected, never taken
        m = mag_of(field)
        ride = (t > 30) & (t < 70)
        m[ride] += np.array([25.0, -15.0, 10.0])
        res, _ = run_ekf(t, g, a, m, EkfParams())
        assert res.summary["mag_new_field"] == 0 and np.mean(res.flags[ride] & F_MAG_REJ > 0) > 0.9
        assert np.abs(_heading_error_deg(res.q, q)[t > 10]).max() < 3.0
    # a magnet beside a still sensor for 40 s: rejected, never taken (nothing turned)
    t, g, a, mag_of, field, q = _hand_held(2, still_s=60.0)
    f = field.copy()
    near = (t > 10) & (t < 50)
    f[near] += np.array([0.0, 20.0, -15.0])
    res, _ = run_ekf(t, g, a, mag_of(f), EkfParams())
    assert res.summary["mag_new_field"] == 0 and np.mean(res.flags[near] & F_MAG_REJ > 0) > 0.99
    assert np.abs(_heading_error_deg(res.q, q)[t > 5]).max() < 1.0


def test_a_new_field_is_said_in_memory_and_streamed(tmp_path, capsys):
    """The replaced reference is said: summary key mag_new_field_s, one warning on stderr and in the metadata,
    the same time in memory and streamed in small chunks."""
    t, g, a, mag_of, field, q = _hand_held(0)
    f = field.copy()
    f[t < 8.0] += np.array([10.0, 15.0, -15.0])
    rec = formats.Recording(t)
    for name, v, unit in (("gyro", g, "rad/s"), ("accel", a, "m/s^2"), ("mag", mag_of(f), "uT")):
        rec.add(name, v, unit)
    src = tmp_path / "start_beside_steel.csv"
    formats.write(rec, src)
    times = []
    for extra in ([], ["--stream-mb", "0.05"]):
        out = tmp_path / f"est{len(extra)}.csv"
        code, stdout, err = run_main(["filter", src, "-o", out, "--json", *extra], capsys)
        assert code == 0, err
        summary = json.loads(stdout)
        assert "reference field was replaced 1 time(s)" in err
        assert any("reference field was replaced" in w for w in formats.read(out).meta["warnings"])
        times.append(summary["mag_new_field_s"])
    assert len(times[0]) == 1 and times[0] == times[1], times


def test_a_heading_far_off_does_not_teach_the_gyro_bias():
    """The magnetometer teaches the gyro bias about the vertical only from heading innovations within
    mag_bias_gate = 3 σ (σ² = the heading's variance + the magnetometer's undisturbed σ² per update): a heading
    off by more is the heading's error, not the gyro's. A start beside steel (20 µT east for 8 s: the field 8 %
    strong and its dip 8° flat, inside the gates; the heading starts 43° off): while the heading converged, the
    bias learnt its error and the sensor's turning put it into the tilt — inclination RMS 1.9–2.5° against 0.3°
    intact (seeds 0–3); with the gate 0.6–1.2°. On BROAD the same start (20 µT east for 10 s) gives 0.91°
    inclination without the gate, 0.78° with it (0.74° intact; test_broad_started_beside_steel); trial 33's
    heading inside its magnet costs 0.20° total (2.38 → 2.58°; the 16 trials 1.95 → 1.97°). The intact run is
    unchanged."""
    for seed in (0, 1):
        t, g, a, mag_of, field, q = _hand_held(seed)
        intact = mag_of(field)
        r0, _ = run_ekf(t, g, a, intact, EkfParams(mag_bias_gate=0.0))
        r1, _ = run_ekf(t, g, a, intact, EkfParams())
        assert np.abs(_inclination_error_deg(r0.q, q) - _inclination_error_deg(r1.q, q)).max() < 0.01
        f = field.copy()
        f[t < 8.0] += np.array([0.0, 20.0, 0.0])
        m = mag_of(f)
        moving = t > 10
        without = np.sqrt(
            np.mean(_inclination_error_deg(run_ekf(t, g, a, m, EkfParams(mag_bias_gate=0.0))[0].q, q)[moving] ** 2)
        )
        res, _ = run_ekf(t, g, a, m, EkfParams())
        gated = np.sqrt(np.mean(_inclination_error_deg(res.q, q)[moving] ** 2))
        assert without > 1.5 and gated < 0.7 * without, (without, gated)
        assert res.summary["mag_new_field"] == 0  # the gates passed this field: no new reference involved


def test_heading_recovers_within_seconds_after_a_magnet_is_taken_away():
    """A magnet beside the sensor (a world-fixed field of half the earth's, 40 s, 2 s ramps in and out) on a
    rolling ship: the norm/dip de-weighting keeps the heading within 1.5° during the disturbance and within 0.8°
    from 2 s after it ends. With the detection off the heading follows the magnet (~28°) and is still ~18° off
    5 s after it is gone — the ≈ 20 s time constant of an undetected field change."""
    from formats.frames import quat_to_matrix

    off = {"mag_norm_soft": 0.0, "mag_dip_soft_deg": 0.0, "mag_norm_gate": 0.0, "mag_dip_gate_deg": 0.0}
    for seed in (1, 2):
        rec = simulate("ship-roll", duration=110, seed=seed)
        t, m = rec.time, np.array(rec["mag"], dtype=float)
        ramp = np.clip(np.minimum(t - 40, 80 - t) / 2.0, 0, 1)
        d = 0.5 * np.median(np.linalg.norm(m, axis=1)) * np.array([0.6, -0.7, 0.4]) / np.linalg.norm([0.6, -0.7, 0.4])
        md = m + ramp[:, None] * np.einsum("nji,j->ni", quat_to_matrix(rec["ref_q"]), d)  # world vector, body axes
        err = {}
        for name, kw in (("default", {}), ("undetected", off)):
            res, _ = run_ekf(t, rec.get("gyro", "rad/s"), rec.get("accel", "m/s^2"), md, EkfParams(**kw))
            e = np.abs(_heading_error_deg(res.q, rec["ref_q"]))
            err[name] = (e[(t > 40) & (t < 82)].max(), e[t > 84].max(), e[t > 87].max())
        assert err["default"][0] <= 1.5 and err["default"][1] <= 0.8, (seed, err)
        assert err["undetected"][0] >= 15.0 and err["undetected"][2] >= 10.0, (seed, err)


def test_projected_accel_update_is_the_joseph_form_of_its_gain():
    """_drop_vertical turns the optimal update into K' = T K (T = I − diag(r rᵀ, r rᵀ)); its covariance must equal
    the Joseph form (I − K'H) P (I − K'H)ᵀ + K' R K'ᵀ computed densely, and δx must equal K' y."""
    from formats.jit.decorators import njit
    from imutool.attitude.covariance import _drop_vertical, _vertical_forms
    from imutool.attitude.updates import _vec_update

    @njit  # the three are compiled without a Python entry: called here from a compiled function, as the kernel does
    def projected_update(P, h, y, sig2, r, drop_att, drop_bias, dx):
        fa, fx, fb = _vertical_forms(P, r[0], r[1], r[2])
        _vec_update(P, h[0], h[1], h[2], y[0], y[1], y[2], sig2, 0.0, True, dx, False)
        _drop_vertical(P, fa, fx, fb, r[0], r[1], r[2], drop_att, drop_bias, dx)

    rng = np.random.default_rng(4)
    a = rng.normal(size=(6, 6))
    P0 = a @ a.T * 1e-3 + np.eye(6) * 1e-4
    h = rng.normal(size=3)
    h /= np.linalg.norm(h)
    y = rng.normal(size=3) * 0.01
    sig2 = 0.03**2
    for drop_att, drop_bias in ((True, True), (True, False), (False, True)):
        P = P0.copy()
        dx = np.zeros(6)
        r = -h
        projected_update(P, h, y, sig2, r, drop_att, drop_bias, dx)
        hx = np.array([[0, -h[2], h[1]], [h[2], 0, -h[0]], [-h[1], h[0], 0]])
        H = np.hstack([hx, np.zeros((3, 3))])
        K = P0 @ H.T @ np.linalg.inv(H @ P0 @ H.T + sig2 * np.eye(3))
        rr = np.outer(r, r)
        T = np.eye(6) - np.block([[rr * drop_att, np.zeros((3, 3))], [np.zeros((3, 3)), rr * drop_bias]])
        Kp = T @ K
        A = np.eye(6) - Kp @ H
        assert np.allclose(P, A @ P0 @ A.T + sig2 * Kp @ Kp.T, rtol=1e-9, atol=1e-12)
        assert np.allclose(dx, Kp @ y, rtol=1e-9, atol=1e-14)


@pytest.mark.slow
def test_streamed_filter_on_parquet_equals_in_memory(tmp_path):
    """A Parquet input streams through `filter` by row groups (bounded memory) into a Parquet or CSV output, value
    for value the same estimate as the in-memory run."""
    pytest.importorskip("pyarrow", reason="Parquet needs the [parquet] extra (pyarrow)")
    from imutool.cli import cli

    rec = simulate("ship-roll", duration=30, seed=8)
    src = tmp_path / "roll.parquet"
    formats.write(rec, src)
    outs = {}
    for name, extra in (("mem", []), ("stream", ["--stream-mb", "0", "--chunk-rows", "1000"])):
        out = tmp_path / f"{name}.parquet"
        run = CliRunner().invoke(cli, ["filter", str(src), "-o", str(out), "--json", *extra])
        assert run.exit_code == 0, run.output
        assert json.loads(run.stdout)["method"] == ("ekf (streamed)" if name == "stream" else "ekf")
        outs[name] = formats.read(out)
    assert np.allclose(outs["mem"]["roll"], outs["stream"]["roll"], atol=1e-6)
    assert np.allclose(outs["mem"]["q"], outs["stream"]["q"], atol=1e-9)


def test_accel_noise_floor_is_a_sensor_property_not_the_motion():
    """The learned accelerometer white noise (which de-weights the accelerometer) follows a quieter level at once
    but rises towards a louder one only with accel_noise_rise_time: 60 s of motion jerk (4× the sensor's noise in
    the second differences) must not de-weight the accelerometer as if the sensor had become 4× noisier.
    With rise time 0 the floor is the 10-s mean itself (the earlier behaviour)."""
    from imutool.attitude.layout import S_AFLOOR, S_AVAR

    rng = np.random.default_rng(3)
    fs, sigma = 200.0, 0.05
    t = np.arange(0, 140, 1 / fs)
    acc = np.tile([0.0, 0.0, -9.80665], (len(t), 1)) + rng.normal(0, sigma, (len(t), 3))
    loud = (t >= 20) & (t < 80)
    acc[loud] += rng.normal(0, 4 * sigma, (loud.sum(), 3))
    gyro = rng.normal(0, 1e-3, (len(t), 3))
    floors = {}
    for rise in (0.0, 300.0):
        prm = EkfParams(accel_noise_rise_time=rise, mag_mode="off")
        res_loud, st_loud = run_ekf(t[t < 80], gyro[t < 80], acc[t < 80], None, prm)
        _, st_end = run_ekf(t, gyro, acc, None, prm)
        floors[rise] = (st_loud[S_AFLOOR], st_loud[S_AVAR], st_end[S_AFLOOR], res_loud.std[-1, 0])
    quiet = sigma**2  # the estimator's target: σ² per axis
    f0, avar0, end0, roll_sd0 = floors[0.0]
    f1, avar1, end1, roll_sd1 = floors[300.0]
    assert avar1 > 10 * quiet and f0 == avar0  # the 10-s mean sees the jerk; rise time 0 uses it as is
    # the floor rose by about 1 − e^(−60/300) ≈ 18 % of the step in 60 s of jerk, not all the way
    assert f1 - quiet < 0.25 * (avar1 - quiet), floors
    assert abs(end1 - quiet) < 0.3 * quiet and abs(end0 - quiet) < 0.3 * quiet, floors  # quiet again: back at once
    # and the update uses the floor: the accelerometer keeps its weight, so roll σ after the jerk stays smaller
    assert roll_sd1 < 0.8 * roll_sd0, floors


def _gyrocompass(rec, seed=0):
    """A 1 Hz gyrocompass from the simulator's truth: 0.3° noise, 0.1° resolution (HDT's), its fixes' times."""
    t = rec.time - rec.time[0]
    idx = np.flatnonzero(np.diff(np.floor(t), prepend=-1) > 0)
    noise = np.random.default_rng(seed).normal(0.0, 0.3, len(idx))
    return rec.time[idx], np.round((rec["ref_heading"][idx] + noise) % 360, 1)


@pytest.mark.parametrize("streamed", [pytest.param(False, marks=pytest.mark.slow), True])
def test_a_gyrocompass_heading_replaces_the_magnetometer(tmp_path, streamed):
    """A bridge sensor without a magnetometer, SOG/COG and its lever arm: nothing holds the heading, so only the
    speed along the bow is used (warned; the sway and surge stay in the roll). A gyrocompass heading (channel
    heading_true, or `--heading` HDT sentences) is taken as the heading measurement: roll within MSC.363's 1°,
    heading within 0.5°, no warning;
    the summary says where the heading came from, in memory and streamed. The magnetometer is not used then."""
    from formats.nmea import checksum
    from imutool.cli import cli

    rec = simulate("ship-at-sea", duration=300, seed=0)
    lever = ",".join(str(x) for x in rec.meta["lever_arm_m"])
    nomag = formats.Recording(rec.time, {c: rec[c] for c in rec.channels if c != "mag"}, dict(rec.meta))
    tf, hf = _gyrocompass(rec)
    hdt = tmp_path / "hdt.nmea"
    lines = (f"{t:.3f};A;$HEHDT,{h:.1f},T*{checksum(f'HEHDT,{h:.1f},T')}\n" for t, h in zip(tf, hf, strict=True))
    hdt.write_text("".join(lines))
    with_col = nomag.copy()
    with_col.add("heading_true", np.degrees(np.interp(rec.time, tf, np.unwrap(np.radians(hf)))) % 360, "deg")
    extra = ["--stream-mb", "0", "--chunk-rows", "5000"] if streamed else []
    late = rec.time - rec.time[0] >= 60
    cases = [("no_heading", nomag, []), ("column", with_col, []), ("column_and_mag", rec, [])]
    if not streamed:  # a --heading file is attached in memory (as --gnss)
        cases.append(("hdt_file", nomag, ["--heading", str(hdt)]))
    for name, r, opts in cases:
        if name == "column_and_mag":
            r = rec.copy()
            r.add("heading_true", with_col["heading_true"], "deg")
        src, out = tmp_path / f"{name}.csv", tmp_path / f"{name}_est.csv"
        formats.write(r, src)
        run = CliRunner().invoke(
            cli, ["filter", str(src), "-o", str(out), "--lever-arm", lever, "--json", *opts, *extra]
        )
        assert run.exit_code == 0, run.output
        s = json.loads(run.stdout)
        est = formats.read(out)
        roll = np.abs(est["roll"] - rec["ref_roll"])[late]
        head = np.abs(wrap_deg180(est["heading"] - rec["ref_heading"]))[late]
        if name == "no_heading":
            assert "GNSS velocity without a heading" in run.stderr and s["heading_source"] == "none (gyro)"
            assert est.meta["heading_source"] == "none (gyro)"
            assert roll.max() > 1.0, roll.max()  # measured 1.3° (the velocity turned with the unheld heading: 5.8°)
            continue
        duration = rec.time[-1] - rec.time[0]  # one update a second (heading_input_interval)
        assert s["heading_source"].startswith("heading_true") and s["heading_input_updates"] > 0.9 * duration
        # the feed's lag against the gyro, measured chunk by chunk when streamed: the same in both
        assert abs(s["heading_input_lag_s"]) <= 0.2 and "lags the gyro" not in run.stderr, s
        assert float(est.meta["heading_input_lag_s"]) == s["heading_input_lag_s"]
        assert est.meta["heading_source"] == s["heading_source"]
        assert "GNSS velocity without a heading" not in run.stderr, run.stderr
        assert np.sqrt(np.mean(roll**2)) <= 0.5 and roll.max() <= 1.0, (name, roll.max())  # 0.14 / 0.42
        assert np.sqrt(np.mean(head**2)) <= 0.5, name  # 0.14


def test_an_empty_heading_input_is_said_and_a_stopped_gyrocompass_is_not_interpolated(tmp_path):
    """A heading_true column with no value: the magnetometer is not used either, so the run says so. A
    gyrocompass feed that stops for 20 s is not drawn as a straight line across the gap (NaN: no update)."""
    from imutool.filtering import attach_heading

    rec = simulate("ship-roll", duration=60, seed=1)
    empty = rec.copy()
    empty.add("heading_true", np.full(len(rec), np.nan), "deg")
    _, s = ekf_recording(empty)
    assert s["heading_input_updates"] == 0
    assert any("heading_true (external heading) holds no valid value" in w for w in s["warnings"])
    _, s = ekf_recording(rec)
    assert s["heading_source"] == "magnetometer" and "heading_input_updates" not in s
    tf, hf = _gyrocompass(rec)
    keep = (tf - rec.time[0] < 20) | (tf - rec.time[0] > 40)
    src = tmp_path / "hdg.csv"
    formats.write(formats.Recording(tf[keep], {"heading_true": hf[keep]}, {}), src)
    out = attach_heading(rec, src)
    t = rec.time - rec.time[0]
    h = out["heading_true"]
    assert np.all(np.isnan(h[(t > 20) & (t < 40)])) and np.all(np.isfinite(h[(t > 1) & (t < 19)]))
    assert np.abs(wrap_deg180(h[(t > 41) & (t < 59)] - rec["ref_heading"][(t > 41) & (t < 59)])).max() < 1.5


def test_a_glitched_or_wrong_gyrocompass_fix_is_handled(tmp_path):
    """One fix 120° off mid-run is skipped (beyond 4σ): the heading moves < 0.5°. A wrong *first* fix (150° off for
    0.6 s) is disagreed with for 5 s, then the gyrocompass's heading is taken outright: within 1° from 10 s on
    (the linear update alone left 16° at 40 s). A heading_true in rad is read in its unit in memory and streamed
    alike; a feed that covers a fifth of the run is said."""
    from imutool.cli import cli

    rec = simulate("ship-at-sea", duration=120, seed=0)
    t = rec.time - rec.time[0]
    tf, hf = _gyrocompass(rec)
    h = np.degrees(np.interp(rec.time, tf, np.unwrap(np.radians(hf)))) % 360
    runs = {}
    for name in ("clean", "glitch", "first"):
        hh = h.copy()
        if name == "glitch":
            hh[(t >= 60) & (t < 60.5)] += 120.0
        if name == "first":
            hh[t < 0.6] += 150.0
        res, _ = run_ekf(
            rec.time,
            rec["gyro"],
            rec["accel"],
            None,
            EkfParams(),
            rec["sog"],
            rec["cog"],
            lever_arm=np.array(rec.meta["lever_arm_m"]),
            heading_deg=hh % 360,
        )
        runs[name] = (np.degrees(quat_to_euler(res.q)[2]), res.summary)
    assert runs["glitch"][1]["heading_input_rejected"] >= 1 and runs["clean"][1]["heading_input_rejected"] == 0
    assert np.abs(wrap_deg180(runs["glitch"][0] - runs["clean"][0])).max() < 0.5
    late = t >= 10
    assert np.abs(wrap_deg180(runs["first"][0] - rec["ref_heading"]))[late].max() < 1.0
    # the unit: heading_true in rad, in memory and streamed
    tmp_dir = tmp_path
    r = formats.Recording(rec.time, {c: rec[c] for c in rec.channels if c != "mag"}, dict(rec.meta))
    r.add("heading_true", np.radians(h), "rad")
    src = f"{tmp_dir}/rad.csv"
    formats.write(r, src)
    lever = ",".join(str(x) for x in rec.meta["lever_arm_m"])
    outs = []
    for extra in ([], ["--stream-mb", "0", "--chunk-rows", "3000"]):
        out = f"{tmp_dir}/est{len(extra)}.csv"
        run = CliRunner().invoke(cli, ["filter", src, "-o", out, "--lever-arm", lever, *extra])
        assert run.exit_code == 0, run.output
        outs.append(formats.read(out)["heading"])
    for o in outs:
        assert np.abs(wrap_deg180(o - rec["ref_heading"]))[t >= 10].max() < 1.0
    # a feed that covers a fifth of the run
    part = h.copy()
    part[t > 24] = np.nan
    rp = rec.copy()
    rp.add("heading_true", part, "deg")
    _, s = ekf_recording(rp)
    assert any("covers about 2" in w for w in s["warnings"]), s["warnings"]


def test_attach_heading_sorts_refuses_a_file_without_clock_and_keeps_fix_times(tmp_path, monkeypatch):
    """Fixes out of time order are sorted (of equal times the last read wins), a fix's own time keeps its value,
    the inside of a gap over 5 s is NaN, and an NMEA file without a clock is refused (its sentence index would be
    taken for seconds)."""
    from formats.nmea import checksum
    from imutool import filtering

    rec = simulate("ship-roll", duration=30, seed=1)
    t0 = rec.time[0]
    fixes = [(1, 10.0), (3, 30.0), (2, 20.0), (2, 21.0), (10, 100.0), (11, 110.0)]
    unsorted = formats.Recording(
        t0 + np.array([f[0] for f in fixes], float), {"heading_true": np.array([f[1] for f in fixes])}, {}
    )
    monkeypatch.setattr(filtering.formats, "read", lambda path: unsorted)
    out = filtering.attach_heading(rec, tmp_path / "h.csv")["heading_true"]
    monkeypatch.undo()
    at = {round(x - t0, 3): v for x, v in zip(rec.time, out, strict=True)}
    assert at[2.0] == pytest.approx(21.0) and at[2.5] == pytest.approx(25.5)  # sorted; the last of equal times
    assert np.isnan(at[5.0]) and at[10.0] == pytest.approx(100.0)  # inside a 7 s gap: none; at a fix: the fix
    assert np.isnan(at[0.5]) and np.isnan(at[20.0])  # outside the feed
    nmea = tmp_path / "noclock.nmea"
    nmea.write_text("".join(f"$HEHDT,{h:.1f},T*{checksum(f'HEHDT,{h:.1f},T')}\n" for h in (10.0, 11.0, 12.0)))
    with pytest.raises(ImutoolError, match="no clock"):
        filtering.attach_heading(rec, nmea)


def test_attach_gnss_keeps_the_courses_after_an_empty_one(tmp_path):
    """A receiver leaves RMC's course empty when it does not know it (at low speed, say). The courses after such
    a fix were lost: the unwrap ran over the NaN, which voided every course after it, and the SOG/COG
    compensation silently stopped there."""
    from formats.nmea import checksum
    from imutool.filtering import attach_gnss

    rec = simulate("turn", duration=60, seed=4, straight_s=15, ramp_s=5)
    lines = []
    for n, i in enumerate(np.flatnonzero(np.diff(np.floor(rec.time), prepend=-1) > 0)):
        kn, cog = rec["ref_sog"][i] / (1852 / 3600), rec["ref_cog"][i] % 360
        course = "" if n == 10 else f"{cog:.2f}"
        utc = f"{int(rec.time[i] // 3600):02d}{int(rec.time[i] % 3600 // 60):02d}{rec.time[i] % 60:05.2f}"
        body = f"GPRMC,{utc},A,,,,,{kn:.2f},{course},010125,,,A"
        lines.append(f"{rec.time[i]:.3f};A;${body}*{checksum(body)}")
    gnss = tmp_path / "gnss.nmea"
    gnss.write_text("\n".join(lines) + "\n")
    out = attach_gnss(rec, gnss)
    late = (rec.time - rec.time[0] > 12) & (rec.time - rec.time[0] < 58)
    assert np.all(np.isfinite(out["cog"][late]))
    assert np.abs(wrap_deg180(out["cog"][late] - rec["ref_cog"][late])).max() < 3.0


def test_attach_gnss_sorts_bridges_an_outage_and_refuses_a_file_without_clock(tmp_path, monkeypatch):
    """SOG/COG fixes out of time order were handed to np.interp unsorted (a silently wrong speed), and a VTG-only
    NMEA file (no clock) was squeezed onto its sentence index as seconds. Now: sorted (of equal times the last
    read), the clock-less file refused; an outage is bridged (blanking it measured worse: docs/attitude.md)."""
    from formats.nmea import checksum
    from imutool import filtering

    rec = simulate("ship-roll", duration=30, seed=1)
    t0 = rec.time[0]
    fixes = [(1, 1.0, 10.0), (3, 3.0, 30.0), (2, 2.0, 20.0), (2, 2.5, 25.0), (10, 10.0, 100.0), (11, 11.0, 110.0)]
    unsorted = formats.Recording(
        t0 + np.array([f[0] for f in fixes], float),
        {"sog": np.array([f[1] for f in fixes]), "cog": np.array([f[2] for f in fixes])},
        {},
    )
    monkeypatch.setattr(filtering.formats, "read", lambda path: unsorted)
    out = filtering.attach_gnss(rec, tmp_path / "g.csv")
    monkeypatch.undo()
    at = {round(x - t0, 3): (s, c) for x, s, c in zip(rec.time, out["sog"], out["cog"], strict=True)}
    assert at[2.0] == pytest.approx((2.5, 25.0)) and at[1.5] == pytest.approx((1.75, 17.5))  # sorted, last wins
    assert at[2.5] == pytest.approx((2.75, 27.5))
    assert at[5.0] == pytest.approx((5.0, 50.0))  # a 7 s outage is bridged (a steady turn's course is linear)
    assert at[10.0] == pytest.approx((10.0, 100.0)) and at[10.5] == pytest.approx((10.5, 105.0))
    vtg = tmp_path / "vtg_only.nmea"
    bodies = [f"GPVTG,{c:.1f},T,,M,{k:.1f},N,{k * 1.852:.1f},K,A" for c, k in ((10, 5), (11, 5), (12, 5))]
    vtg.write_text("".join(f"${b}*{checksum(b)}\n" for b in bodies))
    with pytest.raises(ImutoolError, match="no clock"):
        filtering.attach_gnss(rec, vtg)


@pytest.mark.slow
def test_a_late_gyrocompass_is_read_later_with_heading_input_latency(tmp_path, capsys):
    """A gyrocompass whose HDT is 0.8 s late: through the turn the heading lags by 0.8 s × 3 °/s. The run measures
    the lag against the gyro and says it (summary, metadata, one warning) until it is given; with
    `--param heading_input_latency=0.8` each fix is taken for the heading 0.8 s before its stamp (measured on this
    run: heading RMS 1.82° → 0.10° after the first minute). The parameter is written into the output's metadata,
    and a streamed run refuses it (a heading read later needs the rows after a chunk's end)."""
    from formats.nmea import checksum
    from imutool.cli import cli

    rec = simulate("ship-at-sea", duration=300, seed=0)
    lever = ",".join(str(x) for x in rec.meta["lever_arm_m"])
    nomag = formats.Recording(rec.time, {c: rec[c] for c in rec.channels if c != "mag"}, dict(rec.meta))
    tf, _ = _gyrocompass(rec)
    unwrapped = np.degrees(np.unwrap(np.radians(rec["ref_heading"])))
    noise = np.random.default_rng(0).normal(0.0, 0.3, len(tf))
    hf = np.round((np.interp(tf - 0.8, rec.time, unwrapped) + noise) % 360, 1)  # the heading 0.8 s before
    hdt = tmp_path / "hdt.nmea"
    hdt.write_text(
        "".join(f"{t:.3f};A;$HEHDT,{h:.1f},T*{checksum(f'HEHDT,{h:.1f},T')}\n" for t, h in zip(tf, hf, strict=True))
    )
    src = tmp_path / "imu.csv"
    formats.write(nomag, src)
    late = rec.time - rec.time[0] >= 60
    rms = {}
    for latency in (0.0, 0.8):
        out = tmp_path / f"est_{latency}.csv"
        run = CliRunner().invoke(
            cli,
            [
                "filter",
                str(src),
                "-o",
                str(out),
                "--lever-arm",
                lever,
                "--heading",
                str(hdt),
                "--param",
                f"heading_input_latency={latency}",
                "--json",
            ],
        )
        assert run.exit_code == 0, run.output
        s = json.loads(run.stdout)
        assert s["heading_input_lag_s"] == pytest.approx(0.8, abs=0.2)  # measured from the run: 0.92
        assert ("lags the gyro by about" in run.stderr) == (latency == 0.0), run.stderr
        est = formats.read(out)
        assert float(est.meta["heading_input_lag_s"]) == s["heading_input_lag_s"]
        rms[latency] = float(np.sqrt(np.mean(wrap_deg180(est["heading"] - rec["ref_heading"])[late] ** 2)))
        assert est.meta["filter"]["heading_input_latency"] == latency
    assert rms[0.0] > 1.0 and rms[0.8] < 0.3, rms  # measured 1.82 / 0.10
    with_col = nomag.copy()  # a heading_true column in a file large enough to stream: refused, in one line
    with_col.add("heading_true", np.degrees(np.interp(rec.time, tf, np.unwrap(np.radians(hf)))) % 360, "deg")
    formats.write(with_col, tmp_path / "with_col.csv")
    out = tmp_path / "streamed.csv"
    code, _, err = run_main(
        [
            "filter",
            tmp_path / "with_col.csv",
            "-o",
            out,
            "--stream-mb",
            "0",
            "--param",
            "heading_input_latency=0.8",
            "-q",
        ],
        capsys,
    )
    assert code == 2 and "heading_input_latency" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and not out.exists(), err
    lags = {}  # without the latency, streamed in chunks and in memory: the same lag measured, and said
    for name, extra in (("memory", []), ("streamed", ["--stream-mb", "0", "--chunk-rows", "5000"])):
        code, stdout, err = run_main(
            ["filter", tmp_path / "with_col.csv", "-o", tmp_path / f"{name}.csv", "--json", *extra], capsys
        )
        assert code == 0 and "lags the gyro by about" in err, err
        summary = json.loads(stdout)
        assert summary["method"].endswith("(streamed)") == (name == "streamed"), summary["method"]
        lags[name] = summary["heading_input_lag_s"]
    assert lags["streamed"] == lags["memory"] == pytest.approx(0.8, abs=0.2), lags


def test_the_heading_lag_is_measured_where_the_heading_moves_and_not_said_where_it_cannot_be():
    """measure_heading_lag finds a feed's lag from the ship's yaw alone (ship-roll: no turn) within 0.1 s, for
    lags of 0, 0.5 and 1 s; on a sensor whose heading never moves the lag cannot be told, and nothing is said."""
    from imutool.heading_lag import heading_lag_check, measure_heading_lag

    for scenario, seed in (("ship-roll", 1), ("static", 0)):
        rec = simulate(scenario, duration=200, seed=seed)
        tf, _ = _gyrocompass(rec)
        unwrapped = np.unwrap(np.radians(rec["ref_heading"]))
        noise = np.random.default_rng(seed).normal(0.0, 0.3, len(tf))
        for lag in (0.0, 0.5, 1.0):
            hf = np.round((np.degrees(np.interp(tf - lag, rec.time, unwrapped)) + noise) % 360, 1)
            col = np.degrees(np.interp(rec.time, tf, np.unwrap(np.radians(hf)), left=np.nan)) % 360
            res, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], None, heading_deg=col)
            m = measure_heading_lag(rec.time, col, res.q, rec["gyro"], res.bias)
            summary, warns = heading_lag_check(m, 0.0)
            if scenario == "ship-roll":
                assert summary["heading_input_lag_s"] == pytest.approx(lag, abs=0.1), (lag, m)
                assert bool(warns) == (lag > 0), warns
            else:  # nothing moves: no lag is reported, nothing is said
                assert summary == {"heading_input_lag_s": None} and warns == [], (lag, m)
    assert heading_lag_check(
        measure_heading_lag(rec.time[:5000], col[:5000], res.q[:5000], rec["gyro"][:5000], res.bias[:5000]), 0.0
    ) == ({"heading_input_lag_s": None}, [])
    rec = simulate("ship-roll", duration=200, seed=1)  # a feed stamped 0.6 s early: a clock offset, said so
    early = np.degrees(np.interp(rec.time + 0.6, rec.time, np.unwrap(np.radians(rec["ref_heading"])))) % 360
    res, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], None, heading_deg=early)
    summary, warns = heading_lag_check(measure_heading_lag(rec.time, early, res.q, rec["gyro"], res.bias), 0.0)
    lag = summary["heading_input_lag_s"]
    assert lag == pytest.approx(-0.6, abs=0.1) and type(lag) is float, lag
    assert len(warns) == 1 and "leads the gyro" in warns[0] and "stamps are early" in warns[0], warns


def test_params_come_from_one_table():
    """PARAMS is the one source: the dataclass's fields and defaults, PARAM_DOC and the kernel vector are made from
    it. Each row with a kernel slot moves that slot alone, converted as the row says (as is, radians, 0/1); the slots
    the coefficients fill move with the sample interval; every slot is filled once."""
    from dataclasses import fields

    from imutool.attitude import PARAM_DOC, PARAMS, EkfCoefficients, ToKernel
    from imutool.attitude.layout import N_PARAMS, P_GAP_DT, P_GYRO_PREV_W, P_MAG_NOISE
    from imutool.attitude.param_table import COEFFICIENT_SLOTS

    assert [(f.name, f.default) for f in fields(EkfParams)] == [(p.name, p.default) for p in PARAMS]
    assert list(PARAM_DOC) == [p.name for p in PARAMS] and PARAM_DOC["gyro_noise"][0] == "rad/s/√Hz"
    assert "``mag_heading_density`` = 1.2 (deg*sqrt(s))" in EkfParams.__doc__
    slots = sorted([p.slot for p in PARAMS if p.slot is not None] + list(COEFFICIENT_SLOTS))
    assert slots == list(range(N_PARAMS))
    base = EkfParams().vector(0.005)
    for p in PARAMS:
        if p.slot is None:
            continue
        if isinstance(p.default, bool):
            changed, want = EkfParams(**{p.name: not p.default}), 0.0 if p.default else 1.0
        else:
            lo, hi = p.range
            v = 0.5 * (p.default + hi) if p.default < hi else 0.5 * (lo + p.default)
            changed, want = EkfParams(**{p.name: v}), (np.radians(v) if p.to_kernel is ToKernel.RADIANS else v)
        vec = changed.vector(0.005)
        moved = np.flatnonzero(vec != base)
        assert list(moved) == [p.slot] and vec[p.slot] == want, p.name
    c = EkfCoefficients.derive(EkfParams(gap_factor=4.0, gyro_integration="trapezoid"), 0.01, 0.04)
    assert c.gap_dt == 4.0 * 0.01 and c.gyro_prev_weight == 0.5 and c.samples_per_update == 2
    assert c.mag_sigma == pytest.approx(np.radians(max(1.2 / np.sqrt(0.04), 5.0)))
    vec = c.kernel_vector(EkfParams(gap_factor=4.0, gyro_integration="trapezoid"))
    assert vec[P_GAP_DT] == c.gap_dt and vec[P_GYRO_PREV_W] == 0.5 and vec[P_MAG_NOISE] == c.mag_sigma


def test_docs_hold_the_parameter_table():
    """docs/attitude.md shows the parameter table as params_markdown() makes it from PARAMS (regenerate on change)."""
    from pathlib import Path

    from imutool.attitude import params_markdown

    docs = (Path(__file__).resolve().parents[1] / "docs" / "attitude.md").read_text(encoding="utf-8")
    assert params_markdown() in docs


def test_params_file_version_and_migrations(tmp_path, capsys):
    """The parameter TOML carries a version: a saved file reads back equal, with no migration; an unversioned
    (version 0) file gets the named migrations its keys and values show it predates, each with its date and what
    changed, and the CLI prints their notes; a file newer than the code, a bad version and an unknown key are
    refused in one line."""
    from imutool.attitude import MIGRATIONS, PARAMS_VERSION, read_params_file
    from imutool.cli import cli

    p = EkfParams(bias_rw=3e-5, mag_mode="full", init_bias=(0.001, 0.0, -0.002))
    f = tmp_path / "now.toml"
    f.write_text(p.to_toml())
    assert f"version = {PARAMS_VERSION}" in f.read_text().splitlines()[1]
    now = read_params_file(str(f))
    assert now.params == p and now.version == PARAMS_VERSION and now.migrations == () and now.notes() == []
    assert EkfParams.from_toml(str(f)) == p

    for m in MIGRATIONS:
        assert m.name and m.changed and "2026-" in m.since and m.before_version <= PARAMS_VERSION
    old = tmp_path / "old.toml"  # every key of its day: before updates every N samples and the magnetometer density
    old.write_text("[ekf]\nupdate_every = 1\nmag_noise_deg = 20.0\naccel_lp_tau = 3.0\n")
    v0 = read_params_file(str(old))
    assert v0.version == 0 and v0.params.update_every == 1 and v0.params.mag_noise_deg == 20.0  # values kept
    assert [m.name for m in v0.migrations] == [
        "updates_every_n_samples",
        "mag_sigma_density",
        "mag_new_field",
        "butterworth_lowpass",
        "motion_model",
        "lever_arm_estimate",
        "aided_smoother",
    ]
    notes = v0.notes()
    assert len(notes) == 8 and "before 2026-11-26" in notes[0] and "commit 1816144" in notes[3]
    later = v0.notes(EkfParams(update_every=0, mag_noise_deg=20.0), {"update_every"})  # --update-every 0 given
    assert len(later) == 7 and later[0].startswith(f"{old} sets mag_noise_deg = 20")
    run = CliRunner().invoke(cli, ["filter", str(_roll(tmp_path)), "-o", str(tmp_path / "e.csv"), "--params", str(old)])
    assert run.exit_code == 0, run.output
    assert [line for line in run.stderr.splitlines() if line.startswith("note: ")] == [f"note: {n}" for n in notes]
    partial = tmp_path / "partial.toml"  # saved with the density, before the new-field acceptance
    partial.write_text("[ekf]\nmag_heading_density = 1.2\nmag_noise_deg = 0.0\n")
    assert [m.name for m in read_params_file(str(partial)).migrations] == [
        "mag_new_field",
        "motion_model",
        "lever_arm_estimate",
        "aided_smoother",
    ]
    v3 = tmp_path / "v3.toml"  # saved with the aided pass, before it was smoothed
    v3.write_text("version = 3\n[ekf]\naided = true\n")
    m3 = read_params_file(str(v3))
    assert [m.name for m in m3.migrations] == ["aided_smoother"] and "aided_smoother=false" in m3.notes()[0]
    assert m3.notes(EkfParams(aided_smoother=False), {"aided_smoother"}) == []

    for text, needle in (
        (f"version = {PARAMS_VERSION + 1}\n[ekf]\ngyro_noise = 0.001\n", "newer than this imutool"),
        ("version = 'one'\n[ekf]\n", "version 'one'"),
        ("version = -1\n[ekf]\n", "version -1"),
        (f"version = {PARAMS_VERSION}\n[ekf]\nnonsense = 1\n", "unknown EKF parameter(s) nonsense"),
    ):
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(ImutoolError, match=re.escape(needle)):
            read_params_file(str(bad))
        code, _, err = run_main(["filter", _roll(tmp_path), "-o", tmp_path / "x.csv", "--params", bad], capsys)
        assert code == 2 and needle in err and len(err.strip().splitlines()) == 1
        assert not (tmp_path / "x.csv").exists()


def test_params_from_options_is_the_library_route(tmp_path):
    """The run's parameters and migration notes come from the library (not the click module): defaults, then the
    file, then --param items, then the everyday flags; a bad name or value refused naming --param."""
    import inspect

    from imutool.attitude import params_from_options, read_params_file
    from imutool.cli import filter as cli_filter

    assert params_from_options() == (EkfParams(), [])
    old = tmp_path / "old.toml"
    old.write_text("[ekf]\nupdate_every = 1\nmag_noise_deg = 20.0\naccel_lp_tau = 3.0\n")
    p, notes = params_from_options(str(old), ["accel-lp-tau=2", "mag_mode=full"], update_every=0)
    assert (p.accel_lp_tau, p.mag_mode, p.update_every, p.mag_noise_deg) == (2.0, "full", 0, 20.0)
    assert notes == read_params_file(str(old)).notes(p, {"accel_lp_tau", "mag_mode", "update_every"}) and notes
    for item, needle in (("nonsense=1", "--param 'nonsense=1'"), ("accel_lp_tau=x", "--param accel_lp_tau='x'")):
        with pytest.raises(ImutoolError, match=re.escape(needle)):
            params_from_options(None, [item])
    assert "EkfParams" not in inspect.getsource(cli_filter)


def _roll(tmp_path):
    src = tmp_path / "roll20.csv"
    if not src.exists():
        formats.write(simulate("ship-roll", duration=20, seed=1), src)
    return src


def test_a_long_low_pass_does_not_diverge_on_a_bridge_sensor():
    """issue 35, item 1: accel_lp_tau 10 s on a bridge sensor 30 m above the roll centre in a seaway (sway 1.5 m at
    6 s, roll to 30°, GNSS speed, lever arm given) diverged to ~200° of roll error when the start-up running mean
    lasted τ/10 (1 s): it read the change of the sway's acceleration as gyro bias. With the mean capped at
    LP_MEAN_MAX (0.25 s, the same as before at τ ≤ 2.5 s) the roll stays within a few degrees."""
    from imutool.filtering import run_filter

    rec = simulate(
        "ship-at-sea",
        duration=180.0,
        seed=0,
        lever_arm=(-12.0, 0.0, -30.0),
        roll_significant_deg=30.0,
        sway_m=1.5,
        sway_period=6.0,
        turn_start=40.0,
        speed_source="gnss",
    )
    after = rec.time - rec.time[0] >= 120.0
    for tau, bound in ((2.5, 2.0), (10.0, 5.0)):
        est = run_filter(
            rec, params=EkfParams(accel_lp_tau=tau, ship_lp_tau=tau), lever_arm=np.array(rec.meta["lever_arm_m"])
        )
        err = np.abs(est.recording["roll"] - rec["ref_roll"])[after]
        assert err.max() < bound, (tau, err.max())
