"""Ship scenarios: truth consistency, the documented noise interpretation, GNSS channels, static cost."""

import numpy as np

from imutool.sim import simulate


def test_ship_roll_truth_and_noise():
    r = simulate("ship-roll", duration=30, seed=3, lever_z_m=0.0)
    assert abs(np.nanmax(r["ref_roll"]) - 15.0) < 0.1
    f = r["accel"]
    roll_acc = np.degrees(np.arctan2(-f[:, 1], -f[:, 2]))
    # "white noise σ = 1.5°": accelerometer-only roll scatters with σ ≈ 1.5° (no lever arm here)
    assert abs(np.std(roll_acc - r["ref_roll"]) - 1.5) < 0.1
    # gyro = truth + bias + noise
    resid = r["gyro"] - r["ref_gyro"] - r["ref_gyro_bias"]
    assert np.all(np.abs(resid.mean(axis=0)) < 1e-3)
    q = r["ref_q"]
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0)


def test_ship_roll_lever_arm_fools_accelerometer():
    r = simulate("ship-roll", duration=20, seed=1, lever_z_m=-5.0)
    f = r["ref_accel"]  # error-free specific force: only the lever-arm acceleration remains
    err = np.degrees(np.arctan2(-f[:, 1], -f[:, 2])) - r["ref_roll"]
    assert np.abs(err).max() > 2.0


def test_turn_has_centripetal_and_gnss():
    r = simulate("turn", duration=60, seed=2, straight_s=10, ramp_s=5)
    assert {"sog", "cog", "ref_cog"} <= set(r.channels)
    assert np.allclose(np.nanmedian(r["sog"]), 10.0, atol=0.1)
    late = r.time > 30
    f = r["ref_accel"][late]
    err = np.degrees(np.arctan2(-f[:, 1], -f[:, 2])) - r["ref_roll"][late]
    assert abs(err.mean()) > 2.5  # 10 m/s × 3 °/s ≈ 0.52 m/s² ≈ 3° of false tilt
    hd = np.unwrap(np.radians(r["ref_heading"]))
    assert abs(np.degrees(hd[-1] - hd[late][0]) / (r.time[-1] - r.time[late][0]) - 3.0) < 0.05


def test_static_long_is_cheap_and_still():
    r = simulate("static", duration=1800, rate_hz=100, seed=0, gyro_bias_instability_deg_s=0.01)
    assert len(r) == 180001
    assert np.allclose(r["ref_gyro"], 0.0)
    g = r["gyro"] - r["ref_gyro_bias"]
    assert abs(np.std(g[:, 0]) - np.radians(0.005) * 10) < 1e-4  # white noise σ = N·√fs


# --- ship-at-sea: a bridge sensor on a vessel in irregular seas, with a 360° turn (imutool.sim.voyage) ---

G_NED = np.array([0.0, 0.0, 9.80665])


def _body(q, v_ned):
    """Rᵀ v for each sample: a NED vector in body axes."""
    from formats.frames import quat_to_matrix

    return np.einsum("nji,nj->ni", quat_to_matrix(q), v_ned)


def test_ship_at_sea_gyro_integrates_to_truth():
    """Body rates come from the Euler-angle derivatives: the error-free gyro, integrated, stays on ref_q."""
    from formats.frames import quat_conjugate, quat_multiply

    r = simulate("ship-at-sea", duration=60, seed=4, noise=0, turn_start=5)
    assert np.array_equal(r["gyro"], r["ref_gyro"])  # noise=0: no noise, bias or quantisation
    t, w, q_ref = r.time, r["gyro"], r["ref_q"]
    q = q_ref[0].copy()
    worst = 0.0
    for k in range(len(t) - 1):
        h = t[k + 1] - t[k]
        rot = 0.5 * (w[k] + w[k + 1]) * h + np.cross(w[k], w[k + 1]) * h * h / 12  # with coning correction
        a = np.linalg.norm(rot)
        q = quat_multiply(q, np.r_[np.cos(a / 2), np.sinc(a / (2 * np.pi)) * rot / 2])
        e = quat_multiply(quat_conjugate(q_ref[k + 1]), q)
        worst = max(worst, 2 * np.degrees(np.arcsin(min(1.0, np.linalg.norm(e[1:])))))
    assert worst < 0.05
    # the motion is not trivial: the turn and the roll both happen in these 60 s
    assert np.ptp(np.unwrap(np.radians(r["ref_heading"]))) > np.radians(100)
    assert np.abs(r["ref_roll"]).max() > 15


def test_ship_at_sea_specific_force_from_position_track():
    """f = Rᵀ(a − g): the simulator's accelerometer (noise off) against finite differences of ref_pos."""
    for lever in ("0,0,0", (-30, 0, -20)):
        r = simulate("ship-at-sea", duration=40, seed=7, noise=0, turn_start=5, lever_arm=lever)
        p, h = r["ref_pos"], 1.0 / r.meta["rate_hz"]
        a = (p[2:] - 2 * p[1:-1] + p[:-2]) / h**2
        f = _body(r["ref_q"][1:-1], a - G_NED)
        assert np.abs(f - r["accel"][1:-1]).max() < 2e-3
        # ref_vel is the derivative of ref_pos
        assert np.abs((p[2:] - p[:-2]) / (2 * h) - r["ref_vel"][1:-1]).max() < 2e-3
    # the hull point's acceleration really is there: heave, turn centripetal (≈ 0.42 m/s²) and sway
    assert np.abs(a[:, 2]).max() > 0.8
    # at rest (calm water, no turn, no speed) the accelerometer reads −g on z
    calm = simulate("ship-at-sea", duration=5, seed=1, noise=0, severity=0, turn_rate_dps=0, speed_mps=0)
    assert np.allclose(calm["accel"], [0.0, 0.0, -9.80665], atol=1e-12)


def test_ship_at_sea_lever_arm_term():
    """f(r) − f(0) = ω̇ × r + ω × (ω × r), with ω̇ from finite differences of the truth rate."""
    lever = np.array([-30.0, 0.0, -20.0])
    r0 = simulate("ship-at-sea", duration=40, seed=5, noise=0, turn_start=5, lever_arm=(0, 0, 0))
    rb = simulate("ship-at-sea", duration=40, seed=5, noise=0, turn_start=5, lever_arm=lever)
    assert rb.meta["lever_arm_m"] == lever.tolist() and r0.meta["lever_arm_m"] == [0.0, 0.0, 0.0]
    assert np.array_equal(r0["ref_q"], rb["ref_q"])  # the lever arm does not change the sea
    h = 1.0 / r0.meta["rate_hz"]
    w = r0["ref_gyro"]
    wd = (w[2:] - w[:-2]) / (2 * h)
    w = w[1:-1]
    expect = np.cross(wd, lever) + np.cross(w, np.cross(w, lever))
    diff = (rb["accel"] - r0["accel"])[1:-1]
    assert np.abs(diff - expect).max() < 2e-3
    assert np.linalg.norm(expect, axis=1).max() > 1.0  # 20 m above the roll centre: metres per second squared
    assert np.abs(rb["ref_lever_accel"][1:-1] - expect).max() < 2e-3


def test_ship_at_sea_stresses_accelerometer_tilt():
    """Accelerometer-only roll at the bridge is off by more than 2° RMS during the turn (noise on)."""
    r = simulate("ship-at-sea", duration=200, seed=2, turn_start=30)
    f = r["accel"]
    err = np.degrees(np.arctan2(-f[:, 1], -f[:, 2])) - r["ref_roll"]
    turn = (r.time > 30) & (r.time < 160)
    assert np.sqrt(np.mean(err[turn] ** 2)) > 2.0
    # a drifting gyro bias (random walk on top of the constant one) and an accelerometer bias are present
    gb = r["ref_gyro_bias"]
    assert np.abs(gb[-1] - gb[0]).max() > 0 and np.abs(gb[0]).max() > 0
    assert np.abs(np.asarray(r.meta["accel_bias_m_s2"])).max() > 0


def test_ship_at_sea_turn_heel_gnss_and_sea():
    r = simulate("ship-at-sea", duration=200, seed=3, severity=0, turn_start=20)  # calm water: the turn alone
    v, rate = 8.0, np.radians(3.0)
    heel = -np.degrees(np.arctan(v * rate * 3.0 / (9.80665 * 2.0)))  # outward: port-down in a starboard turn
    steady = (r.time > 40) & (r.time < 130)
    assert abs(np.mean(r["ref_roll"][steady]) - heel) < 0.01 and -5 < heel < -2
    assert np.allclose(r["ref_rate_of_turn"][steady], 3.0, atol=1e-9)
    hd = np.unwrap(np.radians(r["ref_heading"]))
    assert abs(np.degrees(hd[-1] - hd[0]) - 360.0) < 1e-6
    # GNSS: 1 Hz fixes held between them, close to the truth
    sog, cog = r["sog"], r["cog"]
    changes = r.time[1:][np.diff(sog) != 0]
    assert np.allclose(changes, np.round(changes), atol=1e-9)
    assert np.abs(sog - r["ref_sog"]).max() < 0.3 and abs(np.median(sog) - v) < 0.05
    dcog = (cog - r["ref_cog"] + 180) % 360 - 180
    assert np.abs(dcog[steady]).max() < 5.0  # ≤ 1 s hold at 3 °/s plus noise
    # the sea: roll peak = roll_deg with no turn, heave ±2 m, deterministic per seed
    s = simulate("ship-at-sea", duration=120, seed=3, turn_rate_dps=0, noise=0)
    assert abs(np.abs(s["ref_roll"]).max() - 19.0) < 1e-9
    assert abs(np.abs(s["ref_heave"]).max() - 2.0) < 1e-9
    a, b = simulate("ship-at-sea", duration=20, seed=9), simulate("ship-at-sea", duration=20, seed=9)
    assert all(np.array_equal(a[k], b[k]) for k in a.channels)
    assert not np.array_equal(a["ref_roll"], simulate("ship-at-sea", duration=20, seed=10)["ref_roll"])


def test_ship_at_sea_cli_lever_arm(tmp_path):
    from click.testing import CliRunner

    import formats
    from imutool.cli import cli

    out = tmp_path / "voyage.csv"
    run = CliRunner().invoke(
        cli,
        [
            "simulate",
            "ship-at-sea",
            "-o",
            str(out),
            "--duration",
            "5",
            "--set",
            "lever_arm=-10,2,-15",
            "--set",
            "turn_rate_dps=0",
        ],
    )
    assert run.exit_code == 0, run.output
    rec = formats.read(str(out))
    assert list(rec.meta["lever_arm_m"]) == [-10.0, 2.0, -15.0]
    assert {"sog", "cog", "ref_sog", "ref_cog", "ref_q", "ref_roll", "ref_pos"} <= set(rec.channels)
    bad = CliRunner().invoke(
        cli, ["simulate", "ship-at-sea", "-o", str(tmp_path / "x.csv"), "--duration", "5", "--set", "lever_arm=1,2"]
    )
    assert bad.exit_code != 0 and "lever_arm" in str(bad.exception) and not (tmp_path / "x.csv").exists()


# --- ship-at-sea for the ship grid (issue 35): surge, roll to a significant amplitude, the ship's speed sources ---


def test_ship_at_sea_surge_is_a_translation_along_the_track_and_the_sea_stays():
    """Surge adds u(t) along the track (peak = surge_m) and nothing else; f is still Rᵀ(a − g) of the track."""
    kw = dict(duration=60, seed=11, noise=0, turn_rate_dps=0, lever_arm="0,0,0")
    r0 = simulate("ship-at-sea", **kw)
    r1 = simulate("ship-at-sea", surge_m=1.2, surge_period=7.0, **kw)
    for k in ("ref_q", "ref_heave", "ref_gyro"):
        assert np.array_equal(r0[k], r1[k])  # the same sea: surge draws from its own stream
    course = np.radians(30.0)
    e1, e2 = np.array([np.cos(course), np.sin(course), 0.0]), np.array([-np.sin(course), np.cos(course), 0.0])
    d = r1["ref_pos"] - r0["ref_pos"]
    along, across = d @ e1, d @ e2
    assert np.abs(across).max() < 1e-9 and np.abs(d[:, 2]).max() < 1e-9
    assert 1.2 <= np.ptp(along) <= 2.4 + 1e-9  # u − u(0) with max|u| = 1.2 m
    p, h = r1["ref_pos"], 1.0 / r1.meta["rate_hz"]
    a = (p[2:] - 2 * p[1:-1] + p[:-2]) / h**2
    assert np.abs(_body(r1["ref_q"][1:-1], a - G_NED) - r1["accel"][1:-1]).max() < 2e-3
    # a 7 s surge of 1.2 m is ≈ 0.97 m/s² along the track: really there
    assert np.abs((r1["accel"] - r0["accel"])[:, 0]).max() > 0.6
    assert r1.meta["surge_peak_m"] == 1.2 and "surge_peak_m" not in r0.meta


def test_ship_at_sea_accelerometer_at_the_lever_arm_is_the_hull_specific_force_within_noise():
    """Noise on: accel − Rᵀ(a_sensor − g) is the accelerometer bias plus white noise of the stated density."""
    lever = (-12.0, 3.0, -25.0)
    r = simulate("ship-at-sea", duration=60, seed=12, lever_arm=lever, sway_m=1.5, sway_period=6.0, surge_m=0.5)
    p, h = r["ref_pos"], 1.0 / r.meta["rate_hz"]
    a = (p[2:] - 2 * p[1:-1] + p[:-2]) / h**2  # the sensor's own track: hull motion and lever arm together
    resid = r["accel"][1:-1] - _body(r["ref_q"][1:-1], a - G_NED)
    bias = np.asarray(r.meta["accel_bias_m_s2"])
    sigma = 400e-6 * 9.80665 * np.sqrt(100.0)  # 400 µg/√Hz at 100 Hz: 0.039 m/s² per sample
    assert np.abs(resid.mean(axis=0) - bias).max() < 0.01
    assert np.all(np.abs(resid.std(axis=0) - sigma) < 0.2 * sigma)
    # and the lever arm's part is large against that noise (25 m above the roll centre)
    assert np.linalg.norm(r["ref_lever_accel"], axis=1).max() > 1.0


def test_ship_at_sea_smoothed_sog_has_no_sway_and_the_hull_velocity_has():
    kw = dict(duration=120, seed=13, turn_rate_dps=0, sway_m=1.5, sway_period=6.0, surge_m=0.8, surge_period=9.0)
    hull = simulate("ship-at-sea", **kw)
    smooth = simulate("ship-at-sea", speed_source="smoothed", **kw)
    # the hull's velocity: the sway's 1.57 m/s across an 8 m/s track swings the course by ±11°
    dc = (hull["cog"] - 30.0 + 180) % 360 - 180
    assert np.ptp(dc) > 10.0 and np.ptp(hull["sog"]) > 1.0
    # the receiver's track: the course and the speed, fix noise only (0.05 m/s on 8 m/s: 0.36°)
    dc = (smooth["cog"] - 30.0 + 180) % 360 - 180
    assert np.abs(dc).max() < 2.0 and np.abs(smooth["sog"] - 8.0).max() < 0.25
    assert np.std(smooth["sog"]) < 0.06
    assert smooth.meta["speed_source"] == "smoothed" and "speed_source" not in hull.meta
    for k in ("ref_q", "accel", "gyro", "ref_sog"):  # the same voyage and sensors: only the GNSS columns differ
        assert np.array_equal(hull[k], smooth[k])


def test_ship_at_sea_gnss_velocity_columns_at_the_antenna_and_no_speed_sources():
    arm = "-12,0,-23"
    kw = dict(duration=30, seed=14, noise=0, lever_arm=arm, turn_start=5)
    r = simulate("ship-at-sea", gnss_columns="both", antenna_arm=arm, **kw)
    assert {"sog", "cog", "vel_n", "vel_e"} <= set(r.channels)
    fixes = np.flatnonzero(np.diff(r.time % 1.0) < 0) + 1  # the rows where a new 1 Hz fix starts
    # antenna at the sensor's place: its fixes are the sensor's own velocity (roll-induced velocity included)
    assert np.abs(r["vel_n"][fixes] - r["ref_vel"][fixes, 0]).max() < 1e-9
    assert np.abs(r["vel_e"][fixes] - r["ref_vel"][fixes, 1]).max() < 1e-9
    assert np.allclose(np.hypot(r["vel_n"], r["vel_e"]), r["sog"])
    assert r.meta["antenna_arm_m"] == [-12.0, 0.0, -23.0]
    only = simulate("ship-at-sea", gnss_columns="vel", **kw)
    assert "sog" not in only.channels and "vel_n" in only.channels
    for src in ("log", "none"):
        x = simulate("ship-at-sea", speed_source=src, **kw)
        assert not {"sog", "cog", "vel_n", "vel_e"} & set(x.channels)
        assert x.meta["speed_source"] == src and np.array_equal(x["accel"], r["accel"])
    assert simulate("ship-at-sea", speed_source="log", **kw).meta["log_speed_mps"] == 8.0


def test_ship_at_sea_roll_to_a_significant_amplitude_and_refusals():
    import pytest

    from formats.errors import ImutoolError

    r = simulate("ship-at-sea", duration=300, seed=15, noise=0, turn_rate_dps=0, roll_significant_deg=25.0)
    assert abs(2 * np.std(r["ref_roll"]) - 25.0) < 0.05  # 2σ, no turn heel here
    assert r.meta["roll_significant_amplitude_deg"] == pytest.approx(25.0, abs=0.01)
    assert r.meta["roll_peak_deg"] > 25.0
    for bad in (dict(speed_source="radar"), dict(gnss_columns="nmea"), dict(antenna_arm="1,2"), dict(sway_period=0)):
        with pytest.raises(ImutoolError):
            simulate("ship-at-sea", duration=5, **bad)
