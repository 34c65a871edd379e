"""Issue 48 item 10 (parts): `--with` merges two logs of one kind (`--with-prefix`) and keeps each file on its own
clock where the command needs no grid (evaluate); `events detect` takes the loading options every command takes."""

import json

import numpy as np
from conftest import run_main

import formats
from formats import Recording
from formats.frames import euler_to_quat
from imutool.evaluation import run_evaluate
from imutool.loading import load_recording


def _imu(path, t, k: float) -> None:
    rec = Recording(t)
    rec.add("gyro", np.column_stack([t * 0 + k, t * 0, t * 0.01]))
    rec.add("accel", np.tile([0.0, 0.0, -9.81], (len(t), 1)))
    formats.write(rec, path)


def test_two_logs_of_one_kind_with_prefix(tmp_path, capsys):
    a, b = tmp_path / "imu1.csv", tmp_path / "imu2.csv"
    _imu(a, np.arange(0, 10, 0.01), 0.1)
    _imu(b, np.arange(0.003, 10, 0.02), 0.2)
    code, _, err = run_main(["info", str(a), "--with", str(b)], capsys)  # before: the only answer
    assert code == 2 and "--with-prefix" in err
    rec, report = load_recording(a, with_files=[str(b)], with_prefixes=["imu2_"])
    assert {"gyro", "accel", "imu2_gyro", "imu2_accel"} <= set(rec.channels)
    assert np.allclose(rec["imu2_gyro"][:, 0], 0.2) and np.allclose(rec["gyro"][:, 0], 0.1)
    assert rec.meta["merged"]["files"][1]["prefix"] == "imu2_" and "one grid" in rec.meta["merged"]["time_base"]
    out = tmp_path / "both.csv"
    code, _, err = run_main(["convert", str(a), str(out), "--with", str(b), "--with-prefix", "imu2_"], capsys)
    back = formats.read(out)
    assert code == 0 and "imu2_gyro_x" in back.column_names() and "imu2_gyro" in back.channels
    code, _, err = run_main(["info", str(a), "--with-prefix", "x_"], capsys)
    assert code == 2 and "give the file too" in err
    code, _, err = run_main(["info", str(a), "--with", str(b), "--with-prefix", "2bad"], capsys)
    assert code == 2 and "--with-prefix" in err


def test_with_keeps_its_own_clock_for_evaluate(tmp_path, capsys):
    """An estimate at 50 Hz and its truth in a file of its own at 7 Hz on a clock 0.004 s apart: `evaluate
    --with` keeps both on their own samples (no resampling: the recording's rows are the union, one stream per
    file), and compares as with --reference."""
    te = np.arange(0, 60, 0.02)
    tr = np.arange(0.004, 60, 1 / 7)
    roll = lambda t: 8 * np.sin(2 * np.pi * t / 9)  # noqa: E731
    est = Recording(te, {"roll": roll(te) + 0.25})
    est.add("q", euler_to_quat(np.radians(roll(te) + 0.25), 0.0 * te, 0.0 * te))
    ref = Recording(tr, {"ref_roll": roll(tr)})
    ref.add("ref_q", euler_to_quat(np.radians(roll(tr)), 0.0 * tr, 0.0 * tr))
    pe, pr = tmp_path / "est.csv", tmp_path / "truth.csv"
    formats.write(est, pe)
    formats.write(ref, pr)
    rec, _ = load_recording(pe, with_files=[str(pr)], with_clock="own")
    assert len(rec) == len(np.union1d(te, tr)) and rec.multi_clock
    assert rec.own_rows("ref_roll").sum() == len(tr) and rec.own_rows("roll").sum() == len(te)
    t_own, v_own = rec.series("ref_roll")
    assert np.array_equal(t_own, tr) and np.array_equal(v_own, roll(tr))  # its own samples, untouched
    joined = run_evaluate(pe, with_files=(str(pr),)).summary
    apart = run_evaluate(pe, pr).summary
    assert abs(joined["angles"]["roll"]["rmse"] - 0.25) < 0.01
    assert abs(joined["angles"]["roll"]["rmse"] - apart["angles"]["roll"]["rmse"]) < 1e-3
    assert joined["angles"]["roll"]["n"] == apart["angles"]["roll"]["n"]
    assert (
        abs(joined["quaternion"]["total"]["rmse"] - 0.25) < 0.01
        and joined["quaternion"]["n"] == apart["quaternion"]["n"]
    )
    code, out, err = run_main(["evaluate", str(pe), "--with", str(pr), "--json"], capsys)
    s = json.loads(out)
    assert code == 0 and abs(s["angles"]["roll"]["rmse"] - 0.25) < 0.01


def test_events_detect_takes_the_loading_options(tmp_path, capsys):
    """A logger's CSV: a ms time column and a heel column of its own name. Before: no such options (usage error)."""
    t = np.arange(0, 1200, 0.5)
    heel = 30 * np.sin(2 * np.pi * t / 12) * (t > 600)  # heavy roll in the second half
    p = tmp_path / "logger.csv"
    with open(p, "w") as f:
        f.write("stamp_ms,HeelDeg\n")
        for a, b in zip(t, heel, strict=True):
            f.write(f"{a * 1000:.0f},{b:.4f}\n")
    canon = tmp_path / "canon.csv"
    formats.write(Recording(t, {"roll": heel}), canon)
    code, out, err = run_main(["events", "detect", str(canon), "--json"], capsys)
    want = json.loads(out)
    assert code == 0 and want["heavy_roll_events"] >= 1
    code, out, err = run_main(
        [
            "events",
            "detect",
            str(p),
            "--columns",
            "HeelDeg=roll:deg",
            "--time-column",
            "stamp_ms:ms",
            "--json",
        ],
        capsys,
    )
    assert code == 0, err
    got = json.loads(out)
    assert got["heavy_roll_events"] == want["heavy_roll_events"] and got["max_heel_deg"] == want["max_heel_deg"]
    assert got["validation"][0]["input"] == str(p)
