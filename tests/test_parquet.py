"""Parquet in and out: bit-exact round trip with metadata, CSV/bag/Parquet conversion, bounded-memory streaming."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import formats
from formats import Recording
from formats.errors import ImutoolError

pa = pytest.importorskip("pyarrow", reason="pyarrow not installed (the [parquet] extra)")
pq = pytest.importorskip("pyarrow.parquet")

from formats.parquet import ParquetWriter, iter_parquet, read_parquet, write_parquet  # noqa: E402
from imutool.cli import main  # noqa: E402


def _rec(n: int = 2000, seed: int = 0) -> Recording:
    rng = np.random.default_rng(seed)
    t = 1.7e9 + np.arange(n) / 200.0 + rng.uniform(0, 1e-6, n)  # Unix time with sub-µs jitter: all 17 digits
    rec = Recording(
        t,
        meta={
            "sensor": "test IMU",
            "rate_hz": 200.0,
            "mounting": {"remap": "x,-y,-z", "misalignment_deg": [0.5, 0, 1]},
            "note": "a: b, c",
            "count": 3,
        },
    )
    rec.add("gyro", rng.normal(0, 0.1, (n, 3)))
    rec.add("accel", rng.normal(0, 1, (n, 3)) + [0, 0, -9.81])
    rec.add("mag", rng.normal(20, 5, (n, 3)))
    rec.add("roll", rng.normal(0, 10, n))
    rec.add("q", np.tile([1.0, 0, 0, 0], (n, 1)) + rng.normal(0, 1e-3, (n, 4)))
    rec.add("pos", rng.normal(0, 100, (n, 3)))
    rec.add("movement", (np.arange(n) // 100 % 3).astype(float), "1")
    rec.add("speed", rng.uniform(0, 10, n), "kn")
    rec.channels["gyro"][7, 1] = np.nan
    rec.channels["speed"][3] = np.nan
    rec.channels["roll"][11] = -0.0
    rec.channels["accel"][5, 0] = 5e-324  # subnormal
    return rec


def _same(a: Recording, b: Recording) -> None:
    assert a.column_names() == b.column_names()
    assert a.time.tobytes() == b.time.tobytes()
    for k in a.channels:
        assert a[k].tobytes() == b[k].tobytes(), k  # bit-exact, NaN and −0.0 included
    assert a.units == b.units
    assert a.columns == b.columns


def test_round_trip_bit_exact_with_metadata(tmp_path):
    rec = _rec()
    p = tmp_path / "r.parquet"
    formats.write(rec, p)
    back = formats.read(p)
    _same(rec, back)
    meta = {k: v for k, v in back.meta.items() if k != "source"}
    assert meta == rec.meta  # types kept: floats, ints, dicts
    assert back.meta["source"] == str(p)
    # metadata readable by other tools: key-value JSON and a unit on each field
    schema = pq.read_schema(p)
    blob = json.loads(schema.metadata[b"imutool"])
    assert blob["format"] == "imutool-parquet" and blob["meta"]["sensor"] == "test IMU"
    assert schema.field("gyro_x").metadata[b"unit"] == b"rad/s"
    assert schema.field("speed").metadata[b"unit"] == b"kn"
    assert schema.names == rec.column_names()  # the CSV's columns, same order


def test_same_columns_and_units_as_csv(tmp_path):
    rec = _rec(500)
    formats.write(rec, tmp_path / "r.csv")
    formats.write(rec, tmp_path / "r.parquet")
    c, p = formats.read(tmp_path / "r.csv"), formats.read(tmp_path / "r.parquet")
    _same(c, p)


def test_canonical_channel_in_other_unit_written_in_canonical_unit(tmp_path):
    rec = Recording(np.arange(10.0), {"gyro": np.ones((10, 3))}, {"gyro": "deg/s"})
    formats.write(rec, tmp_path / "g.parquet")
    back = formats.read(tmp_path / "g.parquet")
    assert back.units["gyro"] == "rad/s"
    assert np.allclose(back["gyro"], np.radians(1.0), rtol=0, atol=1e-15)


def test_streamed_chunks_equal_whole_file(tmp_path):
    rec = _rec(5000)
    p = tmp_path / "r.parquet"
    write_parquet(rec, p, row_group_rows=1234)
    assert pq.ParquetFile(p).metadata.num_row_groups == 5
    chunks = list(iter_parquet(p, chunk_rows=700))
    assert [len(c) for c in chunks] == [700] * 7 + [100]
    assert all(c.meta["sensor"] == "test IMU" for c in chunks)
    whole = Recording(
        np.concatenate([c.time for c in chunks]),
        {k: np.concatenate([c[k] for c in chunks]) for k in rec.channels},
        dict(chunks[0].units),
        columns={k: list(v) for k, v in chunks[0].columns.items()},
    )
    _same(rec, whole)
    # the streamed API the filter uses: formats.iter_chunks dispatches CSV and Parquet alike
    assert [len(c) for c in formats.iter_chunks(p, chunk_rows=2500)] == [2500, 2500]


def test_writer_appends_row_groups_and_is_atomic(tmp_path):
    rec = _rec(3000)
    p = tmp_path / "w.parquet"
    with ParquetWriter(p) as w:
        for i in range(0, 3000, 1000):
            w.write(rec.select(slice(i, i + 1000)))
        assert not p.exists()  # nothing under the final name until close
    assert pq.ParquetFile(p).metadata.num_row_groups == 3
    _same(rec, read_parquet(p))
    # a failure mid-way leaves no output and no temporary file
    q = tmp_path / "bad.parquet"
    with pytest.raises(ImutoolError, match="differ"):
        with ParquetWriter(q) as w:
            w.write(rec.select(slice(0, 10)))
            w.write(Recording(np.arange(3.0) + 100, {"roll": np.zeros(3)}))
    assert not q.exists()
    assert [f for f in os.listdir(tmp_path) if f.endswith(".tmp")] == []


def test_background_writer_same_file_and_errors_surface(tmp_path):
    """background=True (a worker thread converts and writes each chunk): the same bytes as the plain writer; a
    failure inside the worker is raised to the caller, and nothing is left behind."""
    rec = _rec(3000)
    files = {}
    for bg in (False, True):
        files[bg] = tmp_path / f"bg{bg}.parquet"
        with ParquetWriter(files[bg], background=bg) as w:
            for i in range(0, 3000, 700):
                w.write(rec.select(slice(i, i + 700)))
    assert files[True].read_bytes() == files[False].read_bytes()
    _same(rec, read_parquet(files[True]))
    q = tmp_path / "fails.parquet"
    with pytest.raises(RuntimeError, match="worker failed"):
        with ParquetWriter(q, background=True) as w:
            w.write(rec.select(slice(0, 10)))

            def boom(_rec):
                raise RuntimeError("worker failed")

            w._write_chunk = boom  # the next chunk fails in the worker thread
            w.write(rec.select(slice(10, 20)))
            w.write(rec.select(slice(20, 30)))  # the error of the chunk in flight is raised here (or at close)
    assert not q.exists() and [f for f in os.listdir(tmp_path) if f.endswith(".tmp")] == []


def test_foreign_parquet_and_errors(tmp_path):
    n = 50
    t = pa.array(np.datetime64("2024-03-01T12:00:00", "ns") + np.arange(n) * np.timedelta64(10, "ms"))
    table = pa.table(
        {
            "time": t,
            "accel_x": np.zeros(n),
            "accel_y": np.zeros(n),
            "accel_z": np.full(n, -9.81),
            "ship": pa.array(["Aurora"] * n),
            "flag": pa.array([True, False] * 25),
        }
    )
    pq.write_table(table, tmp_path / "foreign.parquet")
    rec = formats.read(tmp_path / "foreign.parquet")
    assert rec.time[0] == pytest.approx(1709294400.0) and rec.time[1] - rec.time[0] == pytest.approx(0.01)
    assert rec["accel"].shape == (n, 3) and rec.units["accel"] == "m/s^2"
    assert rec["flag"][:2].tolist() == [1.0, 0.0]
    assert rec.meta["skipped_columns"] == ["ship"]
    pq.write_table(pa.table({"t": np.arange(3.0)}), tmp_path / "notime.parquet")
    with pytest.raises(ImutoolError, match="no numeric 'time' column"):
        formats.read(tmp_path / "notime.parquet")
    (tmp_path / "junk.parquet").write_bytes(b"not parquet at all")
    with pytest.raises(ImutoolError, match="not a readable Parquet file"):
        formats.read(tmp_path / "junk.parquet")


def _run(args: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as e:
        main(args)
    out = capsys.readouterr()
    return e.value.code, out.out, out.err


def test_convert_csv_parquet_bag(tmp_path, capsys):
    from imutool.sim import simulate

    rec = simulate("ship-roll", duration=5.0, rate_hz=100.0)
    csv1 = tmp_path / "a.csv"
    formats.write(rec, csv1)
    pq1, csv2 = tmp_path / "a.parquet", tmp_path / "b.csv"
    code, out, err = _run(["convert", str(csv1), str(pq1), "--json", "--chunk-rows", "128"], capsys)
    assert code == 0, err
    s = json.loads(out)
    assert s["streamed"] and s["rows_in"] == s["rows_out"] == len(rec) and s["to"] == "parquet"
    assert pq.ParquetFile(pq1).metadata.num_row_groups == -(-len(rec) // 128)
    code, out, err = _run(["convert", str(pq1), str(csv2), "-q"], capsys)
    assert code == 0, err
    _same(formats.read(csv1), formats.read(csv2))  # CSV → Parquet → CSV: data bit-exact
    assert formats.read(csv2).meta["roll_amplitude_deg"] == "15.0"  # metadata carried through
    # bags: CSV → ROS1 bag → Parquet holds what the bag holds
    bag = tmp_path / "a.bag"
    assert _run(["convert", str(csv1), str(bag), "-q"], capsys)[0] == 0
    code, _, err = _run(["convert", str(bag), str(tmp_path / "c.parquet"), "-q"], capsys)
    assert code == 0, err
    from_bag, via = formats.read(bag), formats.read(tmp_path / "c.parquet")
    for k in ("gyro", "accel", "mag"):
        assert via[k].tobytes() == from_bag[k].tobytes()
    assert via.time.tobytes() == from_bag.time.tobytes()
    # an output never overwrites its input
    code, _, err = _run(["convert", str(pq1), str(pq1)], capsys)
    assert code == 2 and ("overwrite the input" in err or "is the input" in err)


_STREAM_SCRIPT = textwrap.dedent("""
    import sys
    import imutool.convert, formats.parquet, formats.csv  # imports before the baseline
    def rss_mb():  # VmHWM: this process's peak RSS (ru_maxrss would include the parent's peak before exec)
        for line in open("/proc/self/status"):
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    base = rss_mb()
    s = imutool.convert.stream_convert(sys.argv[1], sys.argv[2], chunk_rows=50_000)
    print(s["rows_out"], base, rss_mb())
""")

_MAKE_SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    from formats import Recording
    from formats.parquet import ParquetWriter
    n_total, chunk = int(sys.argv[2]), 100_000
    with ParquetWriter(sys.argv[1]) as w:
        for i in range(0, n_total, chunk):
            n = min(chunk, n_total - i)
            t = (i + np.arange(n)) / 200.0
            rng = np.random.default_rng(i)
            w.write(Recording(t, {"gyro": rng.normal(size=(n, 3)), "accel": rng.normal(size=(n, 3)),
                                  "mag": rng.normal(size=(n, 3)), "ref_roll": np.sin(t), "ref_pitch": np.cos(t),
                                  "ref_heading": t % 360, "ref_q": rng.normal(size=(n, 4))}))
""")


@pytest.mark.slow
def test_large_parquet_streams_with_bounded_memory(tmp_path):
    """Peak memory of a streamed Parquet → Parquet conversion does not grow with the file: 0.5 M vs 2 M rows
    (17 columns: 65 vs 260 MiB as float64). A whole-file read would need ≥ 195 MiB more for the larger file."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([os.getcwd(), os.environ.get("PYTHONPATH", "")])}
    grew = {}
    for n in (500_000, 2_000_000):
        src, dst = tmp_path / f"big{n}.parquet", tmp_path / f"out{n}.parquet"
        subprocess.run([sys.executable, "-c", _MAKE_SCRIPT, str(src), str(n)], check=True, env=env)
        r = subprocess.run(
            [sys.executable, "-c", _STREAM_SCRIPT, str(src), str(dst)],
            check=True,
            env=env,
            capture_output=True,
            text=True,
        )
        rows, base, peak = r.stdout.split()
        assert int(rows) == n and pq.ParquetFile(dst).metadata.num_rows == n
        grew[n] = float(peak) - float(base)
        src.unlink()
        dst.unlink()
    data_mib = 1_500_000 * 17 * 8 / 2**20
    assert grew[2_000_000] - grew[500_000] < 0.25 * data_mib, f"peak RSS above imports: {grew} MiB"


def test_final_meta_goes_into_the_footer(tmp_path):
    """The schema's metadata are fixed at the first chunk; metadata known only at the end (a streamed run's
    warnings) go into the footer (``imutool_final``) and the reader merges them over the first chunk's."""
    rec = _rec(3000)
    p = tmp_path / "s.parquet"
    with ParquetWriter(p) as w:
        w.write(rec.select(slice(0, 1000)))
        w.write(rec.select(slice(1000, 3000)))
        w.set_final_meta({"warnings": ["UNITS: something"], "note": "replaced", "rows_seen": np.int64(3000)})
    back = read_parquet(p)
    assert back.meta["warnings"] == ["UNITS: something"] and back.meta["note"] == "replaced"
    assert back.meta["rows_seen"] == 3000 and back.meta["sensor"] == "test IMU"
    assert np.array_equal(back.time, rec.time)
    assert next(iter_parquet(p, chunk_rows=500)).meta["note"] == "replaced"
    # another tool's file with a stray key of that name is not ours: its metadata are not taken
    pq.write_table(
        pa.table({"time": [0.0, 1.0]}).replace_schema_metadata({"imutool_final": '{"x": 1}'}),
        tmp_path / "other.parquet",
    )
    assert "x" not in read_parquet(tmp_path / "other.parquet").meta
