"""Issue 48 items 7 and 8: angles compared on the circle; a reference's frame declared, converted and checked; a
mounting never rotates the truth passed through (unless it is declared sensor→NED)."""

import json

import numpy as np
import pytest
from conftest import run_main

import formats
from formats import Recording
from formats.frames import (
    Q_ENU_TO_NED,
    Q_FLU_TO_FRD,
    angle_diff_deg,
    euler_to_quat,
    quat_conjugate,
    quat_multiply,
    quat_to_euler,
)
from imutool.evaluation import evaluate
from imutool.metrics import evaluate_angle


def _tilted(q: np.ndarray, deg: float, axis: int = 0) -> np.ndarray:
    """q followed by a small body rotation of ``deg`` about body axis ``axis``: an estimate ``deg`` off in tilt."""
    h = np.radians(deg) / 2
    d = np.zeros(4)
    d[0], d[1 + axis] = np.cos(h), np.sin(h)
    return quat_multiply(q, d)


def _truth(n: int = 3000, rate: float = 50.0, roll0: float = 0.0, pitch_amp: float = 8.0) -> Recording:
    t = np.arange(n) / rate
    roll = roll0 + 12 * np.sin(2 * np.pi * t / 9)
    pitch = pitch_amp * np.sin(2 * np.pi * t / 7)
    hdg = 40 + 30 * np.sin(2 * np.pi * t / 40)
    rec = Recording(t)
    rec.add("ref_q", euler_to_quat(*np.radians([roll, pitch, hdg])))
    return rec


def _estimate(truth: Recording, tilt_deg: float = 1.5) -> Recording:
    """The truth with q (and angles from it) ``tilt_deg`` off about the body x axis."""
    est = truth.copy()
    q = _tilted(truth["ref_q"], tilt_deg)
    est.add("q", q)
    for n, a in zip(("roll", "pitch", "heading"), quat_to_euler(q), strict=True):
        est.add(n, np.degrees(a), "deg")
    return est


# -- item 7: on the circle -------------------------------------------------------------------------------------
def test_angle_diff_is_on_the_circle_and_exact_inside():
    d = angle_diff_deg(
        np.array([179.0, -179.0, 180.0, -180.0, 540.0, 0.1, np.nan]), np.array([-179, 179, 0, 0, 0, 0, 0])
    )
    assert d[:4].tolist() == [-2.0, 2.0, 180.0, 180.0] and d[4] == 180.0 and d[5] == 0.1 and np.isnan(d[6])
    x = np.random.default_rng(1).uniform(-170, 170, 100)
    assert np.array_equal(angle_diff_deg(x, x / 3), x - x / 3)  # bit for bit inside ±180°


def test_roll_near_180_is_compared_on_the_circle():
    """A z-up sensor's roll sits near ±180° (BROAD): the reference at 10 Hz, the estimate at 100 Hz, 0.5° apart.
    Before: errors of ±360° at every crossing and interpolation across the circle (roll RMSE tens of degrees)."""
    tr = np.arange(0, 60, 0.1)
    te = np.arange(0, 59.9, 0.01)
    roll_ref = angle_diff_deg(180 + 6 * np.sin(2 * np.pi * tr / 5))  # wrapped to (−180, 180]
    roll_est = angle_diff_deg(180 + 6 * np.sin(2 * np.pi * te / 5) + 0.5)
    s = evaluate_angle(te, roll_est, tr, roll_ref)
    assert abs(s["rmse"] - 0.5) < 0.01 and s["max_abs"] < 0.6
    est = Recording(te, {"roll": roll_est})
    ref = Recording(tr, {"ref_roll": roll_ref})
    out = evaluate(est, ref)
    assert abs(out["angles"]["roll"]["rmse"] - 0.5) < 0.01


def test_plot_error_is_wrapped(tmp_path, monkeypatch):
    """evaluate's error plot draws the wrapped error (no ±360° spikes)."""
    import matplotlib.axes

    drawn = []
    real = matplotlib.axes.Axes.plot

    def spy(self, *a, **k):
        drawn.append(np.asarray(a[1], float) if len(a) > 1 else None)
        return real(self, *a, **k)

    monkeypatch.setattr(matplotlib.axes.Axes, "plot", spy)
    t = np.arange(0, 30, 0.05)
    roll = angle_diff_deg(180 + 5 * np.sin(t))
    rec = Recording(t, {"roll": angle_diff_deg(roll + 0.3), "ref_roll": roll})
    evaluate(rec, plot=tmp_path / "e.png")
    err = drawn[-1]
    assert np.nanmax(np.abs(err)) < 0.31


def test_pitch_near_90_roll_and_heading_left_out_inclination_right():
    """Pitch sweeping to 89.7°: a 0.3° tilt error about the body x axis turns Euler roll and heading by tens of
    degrees there. Roll and heading leave out those rows (counted); pitch and the quaternion stay right."""
    truth = _truth(pitch_amp=89.7)
    est = _estimate(truth, tilt_deg=0.3)
    out = evaluate(est)
    a = out["angles"]
    assert a["roll"]["excluded"] > 0 and a["heading"]["excluded"] == a["roll"]["excluded"]
    assert a["roll"]["max_abs"] < 3.5 and a["heading"]["max_abs"] < 3.5  # below 85° of pitch: bounded
    assert a["pitch"]["rmse"] < 0.3 and "excluded" not in a["pitch"]
    assert abs(out["quaternion"]["total"]["rmse"] - 0.3) < 0.001  # the whole error, about a near-vertical axis


def test_broad_roll_near_180_wrapped(shared):
    """BROAD trial 01 (sensor z up: reference roll near ±180°): an estimate 0.5° off the reference about the
    sensor's x axis. Roll RMSE ~0.5°, not tens of degrees."""
    path = shared("broad", "01_undisturbed_slow_rotation_A.csv")
    rec = formats.read(path)
    rec = rec.select(slice(0, 20000))
    ok = np.isfinite(rec["ref_q"]).all(axis=1)
    rec = rec.select(ok)
    est = Recording(rec.time.copy())
    est.add("q", _tilted(rec["ref_q"], 0.5))
    est.add("ref_q", rec["ref_q"])
    out = evaluate(est)
    roll = out["angles"]["roll"]
    r_deg = np.degrees(quat_to_euler(rec["ref_q"])[0])
    assert np.mean(np.abs(r_deg) > 150) > 0.5  # the case: roll near ±180°
    assert roll["rmse"] < 1.0, roll
    assert abs(out["quaternion"]["total"]["rmse"] - 0.5) < 0.001


# -- item 8: reference frames -------------------------------------------------------------------------------------
def _in_world(truth: Recording, w: np.ndarray) -> Recording:
    """The truth's ref_q expressed in another world: q_w = W* ⊗ q_ned (W rotates that world into NED)."""
    out = truth.copy()
    out.add("ref_q", quat_multiply(quat_conjugate(w), truth["ref_q"]))
    return out


@pytest.mark.parametrize("frame,w", [("enu", Q_ENU_TO_NED), ("zup", Q_FLU_TO_FRD)])
def test_reference_in_a_z_up_world_converted_and_detected(frame, w):
    truth = _truth()
    est = _estimate(truth, 1.5)
    ned = evaluate(est, truth)
    assert abs(ned["quaternion"]["inclination"]["rmse"] - 1.5) < 0.01 and "warnings" not in ned
    assert ned["reference_frame"]["vertical_disagreement_deg"] < 2.0
    other = _in_world(truth, w)
    raw = evaluate(est, other)  # undeclared: compared across frames, and said so
    assert raw["quaternion"]["inclination"]["rmse"] > 90
    assert any("--ref-frame" in x for x in raw["warnings"])
    conv = evaluate(est, other, ref_frame=frame)
    assert abs(conv["quaternion"]["inclination"]["rmse"] - ned["quaternion"]["inclination"]["rmse"]) < 0.01
    assert abs(conv["angles"]["roll"]["rmse"] - ned["angles"]["roll"]["rmse"]) < 0.01
    assert "warnings" not in conv and conv["reference_frame"]["world"] == frame
    assert conv["reference_frame"]["converted"] == ["ref_q", "ref_roll", "ref_pitch", "ref_heading"]


def test_reference_body_axes_declared_by_ref_mounting_and_angles_only():
    truth = _truth()
    est = _estimate(truth, 1.5)
    flu = truth.copy()
    flu.add("ref_q", quat_multiply(truth["ref_q"], Q_FLU_TO_FRD))  # a FLU marker set's orientation
    assert any("--ref-frame" in x for x in evaluate(est, flu)["warnings"])
    out = evaluate(est, flu, ref_mounting="x,-y,-z")
    assert abs(out["quaternion"]["inclination"]["rmse"] - 1.5) < 0.01 and "warnings" not in out
    # a reference of ZYX angles in an ENU world, no quaternion
    q_enu = quat_multiply(quat_conjugate(Q_ENU_TO_NED), truth["ref_q"])
    ang = Recording(truth.time.copy())
    for n, a in zip(("roll", "pitch", "heading"), quat_to_euler(q_enu), strict=True):
        ang.add(f"ref_{n}", np.degrees(a), "deg")
    bad = evaluate(est, ang)
    assert any("--ref-frame" in x for x in bad["warnings"])
    good = evaluate(est, ang, ref_frame="enu")
    ref_angles = evaluate(est, truth)["angles"]
    for n in ("roll", "pitch", "heading"):
        assert abs(good["angles"][n]["rmse"] - ref_angles[n]["rmse"]) < 0.01


def test_evaluate_cli_ref_frame_and_warning(tmp_path, capsys):
    truth = _truth()
    est = _estimate(truth, 1.5)
    est.remove("ref_q")
    pe, pr = tmp_path / "est.csv", tmp_path / "ref.csv"
    formats.write(est, pe)
    formats.write(_in_world(truth, Q_ENU_TO_NED), pr)
    code, out, err = run_main(["evaluate", str(pe), "--reference", str(pr), "--json"], capsys)
    assert code == 0 and "--ref-frame" in err
    code, out, err = run_main(["evaluate", str(pe), "--reference", str(pr), "--ref-frame", "enu", "--json"], capsys)
    s = json.loads(out)
    assert code == 0 and "--ref-frame" not in err and s["reference_frame"]["world"] == "enu"
    assert abs(s["quaternion"]["inclination"]["rmse"] - 1.5) < 0.01
    code, out, err = run_main(["evaluate", str(pe), "--reference", str(pr), "--ref-frame", "up"], capsys)
    assert code == 2


# -- item 8: a mounting leaves the truth alone ----------------------------------------------------------------------
def test_mounting_leaves_body_truth_and_turns_declared_sensor_truth():
    rng = np.random.default_rng(3)
    q = euler_to_quat(*np.radians(rng.uniform(-30, 30, (3, 20))))
    rec = Recording(np.arange(20.0), {"gyro": rng.standard_normal((20, 3)), "ref_q": q})
    m = rec.mounted("x,-y,-z")
    assert np.array_equal(m["ref_q"], q) and m.meta["ref_frame"] == "body"
    assert "not rotated" in m.meta["ref_mounting"]
    for meta in ({"ref_frame": "sensor"}, {"ref_q*": "optical motion-capture orientation, sensor->NED"}):
        s = Recording(rec.time, dict(rec.channels), meta=dict(meta)).mounted("x,-y,-z")
        dot = np.abs(np.sum(s["ref_q"] * quat_multiply(q, Q_FLU_TO_FRD), axis=1))  # q and −q: one rotation
        assert np.allclose(dot, 1.0) and s.meta["ref_frame"] == "body"
        assert "sensor→NED" in s.meta["ref_mounting"]


def test_filter_with_mounting_then_evaluate_small_error(tmp_path, capsys):
    """A simulated ship recorded by a FLU-mounted sensor, its truth body→NED: `filter --mounting x,-y,-z` then
    `evaluate` gives the filter's small error. Before: the mounting turned the passed-through ref_q too (~180°)."""
    from imutool.sim import simulate

    rec = simulate("ship-roll", duration=60, seed=7)
    flu = rec.copy()
    for k in ("gyro", "accel", "mag"):
        flu.channels[k] = rec[k] * np.array([1.0, -1.0, -1.0])
    src, out = tmp_path / "flu.csv", tmp_path / "est.csv"
    formats.write(flu, src)
    code, _, err = run_main(["filter", str(src), "-o", str(out), "--mounting", "x,-y,-z", "-q"], capsys)
    assert code == 0, err
    code, text, err = run_main(["evaluate", str(out), "--json"], capsys)
    s = json.loads(text)
    assert code == 0 and s["quaternion"]["inclination"]["rmse"] < 2.0, s["quaternion"]
    assert s["angles"]["roll"]["rmse"] < 2.0 and "warnings" not in s


def test_evaluate_start_end_window(tmp_path, capsys):
    """--start/--end compare only that window (an early transient left out)."""
    truth = _truth()
    est = _estimate(truth, 0.5)
    r = est["roll"].copy()
    r[truth.time < 10] += 20.0  # a filter still settling for 10 s
    est.add("roll", r, "deg")
    whole = evaluate(est)
    late = evaluate(est, start=10.0)
    assert whole["angles"]["roll"]["rmse"] > 5 and late["angles"]["roll"]["rmse"] < 0.6
    assert late["span"]["start_s"] >= 10.0
    mid = evaluate(est, start=20.0, end=30.0)
    assert 9.9 < mid["span"]["duration_s"] <= 10.0
    p = tmp_path / "e.csv"
    formats.write(est, p)
    code, out, _ = run_main(["evaluate", str(p), "--start", "10", "--end", "50", "--json"], capsys)
    assert code == 0 and json.loads(out)["angles"]["roll"]["rmse"] < 0.6
    code, _, err = run_main(["evaluate", str(p), "--start", "30", "--end", "20"], capsys)
    assert code == 2 and "--end" in err


def test_heading_report_reference_in_an_enu_world(tmp_path):
    """A heading report's reference gyro logged as ZYX angles in an ENU world (yaw from east): with --ref-frame enu
    the evidence equals the NED reference's; the conversion is recorded with the reference input."""
    from imutool.report.route import run_heading_report
    from imutool.sim.programmes import heading_test

    dut, ref, _ = heading_test(offset_deg=0.3, hold_s=15.0, rolling_s=40.0)
    ref.add("pitch", np.zeros(len(ref)), "deg")
    q_enu = quat_multiply(
        quat_conjugate(Q_ENU_TO_NED), euler_to_quat(*np.radians([ref["roll"], ref["pitch"], ref["heading"]]))
    )
    enu = ref.copy()
    for n, a in zip(("roll", "pitch", "heading"), quat_to_euler(q_enu), strict=True):
        enu.add(n, np.degrees(a), "deg")
    assert np.abs(angle_diff_deg(enu["heading"], ref["heading"])).max() > 45  # yaw from east is not heading
    paths = [tmp_path / n for n in ("dut.csv", "ref.csv", "enu.csv")]
    for rec, p in zip((dut, ref, enu), paths, strict=True):
        formats.write(rec, p)
    base = run_heading_report(paths[0], paths[1], tmp_path / "a.pdf").summary
    conv = run_heading_report(paths[0], paths[2], tmp_path / "b.pdf", ref_frame="enu")
    s = conv.summary
    assert s["overall"] == base["overall"]
    st, st0 = s["items"]["static"], base["items"]["static"]
    assert abs(st["max_abs"] - st0["max_abs"]) < 0.01 and abs(st["rmse"] - st0["rmse"]) < 0.01
    ev = conv.data["evidence"]
    ref_in = ev["inputs"]["reference"]
    assert ref_in["meta"]["reference_frame"]["world"] == "enu"


def test_broad_sensor_truth_follows_the_mounting_through_filter(shared, tmp_path, capsys):
    """BROAD declares its ref_q sensor→NED (its `ref_q*` header): `filter --mounting` turns it into body→NED with the
    sensor channels (stated in the output's metadata), so `evaluate` compares like with like either way."""
    rec = formats.read(shared("broad", "02_undisturbed_slow_rotation_B.csv")).select(slice(0, 15000))
    src = tmp_path / "b02.csv"
    formats.write(rec, src)
    errs = {}
    for mounting in (None, "y,x,-z"):
        out = tmp_path / f"est_{mounting is not None}.csv"
        extra = ["--mounting", mounting] if mounting else []
        code, _, err = run_main(["filter", str(src), "-o", str(out), "-q", *extra], capsys)
        assert code == 0, err
        code, text, err = run_main(["evaluate", str(out), "--json"], capsys)
        s = json.loads(text)
        assert code == 0 and "warnings" not in s
        errs[mounting] = s["quaternion"]["inclination"]["rmse"]
    assert errs[None] < 3.0 and abs(errs["y,x,-z"] - errs[None]) < 0.5, errs
    back = formats.read(tmp_path / "est_True.csv")
    assert back.meta["ref_frame"] == "body" and "sensor→NED" in back.meta["ref_mounting"]
