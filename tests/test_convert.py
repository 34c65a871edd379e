"""`imutool convert`: csv ↔ bag ↔ nmea through the CLI, streaming csv → csv, summaries and errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from formats import Recording
from formats.bags import read_bag
from formats.csv import read_csv, write_csv
from formats.frames import euler_to_quat
from imutool.cli import main

RL = ("rosbags", "robot_localization")


def run(args: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as e:
        main([str(a) for a in args])
    out = capsys.readouterr()
    return e.value.code, out.out, out.err


@pytest.fixture
def csv_in(tmp_path) -> Path:
    rng = np.random.default_rng(4)
    n = 300
    rec = Recording(np.arange(n) * 0.02)
    rec.add("gyro", rng.normal(size=(n, 3)) * 0.1)
    rec.add("accel", rng.normal(size=(n, 3)) * 0.2 + [0, 0, -9.81])
    rec.add("mag", rng.normal(size=(n, 3)) + [20, 1, 44])
    roll, pitch, hdg = rng.uniform(-10, 10, n), rng.uniform(-5, 5, n), rng.uniform(0, 359, n)
    rec.add("q", euler_to_quat(np.radians(roll), np.radians(pitch), np.radians(hdg)))
    rec.add("heading", hdg)
    rec.add("roll", roll)
    rec.add("pitch", pitch)
    rec.add("ref_roll", roll + 0.1)
    p = tmp_path / "in.csv"
    write_csv(rec, p)
    return p


@pytest.mark.parametrize(
    "ext",
    [".bag", *(pytest.param(e, marks=pytest.mark.slow) for e in (".db3", ".mcap", "_folder"))],
)
def test_csv_bag_csv_cli(tmp_path, csv_in, capsys, ext):
    bag = tmp_path / f"out{ext}"
    code, out, err = run(["convert", csv_in, bag, "--json"], capsys)
    assert code == 0, err
    s = json.loads(out)
    assert s["rows_in"] == 300 and s["rows_out"] == 300
    assert s["messages_out"] == {"/imu/data": 300, "/imu/mag": 300}
    # never silent about what an Imu/MagneticField message cannot carry
    assert set(s["channels_not_written"]) == {"roll", "pitch", "heading", "ref_roll"}
    assert any("FRD → FLU" in c for c in s["conversions"])
    back = tmp_path / "back.csv"
    code, out, err = run(["convert", bag, "-o", back], capsys)
    assert code == 0, err
    assert "rows in 300, rows out 300" in out and "frame conversions: in:" in out
    a, b = read_csv(csv_in), read_csv(back)
    assert np.max(np.abs(a.time - b.time)) <= 1e-9
    assert np.array_equal(a["gyro"], b["gyro"]) and np.array_equal(a["accel"], b["accel"])
    assert np.allclose(a["mag"], b["mag"], rtol=4e-16, atol=0)
    assert np.allclose(a["q"], b["q"], rtol=0, atol=5e-16)


def test_real_bag_to_csv(shared, tmp_path, capsys):
    src = shared(*RL, "test2.bag")
    out_csv = tmp_path / "imu.csv"
    code, out, err = run(["convert", src, out_csv, "--topic", "/imu/data", "--stamp", "record"], capsys)
    assert code == 0, err
    assert "frame_id ['base_link']" in out and "time = record stamp" in out
    rec = read_csv(out_csv)
    ref = read_bag(src, stamp="record")
    assert len(rec) == 3061
    for k in ref.channels:
        assert np.array_equal(rec[k], ref[k]), k
    assert rec.meta["bag"]["stamp"] == "record"


def test_streaming_csv_to_csv_matches_whole_file(tmp_path, csv_in, capsys):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    code, out, _ = run(["convert", csv_in, a, "--chunk-rows", "37"], capsys)
    assert code == 0 and "(streamed)" in out
    code, out, _ = run(["convert", csv_in, b, "--no-stream"], capsys)
    assert code == 0 and "(streamed)" not in out
    ra, rb = read_csv(a), read_csv(b)
    assert np.array_equal(ra.time, rb.time)
    for k in rb.channels:
        assert np.array_equal(ra[k], rb[k]), k


def test_streaming_handles_duplicates_across_chunks(tmp_path, capsys):
    n = 50
    t = np.arange(n) * 0.1
    t[25] = t[24]  # a duplicate that falls on a chunk boundary with --chunk-rows 25
    rec = Recording(t, {"gyro": np.zeros((n, 3))})
    src = tmp_path / "dup.csv"
    write_csv(rec, src)
    code, out, _ = run(["convert", src, tmp_path / "o.csv", "--chunk-rows", "25", "--json"], capsys)
    assert code == 0
    s = json.loads(out)
    assert s["rows_in"] == 50 and s["rows_out"] == 49
    code, _, err = run(["convert", src, tmp_path / "o2.csv", "--chunk-rows", "25", "--duplicates", "error"], capsys)
    assert code == 2 and "duplicate" in err and not (tmp_path / "o2.csv").exists()


def test_csv_to_nmea(tmp_path, csv_in, capsys):
    out_nmea = tmp_path / "o.nmea"
    code, out, err = run(["convert", csv_in, out_nmea, "--sentences", "HDT", "--json"], capsys)
    assert code == 0, err
    s = json.loads(out)
    lines = out_nmea.read_text().splitlines()
    assert s["sentences_out"]["HDT"] == len(lines) > 0
    assert all(line.startswith("$") and "HDT" in line for line in lines)


def test_ambiguous_topics_error(tmp_path, csv_in, capsys):
    """Two Imu topics and no --topic: one line listing topics with types and counts, exit status 2."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    one = tmp_path / "one.bag"
    run(["convert", csv_in, one, "--quiet"], capsys)
    ts = get_typestore(Stores.ROS1_NOETIC)
    from formats.bags.ros1 import Ros1Bag as _Ros1Bag

    bag = _Ros1Bag(str(one))
    imu = next(t for t in bag.topics().values() if t.name == "/imu/data")
    raw = bag.raw(imu)
    two = tmp_path / "two.bag"
    with Writer(two) as w:
        for name in ("/imu/a", "/imu/b"):
            c = w.add_connection(name, "sensor_msgs/msg/Imu", typestore=ts)
            for o, n, t in zip(raw.offs, raw.lens, raw.rec_ns, strict=True):
                w.write(c, int(t), raw.buf[o : o + n].tobytes())
    code, _, err = run(["convert", two, tmp_path / "x.csv"], capsys)
    assert code == 2
    assert err.count("\n") == 1 and "/imu/a (sensor_msgs/msg/Imu, 300 msgs)" in err and "--topic" in err
    code, out, err = run(["convert", two, tmp_path / "x.csv", "--topic", "/imu/b"], capsys)
    assert code == 0, err


def test_truncated_bag_reports_partial_read(shared, tmp_path, capsys):
    data = Path(shared(*RL, "test1.bag")).read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) // 2])
    code, out, err = run(["convert", cut, tmp_path / "c.csv"], capsys)
    assert code == 0, err
    assert "WARNING: truncated bag:" in out and "messages recovered" in out
    cut.write_bytes(data[:3000])
    code, out, err = run(["convert", cut, tmp_path / "d.csv"], capsys)
    assert code == 2 and "truncated" in err and "Traceback" not in err


def test_bag_to_nmea_derives_heading_from_q(shared, tmp_path, capsys):
    """test2.bag orientation: ENU yaw 20.7° (q_z 0.1796, q_w 0.9832) is heading 69.3° in NED."""
    out_nmea = tmp_path / "t2.nmea"
    code, out, err = run(["convert", shared(*RL, "test2.bag"), out_nmea, "--sentences", "HDT"], capsys)
    assert code == 0, err
    assert "derived from q" in out
    first = out_nmea.read_text().splitlines()[0]
    assert first.split(",")[1] == "69.3"


@pytest.mark.parametrize(
    "ext,extra",
    [
        (".parquet", []),
        (".bag", []),
        (".nmea", ["--sentences", "HDT,XDR"]),
        (".csv", ["--no-stream", "--mounting", "x,-y,-z"]),
    ],
)
def test_python_convert_equals_cli(tmp_path, csv_in, capsys, ext, extra):
    """imutool.convert.run_convert (the library route) writes what `imutool convert` writes and returns its summary."""
    import formats
    from imutool.convert import run_convert

    a, b = tmp_path / f"cli{ext}", tmp_path / f"lib{ext}"
    code, out, err = run(["convert", csv_in, a, "--json", *extra], capsys)
    assert code == 0, err
    kw = {"stream": "--no-stream" not in extra, "sentences": "HDT,XDR"}
    if "--mounting" in extra:
        kw["mounting"] = "x,-y,-z"
    s = run_convert(csv_in, b, **kw).summary
    cli = json.loads(out)
    assert {k: v for k, v in s.items() if k != "output"} == {k: cli[k] for k in s if k != "output"}
    if ext == ".nmea":
        assert a.read_text() == b.read_text() and a.read_text().count("$") > 100
        return
    ra, rb = formats.read(a), formats.read(b)
    assert len(ra) == len(rb) == 300 and np.array_equal(ra.time, rb.time)
    for k in ra.channels:
        assert np.array_equal(ra[k], rb[k], equal_nan=True), k
    if "--mounting" in extra:  # x,-y,-z: y and z flip sign
        assert np.allclose(ra["gyro"][:, 1], -read_csv(csv_in)["gyro"][:, 1])


def test_python_convert_progress_and_refusals(tmp_path, csv_in):
    from formats.errors import ImutoolError
    from imutool.convert import run_convert, streams

    calls: list[tuple[int, int | None]] = []
    stages: list[str] = []
    s = run_convert(
        csv_in, tmp_path / "o.parquet", chunk_rows=100, progress=lambda d, t: calls.append((d, t)), stage=stages.append
    ).summary
    assert s["streamed"] and [d for d, _ in calls] == [100, 200, 300] and not stages
    s = run_convert(tmp_path / "o.parquet", tmp_path / "o.bag", stage=stages.append).summary
    assert stages == ["reading", "writing"] and s["rows_in"] == 300
    assert streams(csv_in, "x.parquet") and not streams(csv_in, "x.parquet", backwards="sort")
    assert not streams(csv_in, "x.bag") and not streams(csv_in, "x.csv", stream=False)
    with pytest.raises(ImutoolError, match="overwrite"):
        run_convert(csv_in, csv_in)
    with pytest.raises(TypeError, match="colums"):
        run_convert(csv_in, tmp_path / "z.csv", colums="a=b")


def test_streamed_and_bag_conversions_check_their_input(tmp_path, capsys):
    """A streamed conversion and a bag input get the checks of a whole-file CSV load: absurd samples bridged and
    counted over all chunks, a gyro in deg/s labelled rad/s warned — on stderr, in the summary and in the
    output's metadata; under --strict the warning is an error and nothing is written."""
    from imutool.sim import simulate

    rec = simulate("ship-roll", duration=20, seed=3)
    rec.channels["gyro"] = np.degrees(rec["gyro"])
    rec.channels["gyro"][1500:1502] = 1e6  # two corrupt samples in the second chunk
    src = tmp_path / "degs.csv"
    write_csv(rec, src)
    out = tmp_path / "o.csv"
    code, stdout, err = run(["convert", src, out, "--chunk-rows", "1000", "--json"], capsys)
    assert code == 0, err
    s = json.loads(stdout)
    assert s["streamed"] and s["validation"][0]["absurd_samples_interpolated"] == {"gyro": 2}
    assert "UNITS: gyro" in err and "2 absurd gyro sample(s)" in err
    meta = read_csv(out).meta
    assert any(w.startswith("UNITS: gyro") for w in meta["warnings"])
    assert meta["validation"]["absurd_samples_interpolated"] == {"gyro": 2}
    assert np.all(np.abs(read_csv(out)["gyro"]) < 100)  # bridged, not copied through
    code, _, err = run(["convert", src, tmp_path / "strict.csv", "--chunk-rows", "1000", "--strict"], capsys)
    assert code == 2 and "UNITS" in err and not (tmp_path / "strict.csv").exists()

    pytest.importorskip("rosbags", reason="bags need rosbags")
    bag = tmp_path / "degs.bag"
    code, _, err = run(["convert", out, bag], capsys)
    assert code == 0, err
    code, stdout, err = run(["convert", bag, tmp_path / "back.csv", "--json"], capsys)
    assert code == 0 and "UNITS: gyro" in err
    assert any(w.startswith("UNITS: gyro") for w in json.loads(stdout)["warnings"])
    assert any(w.startswith("UNITS: gyro") for w in read_csv(tmp_path / "back.csv").meta["warnings"])
