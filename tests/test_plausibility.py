"""Plausibility checks on every input (units, axes, absurd samples) and what validation did, in every summary."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_main as run
from conftest import shared_data

import formats
from formats.plausibility import bridge_absurd, check_recording, gyro_tilt_ratio
from imutool.sim import simulate


@pytest.fixture(scope="module")
def roll():
    return simulate("ship-roll", duration=60, seed=1)


def _foreign(
    rec,
    path,
    gyro_factor=1.0,
    accel_factor=1.0,
    mag_factor=1.0,
    names=("gx", "gy", "gz", "ax", "ay", "az", "mx", "my", "mz"),
):
    """A foreign CSV without units in the header, values scaled into another unit."""
    data = np.column_stack([rec.time, rec["gyro"] * gyro_factor, rec["accel"] * accel_factor, rec["mag"] * mag_factor])
    np.savetxt(path, data, delimiter=",", header="time," + ",".join(names), comments="", fmt="%.9g")
    return path


def test_clean_simulation_gives_no_warning_and_reports_validation(roll, tmp_path, capsys):
    p = tmp_path / "roll.csv"
    formats.write(roll, p)
    # the lever arm given: a ship recording too short for its estimate is told so (a warning of the filter's own)
    code, out, err = run(["filter", p, "-o", tmp_path / "est.csv", "--json", "--lever-arm", "0,0,0"], capsys)
    assert code == 0, err
    assert "warning" not in err
    s = json.loads(out)
    v = s["validation"][0]
    assert v["rows_read"] == v["rows_kept"] == len(roll) and v["rows_dropped"] == 0
    assert "warnings" not in s or not s["warnings"]
    r = gyro_tilt_ratio(roll)
    assert 0.8 < r["k"] < 1.3 and r["correlation"] > 0.8


def test_deg_per_s_gyro_without_units_warns_and_strict_refuses(roll, tmp_path, capsys):
    p = _foreign(roll, tmp_path / "dps.csv", gyro_factor=180 / np.pi)
    out_csv = tmp_path / "est.csv"
    code, out, err = run(["filter", p, "-o", out_csv, "--json"], capsys)
    assert code == 0
    assert "UNITS: gyro" in err and "deg/s" in err and "--columns 'gx=gyro_x:deg/s" in err
    s = json.loads(out)
    assert any("UNITS: gyro" in w for w in s["warnings"])
    header = [ln for ln in out_csv.read_text().splitlines() if ln.startswith("#")]
    assert any(ln.startswith("# warnings:") and "UNITS" in ln for ln in header)
    code, out, err = run(["filter", p, "-o", tmp_path / "est2.csv", "--strict"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "UNITS: gyro" in err
    assert not (tmp_path / "est2.csv").exists()
    # the fix named in the message works: no warning, rates now right
    code, out, err = run(["info", p, "--columns", "gx=gyro_x:deg/s,gy=gyro_y:deg/s,gz=gyro_z:deg/s"], capsys)
    assert code == 0 and "UNITS: gyro" not in err


def test_rad_per_s_values_under_a_deg_per_s_header_contradiction_warns(roll, tmp_path, capsys):
    p = _foreign(
        roll,
        tmp_path / "contra.csv",
        names=("gyro_x_dps", "gyro_y_dps", "gyro_z_dps", "ax", "ay", "az", "mx", "my", "mz"),
    )
    code, out, err = run(["info", p], capsys)
    assert code == 0
    assert "header declares gyro in dps" in err and "look like rad/s" in err


def test_accel_in_g_and_mag_in_gauss_without_units(roll, tmp_path, capsys):
    p = _foreign(roll, tmp_path / "g.csv", accel_factor=1 / 9.80665, mag_factor=0.01)
    code, out, err = run(["info", p], capsys)
    assert code == 0
    assert "UNITS: accelerometer" in err and "look like g" in err and "ax=accel_x:g" in err
    assert "UNITS: magnetometer" in err and "look like gauss" in err
    # no gyro warning: the gyro is fine (the direction of the accelerometer does not depend on its unit)
    assert "UNITS: gyro" not in err
    p2 = _foreign(roll, tmp_path / "mg.csv", accel_factor=1000 / 9.80665)
    code, out, err = run(["info", p2], capsys)
    assert "look like mg" in err


def test_z_up_sensor_warns_naming_mounting(roll, tmp_path, capsys):
    flu = roll.mounted("x,-y,-z")  # FRD → FLU: z up
    p = tmp_path / "flu.csv"
    formats.write(flu, p)
    code, out, err = run(["info", p], capsys)
    assert code == 0 and "AXES" in err and "--mounting x,-y,-z" in err
    code, out, err = run(["info", p, "--mounting", "x,-y,-z"], capsys)
    assert code == 0 and "AXES" not in err
    side = roll.mounted("z,y,-x")  # a sensor on its side: its −x axis points up
    rep = check_recording(side)
    assert any("AXES" in w and "along -x" in w for w in rep.warnings)
    fix = next(w for w in rep.warnings if "AXES" in w).split("--mounting ")[1].split(" ")[0]
    assert not any("AXES" in w for w in check_recording(side.mounted(fix)).warnings)


def test_xio_csv_without_mounting_gives_z_up_warning(capsys):
    p = shared_data("fusion", "sensor_data.csv")
    code, out, err = run(["info", p], capsys)
    assert code == 0
    assert "AXES" in err and "+z" in err and "--mounting x,-y,-z" in err
    assert "UNITS" not in err  # its header states deg/s and g, and the values agree
    code, out, err = run(["info", p, "--mounting", "x,-y,-z"], capsys)
    assert "AXES" not in err


def test_xio_csv_with_the_units_stripped_gives_units_warnings(tmp_path, capsys):
    src = shared_data("fusion", "sensor_data.csv").read_text().splitlines()
    hdr = src[0].replace(" (deg/s)", "").replace(" (g)", "")
    p = tmp_path / "xio.csv"
    p.write_text("\n".join([hdr, *src[1:]]) + "\n")
    code, out, err = run(["info", p, "--mounting", "x,-y,-z"], capsys)
    assert "UNITS: gyro" in err and "deg/s" in err
    assert "UNITS: accelerometer" in err and "look like g" in err


def test_repeated_timestamps_dropped_are_counted_and_warned(roll, tmp_path, capsys):
    r = roll.select(slice(0, 3000))
    r.time = np.floor(r.time / 0.015) * 0.015  # a logger stamping on arrival: ~3 rows per stamp
    p = tmp_path / "dup.csv"
    formats.write(r, p)
    code, out, err = run(["filter", p, "-o", tmp_path / "o.csv", "--json"], capsys)
    assert code == 0
    assert "DROPPED" in err and "repeated timestamp" in err and "--duplicates mean" in err
    v = json.loads(out)["validation"][0]
    assert v["rows_read"] == 3000 and v["rows_kept"] == len(np.unique(r.time))
    assert v["rows_dropped"] == 3000 - v["rows_kept"] and sum(v["dropped"].values()) == v["rows_dropped"]
    code, out, err = run(["filter", p, "-o", tmp_path / "o1.csv"], capsys)
    assert f"3000 rows read, {v['rows_kept']} kept (dropped: {v['rows_dropped']} repeated" in out  # plain summary
    code, out, err = run(["filter", p, "-o", tmp_path / "o2.csv", "--strict"], capsys)
    assert code == 2 and "DROPPED" in err


@pytest.mark.parametrize("cmd", ["filter", "heave"])
def test_one_absurd_sample_does_not_poison_the_estimate(cmd, roll, tmp_path, capsys):
    clean = tmp_path / "clean.csv"
    formats.write(roll, clean)
    bad = roll.copy()
    bad["gyro"][3000, 0] = 1e200
    bad["accel"][4000, 2] = 1e200
    bad["accel"][5000:5040, 1] = np.inf  # a 0.2 s run
    p = tmp_path / "bad.csv"
    formats.write(bad, p)
    code, out, err = run([cmd, clean, "-o", tmp_path / "a.csv", "-q"], capsys)
    assert code == 0, err
    code, out, err = run([cmd, p, "-o", tmp_path / "b.csv", "--json"], capsys)
    assert code == 0, err
    assert "absurd gyro" in err and "absurd accel" in err
    v = json.loads(out)["validation"][0]
    assert v["absurd_samples_interpolated"] == {"gyro": 1, "accel": 41}
    a, b = formats.read(tmp_path / "a.csv"), formats.read(tmp_path / "b.csv")
    col = "roll" if cmd == "filter" else "heave"
    assert np.all(np.isfinite(b[col]))
    tol = 0.5 if cmd == "filter" else 0.05  # deg, m
    assert np.max(np.abs(a[col] - b[col])) < tol


def test_bridge_absurd_library_rules(roll):
    r = roll.copy()
    r["gyro"][10, 2] = -1e300
    r["gyro"][2000:2110, 0] = 1e9  # a 0.55 s run: too long to interpolate → NaN
    out, rep = bridge_absurd(r)
    assert np.isfinite(out["gyro"][10]).all() and np.allclose(
        out["gyro"][10], (r["gyro"][9] + r["gyro"][11]) / 2, atol=1e-12
    )
    assert np.isnan(out["gyro"][2000:2110, 0]).all() and rep.set_nan == {"gyro": 110} and rep.bridged == {"gyro": 1}
    assert r["gyro"][10, 2] == -1e300  # input untouched
    # most samples beyond range: a units problem, left alone and said
    r2 = roll.copy()
    r2["gyro"][:] = 1e3
    out2, rep2 = bridge_absurd(r2)
    assert out2 is r2 and any("unit or scale error" in w for w in rep2.warnings)


def test_filter_skips_a_long_run_set_to_nan(roll, tmp_path, capsys):
    """A run too long to interpolate becomes NaN; the attitude EKF skips those rows and recovers."""
    clean = tmp_path / "clean.csv"
    formats.write(roll, clean)
    bad = roll.copy()
    bad["gyro"][3000:3110, 0] = 1e200  # 0.55 s
    p = tmp_path / "bad.csv"
    formats.write(bad, p)
    assert run(["filter", clean, "-o", tmp_path / "a.csv", "-q"], capsys)[0] == 0
    code, out, err = run(["filter", p, "-o", tmp_path / "b.csv", "--json"], capsys)
    assert code == 0 and json.loads(out)["validation"][0]["absurd_samples_set_nan"] == {"gyro": 110}
    a, b = formats.read(tmp_path / "a.csv"), formats.read(tmp_path / "b.csv")
    after = b.time > 16.0  # 0.5 s after the run
    assert np.all(np.isfinite(b["roll"][after]))
    assert np.max(np.abs(a["roll"][after] - b["roll"][after])) < 1.0


def test_corrupt_bag_chunks_are_reported_not_silent(tmp_path, capsys):
    data = bytearray(shared_data("rosbags", "robot_localization", "test2.bag").read_bytes())
    rng = np.random.default_rng(1)
    for i in rng.integers(len(data) // 3, len(data), 16):
        data[i] ^= 1 << int(rng.integers(0, 8))
    p = tmp_path / "flipped.bag"
    p.write_bytes(bytes(data))
    code, out, err = run(["filter", p, "-o", tmp_path / "o.csv", "--json"], capsys)
    assert code == 0 and "DROPPED" in err and "skipped" in err
    assert any("DROPPED" in w for w in json.loads(out)["warnings"])
    code, out, err = run(["filter", p, "-o", tmp_path / "o2.csv", "--strict"], capsys)
    assert code == 2 and "DROPPED" in err


def test_every_estimate_says_what_was_wrong_with_its_input(roll, tmp_path, capsys):
    """The warnings and the validation report of an input travel into the metadata of every estimate built from
    it — heave, ZVI flags, the attitude and the roll statistics of that attitude — not only to stderr."""
    bad = roll.copy()
    bad.channels["gyro"] = np.degrees(roll["gyro"])  # deg/s under a rad/s header
    bad.channels["gyro"][1000:1002] = 1e6  # two corrupt samples
    src = tmp_path / "bad.csv"
    formats.write(bad, src)
    outs = {
        "heave": ["heave", src, "-o", tmp_path / "heave.csv"],
        "zvi": ["zvi", src, "-o", tmp_path / "zvi.csv", "--flags", tmp_path / "zvi_flags.csv"],
        "filter": ["filter", src, "-o", tmp_path / "filter.csv"],
        "roll": ["roll", tmp_path / "filter.csv", "-o", tmp_path / "roll.csv"],
    }
    for name, args in outs.items():
        code, _, err = run([*args, "-q"], capsys)
        assert code == 0, (name, err)
        path = tmp_path / ("zvi_flags.csv" if name == "zvi" else f"{name}.csv")
        meta = formats.read(path).meta
        assert any(w.startswith("UNITS: gyro") for w in meta.get("warnings", [])), name
        assert any("2 absurd gyro sample(s)" in w for w in meta["warnings"]), name
        assert meta["validation"]["rows_kept"] == len(roll), name


UPSIDE_DOWN = np.array([1.0, -1.0, -1.0])  # body vectors rotated 180° about x


def _upside_down(rec):
    out = rec.copy()
    for c in ("gyro", "accel", "mag"):
        out.channels[c] = rec[c] * UPSIDE_DOWN
    return out


def test_a_mast_sensor_upside_down_is_not_a_gyro_unit_error(tmp_path, capsys):
    """A Phidgets-style bag: the IMU upside down, the gyro right, the sensor high above a fast roll. The
    accelerometer's direction swings by 1 + hω²/g of the roll (≈ 9 here): no unit's factor, and the window-pair
    test of the filter's own gyro check finds the gyro right — no UNITS claim, and --strict takes the file."""
    pytest.importorskip("rosbags", reason="bags need rosbags")
    rec = simulate("ship-roll", duration=60, seed=1, lever_z_m=-5.0, roll_period_s=1.6, roll_amplitude_deg=2.0)
    up = _upside_down(rec)
    rep = check_recording(up)
    assert rep.figures["gyro_tilt_slope"] > 7.5  # the short-step slope that the old check took for a unit error
    assert not any(w.startswith("UNITS") for w in rep.warnings), rep.warnings
    bag = tmp_path / "phidgets.bag"
    formats.write(up, bag)
    code, out, err = run(["info", bag], capsys)
    assert code == 0 and "UNITS" not in err and "AXES" in err
    code, out, err = run(["filter", bag, "-o", tmp_path / "est.csv", "--mounting", "x,-y,-z", "--strict"], capsys)
    assert code == 0, err
    assert "UNITS" not in err and "gyro scale check" not in err  # and the filter's own check agrees


def test_a_real_gyro_unit_error_in_a_bag_is_still_caught(roll, tmp_path, capsys):
    """deg/s written into a bag's angular_velocity (rad/s): named, with the --columns fix that works on a bag."""
    pytest.importorskip("rosbags", reason="bags need rosbags")
    bad = roll.copy()
    bad.channels["gyro"] = np.degrees(roll["gyro"])
    bag = tmp_path / "dps.bag"
    formats.write(bad, bag)
    code, out, err = run(["info", bag], capsys)
    assert code == 0 and "UNITS: gyro" in err and "look like deg/s" in err
    assert "the bag's sensor_msgs/Imu carries gyro in rad/s" in err and "header" not in err
    fix = err.split("--columns ")[1].split()[0].strip("'")
    assert fix == "gyro_x=gyro_x:deg/s,gyro_y=gyro_y:deg/s,gyro_z=gyro_z:deg/s"
    code, out, err = run(["info", bag, "--columns", fix, "--json"], capsys)
    assert code == 0 and "UNITS" not in err
    rep = check_recording(formats.read(bag))  # the library: a unit error at sea is confirmed, not only guessed
    assert rep.figures["gyro_window_check"]["discrepancy_rescaled_deg"] < 3.0


def test_z_up_after_a_bags_rep103_conversion_names_the_sensors_mounting(roll, tmp_path, capsys):
    """A bag is converted from REP-103 FLU at the reader: +z up afterwards is the sensor's own mounting (upside
    down by ROS), not the FLU convention; the fix named stays --mounting x,-y,-z."""
    pytest.importorskip("rosbags", reason="bags need rosbags")
    bag = tmp_path / "updown.bag"
    formats.write(_upside_down(roll), bag)
    code, out, err = run(["info", bag], capsys)
    axes = next(ln for ln in err.splitlines() if "AXES" in ln)
    assert "FLU/ENU-style" not in axes and "e.g. x-io" not in axes
    assert "already" in axes or "after the bag's REP-103" in axes
    assert "mounted" in axes and "--mounting x,-y,-z" in axes
    code, out, err = run(["info", bag, "--mounting", "x,-y,-z"], capsys)
    assert code == 0 and "AXES" not in err


def test_a_unit_error_found_in_a_stream_holds_for_the_rest_of_it(roll, tmp_path):
    """A channel absurd throughout, streamed in many chunks: each chunk judged alone against the rows seen so
    far would be 1 % of them from the 100th chunk on, and a short last chunk at once, and be set to NaN; once a
    chunk showed the unit error, every later chunk is left as it is too, and no NaN is reported."""
    from imutool.loading import ChunkChecks

    wrong = roll.copy()  # 12 001 rows: 120 chunks of 100 rows and a last one of 1
    assert len(wrong) % 100 and len(wrong) > 100 * 100
    wrong["gyro"][:] = 1e3
    checks = ChunkChecks(str(tmp_path / "in.csv"))
    parts = [checks.prepare(wrong.select(slice(i, i + 100))) for i in range(0, len(wrong), 100)]
    assert np.all(np.concatenate([p["gyro"] for p in parts]) == 1e3)
    warnings = checks.finish(len(wrong), len(wrong))[1]
    assert [w for w in warnings if "absurd gyro" in w or "unit or scale error" in w] == [
        w for w in warnings if f"{len(wrong)} of {len(wrong)} gyro samples" in w
    ]
    assert len(warnings) >= 1


def test_a_streamed_voyage_that_starts_in_harbour_is_checked_on_its_motion(tmp_path, monkeypatch):
    """The plausibility checks of a stream look at the stretches an in-memory load looks at, across the whole
    file (its expected rows), not at the first chunk: a gyro in deg/s declared rad/s, still for the first
    third (in harbour), is found in chunks of any size, with the whole-file check's warning, once the last
    stretch is in; judged on the first chunk alone (no size known) it is not. The rows checked are the
    whole-file sample's."""
    import formats.plausibility as plaus
    from imutool.loading import ChunkChecks

    rec = simulate("ship-roll", duration=450, seed=2)  # 90 001 rows: six stretches of 10 000 are sampled
    n, h = len(rec), len(rec) // 3
    rec["gyro"][:h] = 0.0
    rec["accel"][:h] = rec["accel"][h]
    rec["mag"][:h] = rec["mag"][h]
    rec["gyro"][h:] *= 180 / np.pi  # deg/s read as rad/s
    whole = check_recording(rec).warnings
    assert len(whole) == 1 and whole[0].startswith("UNITS: gyro rates are")
    checked = []
    real = plaus.check_recording
    monkeypatch.setattr(plaus, "check_recording", lambda r, *a, **k: checked.append(r) or real(r, *a, **k))

    def streamed(chunk_rows, rows_expected):
        checked.clear()
        checks = ChunkChecks(str(tmp_path / "in.csv"), rows_expected=rows_expected)
        for i in range(0, n, chunk_rows):
            checks.prepare(rec.select(slice(i, i + chunk_rows)))
            if rows_expected == n and i + chunk_rows >= n:
                assert checks.warnings == whole  # checked before the end, once the last stretch is in
        return checks.finish(n, n)[1]

    sample = plaus.sample_rows(rec)
    for chunk_rows in (7_000, 20_000, n):
        assert streamed(chunk_rows, n) == whole, chunk_rows
        assert len(checked) == 1
        np.testing.assert_array_equal(checked[0].time, sample.time)
        np.testing.assert_array_equal(checked[0]["gyro"], sample["gyro"])
    assert streamed(20_000, None) == []  # the first chunk alone: still, nothing to see
    # an estimate above the file's rows (a CSV's): the stretches read so far are checked at the end
    late = streamed(20_000, n + 3_000)
    assert len(late) == 1 and late[0].startswith("UNITS: gyro rates are")
