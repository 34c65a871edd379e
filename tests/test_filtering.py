"""imutool.filtering.run_filter: the one route behind `imutool filter`, `imutool batch filter` and Python."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import run_main

import formats
from formats.errors import ImutoolError
from imutool.attitude import EkfParams
from imutool.filtering import run_filter, streams
from imutool.loading import load_recording
from imutool.sim import simulate


@pytest.fixture(scope="module")
def roll_csv(tmp_path_factory):
    p = tmp_path_factory.mktemp("filtering") / "roll.csv"
    formats.write(simulate("ship-roll", duration=30, seed=11), p)
    return p


def _same_numeric_columns(a_path, b_path):
    a, b = formats.read(a_path), formats.read(b_path)
    assert list(a.channels) == list(b.channels)
    assert np.array_equal(a.time, b.time)
    for name in a.channels:
        assert np.array_equal(a[name], b[name], equal_nan=True), name
    return a


CASES = {
    "ekf": ([], {}),
    "ekf-smooth": (["--smooth"], {"smooth": True}),
    "ekf-mounted-params": (
        ["--mounting", "x,-y,-z", "--param", "mag_noise_deg=10", "--no-gnss"],
        {"mounting": "x,-y,-z", "params": EkfParams(mag_noise_deg=10.0), "use_gnss": False},
    ),
    "ekf-streamed": (
        ["--stream-mb", "0", "--chunk-rows", "997", "--lever-arm", "0,0,-2", "--mounting", "x,-y,-z"],
        {"stream_mb": 0, "chunk_rows": 997, "lever_arm": (0, 0, -2), "mounting": "x,-y,-z"},
    ),
    "lpf": (["--method", "lpf", "--cutoff", "0.3"], {"method": "lpf", "cutoff_hz": 0.3}),
    "compass": (["--method", "compass"], {"method": "compass"}),
}


@pytest.mark.parametrize("case", list(CASES))
def test_python_call_equals_cli(roll_csv, tmp_path, capsys, case):
    """The library function called from Python writes the same file, bit for bit, as `imutool filter`, and
    returns the summary the CLI prints."""
    from imutool.compass import CompassParams

    args, kw = CASES[case]
    cli_out, lib_out = tmp_path / "cli.csv", tmp_path / "lib.csv"
    code, out, err = run_main(["filter", roll_csv, "-o", cli_out, "--json", *args], capsys)
    assert code == 0, err
    cli_summary = json.loads(out)
    if kw.get("method") == "compass":
        kw = {**kw, "compass": CompassParams()}
    res = run_filter(str(roll_csv), str(lib_out), **kw)
    est = _same_numeric_columns(cli_out, lib_out)
    assert len(est) == 6001 and "heading" in est.channels
    assert (res.recording is None) == (case == "ekf-streamed")
    assert res.summary.pop("output") == str(lib_out) and cli_summary["output"] == str(cli_out)
    # the CLI's --json adds the input's warnings (RouteResult.full_summary) to the estimator's own
    lib_warnings, cli_warnings = res.summary.pop("warnings", []), cli_summary.pop("warnings", [])
    assert set(lib_warnings) <= set(cli_warnings)
    assert json.loads(json.dumps(res.summary, default=str)) == {k: cli_summary[k] for k in res.summary}
    if case == "ekf-smooth":  # the smoother summary: truth in the input → causal vs smoothed RMSE
        gain = res.summary["smoother_gain"]
        assert gain["smoothed_rmse_deg"]["roll"] < gain["causal_rmse_deg"]["roll"] < 1.0


def test_recording_in_memory_equals_path(roll_csv, tmp_path):
    """A Recording loaded by the library's loader takes the same route as its path; no output → returned only."""
    rec, report = load_recording(roll_csv)
    assert report["rows_kept"] == len(rec) == 6001
    a = run_filter(str(roll_csv))
    b = run_filter(rec)
    assert a.recording is not None and b.recording is not None and a.summary["output"] is None
    for name in a.recording.channels:
        assert np.array_equal(a.recording[name], b.recording[name]), name
    # the estimate is right, not just repeatable: roll within 1° RMS of the simulator's truth
    err = a.recording["roll"] - rec["ref_roll"]
    assert np.sqrt(np.mean(err[1000:] ** 2)) < 1.0


def test_progress_and_on_input(roll_csv, tmp_path):
    calls: list[tuple[int, int | None]] = []
    seen: list[str] = []
    run_filter(
        str(roll_csv),
        str(tmp_path / "a.csv"),
        progress=lambda d, t: calls.append((d, t)),
        on_input=lambda p, rep: seen.append(p),
    )
    assert seen == [str(roll_csv)] and calls and calls[-1] == (6001, 6001)
    calls.clear()
    seen.clear()
    reports: list[dict] = []
    res = run_filter(
        str(roll_csv),
        str(tmp_path / "b.parquet"),
        stream_mb=0,
        chunk_rows=2500,
        progress=lambda d, t: calls.append((d, t)),
        on_input=lambda p, rep: (seen.append(p), reports.append(rep)),
    )
    assert res.summary["method"] == "ekf (streamed)" and res.summary["rows"] == 6001
    assert [d for d, _ in calls] == [2500, 5000, 6001]  # streamed: chunk by chunk, no whole-file load
    # the input's report comes once, at the end, over all the chunks
    assert seen == [str(roll_csv)] and reports[0]["rows_read"] == reports[0]["rows_kept"] == 6001
    assert len(formats.read(tmp_path / "b.parquet")) == 6001


def test_streams_decision(roll_csv, tmp_path):
    rec = formats.read(roll_csv)
    assert streams(roll_csv, "o.csv", stream_mb=0)
    assert not streams(roll_csv, "o.csv")  # small file: in memory
    assert not streams(roll_csv, None, stream_mb=0)  # nowhere to stream to
    assert not streams(roll_csv, "o.csv", stream_mb=0, smooth=True)  # the smoother needs the whole file
    assert not streams(roll_csv, "o.csv", stream_mb=0, method="lpf")
    assert not streams(rec, "o.csv", stream_mb=0)
    # Parquet: decided by the data's in-memory size (6001 rows × 29 columns × 8 B = 1.39 MB), not the file's
    pq_path = tmp_path / "roll.parquet"
    formats.write(rec, pq_path)
    assert pq_path.stat().st_size < 1.3e6
    assert streams(pq_path, "o.csv", stream_mb=1.3) and not streams(pq_path, "o.csv", stream_mb=1.4)


def test_errors_and_strict(roll_csv, tmp_path):
    with pytest.raises(ImutoolError, match="method"):
        run_filter(str(roll_csv), method="kalman")
    with pytest.raises(ImutoolError, match="lever arm"):
        run_filter(str(roll_csv), lever_arm=(0, np.nan, 1))
    with pytest.raises(TypeError, match="colums"):
        run_filter(str(roll_csv), colums="x")
    # gyro in deg/s labelled rad/s: a plausibility warning, an error under strict=True (before anything runs)
    rec = formats.read(roll_csv)
    rec.channels["gyro"] = np.degrees(rec["gyro"])
    bad = tmp_path / "bad.csv"
    formats.write(rec, bad)
    res = run_filter(str(bad))
    assert res.validation["warnings"] and res.recording is not None
    assert res.recording.meta.get("warnings")
    with pytest.raises(ImutoolError, match="strict"):
        run_filter(str(bad), str(tmp_path / "never.csv"), strict=True)
    assert not (tmp_path / "never.csv").exists()


_MAKE = textwrap.dedent("""
    import sys
    import numpy as np
    from formats import Recording
    from formats.parquet import ParquetWriter
    n_total, chunk = int(sys.argv[2]), 100_000
    with ParquetWriter(sys.argv[1], row_group_rows=chunk) as w:
        for i in range(0, n_total, chunk):
            n = min(chunk, n_total - i)
            t = (i + np.arange(n)) / 200.0
            rng = np.random.default_rng(i)
            roll = 0.2 * np.sin(2 * np.pi * t / 12.0)  # rad: a 12 s roll of ±11°
            acc = np.column_stack([np.zeros(n), -9.81 * np.sin(roll), -9.81 * np.cos(roll)])  # FRD specific force
            w.write(Recording(t, {"gyro": rng.normal(0, 0.002, (n, 3)) + np.column_stack(
                                      [0.2 * 2 * np.pi / 12.0 * np.cos(2 * np.pi * t / 12.0), 0 * t, 0 * t]),
                                  "accel": acc + rng.normal(0, 0.05, (n, 3)),
                                  "mag": np.tile([20.0, 0.0, 45.0], (n, 1)) + rng.normal(0, 0.3, (n, 3)),
                                  "ref_roll": np.degrees(roll)}))
""")

_FILTER = textwrap.dedent("""
    import sys
    import imutool.attitude, imutool.filtering, formats.parquet  # imports before the baseline
    from imutool.cli import main
    def rss_mib():  # VmHWM: this process's peak RSS
        for line in open("/proc/self/status"):
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    base = rss_mib()
    try:
        main(["filter", sys.argv[1], "-o", sys.argv[2], "--stream-mb", "0", "--chunk-rows", "100000", "-q"])
    except SystemExit as e:
        assert not e.code, e.code
    print(base, rss_mib(), file=sys.stderr)
""")


@pytest.mark.slow
def test_parquet_filter_streams_with_bounded_memory(tmp_path):
    """`imutool filter` on a Parquet input streams row group by row group into a Parquet output: peak memory does
    not grow with the file. 0.4 M vs 2 M rows: a whole-file run would hold ≥ 1.6 M × 27 float64 columns
    (10 in, 17 out) = 330 MiB more for the larger file; streamed, the peaks differ by a small fraction of that."""
    import pyarrow.parquet as pq

    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    grew = {}
    for n in (400_000, 2_000_000):
        src, dst = tmp_path / f"in{n}.parquet", tmp_path / f"est{n}.parquet"
        subprocess.run([sys.executable, "-c", _MAKE, str(src), str(n)], check=True, env=env)
        r = subprocess.run(
            [sys.executable, "-c", _FILTER, str(src), str(dst)], env=env, capture_output=True, text=True, timeout=300
        )
        assert r.returncode == 0, r.stderr[-2000:]
        base, peak = map(float, r.stderr.split()[-2:])
        f = pq.ParquetFile(dst)
        assert f.metadata.num_rows == n and f.metadata.num_row_groups >= n // 262_144
        last = f.read_row_group(f.metadata.num_row_groups - 1, columns=["roll", "ref_roll"])
        err = np.asarray(last["roll"]) - np.asarray(last["ref_roll"])
        assert np.sqrt(np.mean(err**2)) < 1.0  # the estimate is right to the end, not just written
        grew[n] = peak - base
        src.unlink()
        dst.unlink()
    whole_mib = 1_600_000 * 27 * 8 / 2**20
    assert grew[2_000_000] - grew[400_000] < 0.15 * whole_mib, f"peak RSS above imports: {grew} MiB"


def test_streamed_filter_checks_its_input_like_an_in_memory_run(roll_csv, tmp_path, capsys):
    """A file large enough to stream gets the input checks of a small one, and says what they found where an
    in-memory run says it: absurd samples bridged (same values as in memory), a gyro in deg/s labelled rad/s
    warned (UNITS), the self-check's warning — on stderr, in the JSON summary and in the output's metadata, for a
    CSV (written into the header at the end) and a Parquet output (in its footer)."""
    from click.testing import CliRunner

    from imutool.cli import cli

    rec = formats.read(roll_csv)
    absurd = rec.copy()
    absurd.channels["gyro"][3000:3003] = 1e6  # three corrupt samples, away from the chunk boundaries
    src = tmp_path / "absurd.csv"
    formats.write(absurd, src)
    outs = {}
    for name, extra in (("memory", []), ("stream", ["--stream-mb", "0", "--chunk-rows", "2500"])):
        outs[name] = tmp_path / f"{name}.csv"
        run = CliRunner().invoke(cli, ["filter", str(src), "-o", str(outs[name]), "--json", *extra])
        assert run.exit_code == 0, run.output
        s = json.loads(run.stdout)
        assert s["validation"][0]["absurd_samples_interpolated"] == {"gyro": 3}, name
        assert any("3 absurd gyro sample(s)" in w for w in s["warnings"]), name
        assert "3 absurd gyro sample(s)" in run.stderr, name
    a, b = formats.read(outs["memory"]), formats.read(outs["stream"])
    assert any("3 absurd gyro" in w for w in b.meta["warnings"])
    head = outs["stream"].read_text().split("\ntime,")[0].splitlines()  # what a person opening the file sees
    assert all(ln.strip("# ") for ln in head), "a blank line (room kept for metadata) in the streamed header"
    assert sum(ln.startswith("# warnings:") for ln in head) == 1
    assert b.meta["validation"]["absurd_samples_interpolated"] == {"gyro": 3}
    for ch in ("roll", "pitch", "heading", "gyro_bias"):
        assert np.array_equal(a[ch], b[ch]), ch

    degs = rec.copy()
    degs.channels["gyro"] = np.degrees(rec["gyro"])
    src = tmp_path / "degs.csv"
    formats.write(degs, src)
    for out in (tmp_path / "degs_out.csv", tmp_path / "degs_out.parquet"):
        if out.suffix == ".parquet":
            pytest.importorskip("pyarrow", reason="Parquet needs the [parquet] extra (pyarrow)")
        run = CliRunner().invoke(
            cli, ["filter", str(src), "-o", str(out), "--json", "--stream-mb", "0", "--chunk-rows", "2500"]
        )
        assert run.exit_code == 0, run.output
        s = json.loads(run.stdout)
        assert s["method"] == "ekf (streamed)"
        assert "UNITS: gyro rates are" in run.stderr and "self-check failed" in run.stderr
        meta = formats.read(out).meta
        assert any(w.startswith("UNITS: gyro") for w in meta["warnings"]), out.suffix
        assert any("self-check failed" in w for w in meta["warnings"]), out.suffix
        assert meta["validation"]["rows_kept"] == len(rec)
    # --strict: the plausibility warning of the first chunk is an error, and nothing is written
    out = tmp_path / "strict.csv"
    code, _, err = run_main(["filter", src, "-o", out, "--stream-mb", "0", "--strict"], capsys)
    assert code == 2 and "UNITS" in err and len(err.strip().splitlines()) == 1 and not out.exists()
    assert not list(tmp_path.glob(".strict.csv.*"))  # no temporary file left behind


def test_chunk_checks_across_chunk_edges_and_the_end_of_a_stream(roll_csv, tmp_path, capsys):
    """ChunkChecks over chunks: absurd samples at a chunk's edge and in a short last chunk are taken out (not
    mistaken for a unit error: the share is over the rows seen so far), the input's own warnings are kept for the
    output, and a streamed run whose warnings come only at the end (rows dropped) fails under --strict without
    leaving a file. A stream with no data rows is an error, not an empty output."""
    from imutool.loading import ChunkChecks

    rec = formats.read(roll_csv)
    rec.meta["warnings"] = ["an earlier warning"]
    bad = rec.copy()
    for i in (2499, 2500, 5990):  # the last row of chunk 1, the first of chunk 2, inside an 11-row last chunk
        bad.channels["gyro"][i] = 1e6
    checks = ChunkChecks(str(roll_csv))
    parts = [checks.prepare(bad.select(slice(a, b))) for a, b in ((0, 2500), (2500, 5990), (5990, len(bad)))]
    gyro = np.concatenate([p["gyro"] for p in parts])
    assert not np.any(np.abs(np.nan_to_num(gyro)) > 100)  # none left for the EKF
    report, warns = checks.finish(len(bad), len(bad))
    assert (
        sum(report.get("absurd_samples_interpolated", {}).values())
        + sum(report.get("absurd_samples_set_nan", {}).values())
        == 3
    )
    assert not any("unit or scale error" in w for w in warns)
    assert checks.meta_warnings(warns)[0] == "an earlier warning"

    src = tmp_path / "earlier.csv"
    formats.write(rec, src)
    out = tmp_path / "o.csv"
    code, _, err = run_main(["filter", src, "-o", out, "--stream-mb", "0", "--chunk-rows", "2500", "-q"], capsys)
    assert code == 0, err
    assert formats.read(out).meta["warnings"][0] == "an earlier warning"

    lines = roll_csv.read_text().splitlines(keepends=True)
    head = [i for i, line in enumerate(lines) if not line.startswith("#")][0] + 1
    dup = lines[:head] + [row for row in lines[head:] for _ in (0, 1)][: len(lines) - head + 200]  # 200 repeats
    src = tmp_path / "dup.csv"
    src.write_text("".join(dup))
    out = tmp_path / "dup_out.csv"
    code, _, err = run_main(["filter", src, "-o", out, "--stream-mb", "0", "--chunk-rows", "2500", "--strict"], capsys)
    assert code == 2 and "DROPPED" in err and not out.exists(), err
    assert not [f for f in tmp_path.iterdir() if f.name.startswith(".dup_out")]
    code, _, err = run_main(["filter", src, "-o", out, "--stream-mb", "0", "--chunk-rows", "2500", "--json"], capsys)
    assert code == 0 and "DROPPED" in err and "DROPPED" in formats.read(out).meta["warnings"][0]

    empty = tmp_path / "empty.csv"
    empty.write_text("".join(lines[:head]))
    code, _, err = run_main(["filter", empty, "-o", tmp_path / "e.csv", "--stream-mb", "0"], capsys)
    assert code == 2 and "no data rows" in err and not (tmp_path / "e.csv").exists()


def test_memory_and_streamed_runs_compose_the_same_checks_and_metadata(roll_csv, tmp_path):
    """One self-check accumulator (imutool.attitude.SelfCheck) and one metadata composition for both paths (issue
    39): the in-memory and the streamed (--chunk-rows 2000) runs of the same file have the same output metadata keys
    (the lever arm's frame included, which the streamed output once lacked), the same summary keys and the same
    figures and warnings — the inconsistency spans, and the gyro-scale check's pairs across chunk edges, included.
    The gyro's x axis is reversed so that the checks have something to say."""
    rec = formats.read(roll_csv)
    rec.channels["gyro"] = rec["gyro"] * [-1, 1, 1]
    src = tmp_path / "flip.csv"
    formats.write(rec, src)
    got, meta = {}, {}
    for name, extra in (("memory", {}), ("streamed", {"stream_mb": 0, "chunk_rows": 2000})):
        out = tmp_path / f"{name}.csv"
        res = run_filter(src, out, lever_arm=(0, 0, -2), **extra)
        got[name], meta[name] = res.summary, formats.read(out).meta
    assert got["streamed"]["method"] == "ekf (streamed)" and got["memory"]["method"] == "ekf"
    assert set(meta["memory"]) == set(meta["streamed"])
    for m in meta.values():
        assert m["lever_arm_frame"].startswith("body FRD") and m["lever_arm_m"] == [0.0, 0.0, -2.0]
        assert m["heading_source"] == "magnetometer"
    assert meta["memory"]["warnings"] == meta["streamed"]["warnings"]
    assert any("gyro axis check" in w for w in meta["memory"]["warnings"])
    # what only a stream has (its dropped rows, the lever arm it was given), and what differs by route
    stream_only = {"dropped_non_increasing_rows", "lever_arm_m"}
    assert set(got["streamed"]) - set(got["memory"]) == stream_only
    assert set(got["memory"]) <= set(got["streamed"])
    by_route = {"method", "output", "validation", "motion"}  # a stream judges its motion on its first chunk
    assert got["memory"]["motion"]["kind"] == got["streamed"]["motion"]["kind"]
    for key in set(got["memory"]) - by_route:
        assert got["memory"][key] == got["streamed"][key], key
    assert got["memory"]["gyro_scale_check"]["pairs"] >= 13  # 30 s in 2-s windows: none lost at the 2 chunk edges
    assert got["memory"]["warnings"] == got["streamed"]["warnings"]


def test_self_check_spans_across_chunks_equal_one_run():
    """SelfCheck's runs of flagged samples fed in chunks (a run open at a chunk's end goes on) are the spans of the
    whole run at once, and only the first ones are kept while all are counted."""
    from imutool.attitude.selfcheck import RunSpans, self_check

    t = np.arange(0.0, 50.0, 0.5)
    bad = ((t >= 3) & (t < 7)) | ((t >= 9.5) & (t < 10)) | (t == 20) | ((t >= 30) & (t < 41)) | (t >= 49)
    whole, _ = self_check(t, bad.astype(np.uint8) * 32)
    for edges in ([0, 100], [0, 7, 8, 19, 60, 61, 62, 100], list(range(0, 101, 3)) + [100]):
        spans = RunSpans(keep=20)
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            spans.add(t[a:b], bad[a:b])
        assert [[round(a, 3), round(b, 3)] for a, b in spans.spans] == whole["inconsistent_spans_s"], edges
        assert spans.count == 5 and spans.n_flagged == whole["inconsistent_samples"]
    few = RunSpans(keep=2)
    for a in range(0, 100, 7):
        few.add(t[a : a + 7], bad[a : a + 7])
    assert few.count == 5 and len(few.spans) == 2 and few.spans == [[3.0, 6.5], [9.5, 9.5]]


def test_filtering_has_no_function_level_imports_but_the_slow_one():
    """imutool.filtering imports at its top; only calibration (scipy.optimize, ~1 s) waits for a deviation card."""
    import ast

    import imutool.filtering as mod

    tree = ast.parse(Path(mod.__file__).read_text(encoding="utf-8"))
    inner = [
        node.module if isinstance(node, ast.ImportFrom) else node.names[0].name
        for fn in ast.walk(tree)
        if isinstance(fn, ast.FunctionDef)
        for node in ast.walk(fn)
        if isinstance(node, (ast.Import, ast.ImportFrom))
    ]
    assert inner == ["calibration"]


def test_scale_check_carry_starts_at_the_kernels_last_complete_window():
    """SelfCheck carries the gyro-scale check's last complete window (and the open one) into the next chunk: where
    that window starts is where the check's kernel cuts it (windows from the first sample, each starting at the
    first sample `window` s or more after the last start), whatever the sample spacing, so no pair is lost or
    counted twice at a chunk edge. The kernel returns that index (it cuts the windows anyway)."""
    from imutool.gyro_check import CANDIDATES, pair_discrepancy_kernel

    def kernel_cut(t, window):
        starts = [0]
        for k in range(1, len(t)):
            if t[k] - t[starts[-1]] >= window:
                starts.append(k)
        return starts[-2] if len(starts) >= 2 else 0

    def last_start(t, window, budget=0):
        z = np.zeros((len(t), 3))
        sums, counts = np.zeros(len(CANDIDATES)), np.zeros(len(CANDIDATES))
        return pair_discrepancy_kernel(t, z, z, z + 1.0, window, 1.0, CANDIDATES, 9.8, budget, sums, counts)[1]

    rng = np.random.default_rng(3)
    for _ in range(200):
        t = 1e5 + np.cumsum(rng.uniform(0.001, 0.5, rng.integers(1, 300)))
        for window in (0.0, 0.01, 2.0, 7.3):
            assert last_start(t, window) == kernel_cut(t, window)
        assert last_start(t, 2.0, budget=10**6) == kernel_cut(t, 2.0)
    assert last_start(np.arange(0.0, 10.0, 0.5), 2.0) == 12  # starts 0, 4, 8, 12, 16: the last complete is 12


def test_a_stream_writes_its_last_chunk_behind_the_final_header(roll_csv, tmp_path, monkeypatch, copy_sizes):
    """A streamed run knows its final metadata (validation, self-check, warnings) after its last chunk's EKF and
    hands them to the writer before writing that chunk: only the rows before it are copied behind the final header
    (the whole file was, at close), and the file is byte for byte the one written the old way."""
    import formats.csv as fcsv

    copied = copy_sizes
    out = tmp_path / "streamed.csv"
    run_filter(roll_csv, out, stream_mb=0, chunk_rows=2500)  # 6001 rows: 2500, 2500, 1001
    text = out.read_bytes()
    rows = text.split(b"\ntime,", 1)[1].split(b"\n", 1)[1].splitlines(keepends=True)
    assert len(rows) == 6001
    assert copied == [len(b"".join(rows[:5000]))]  # the first two chunks, once; the last one written in place
    # the same file when the metadata are given at the end (the writer then copies every row)
    # the last chunk formatted on two threads in blocks of 300 rows while the rows before it are copied: the same
    monkeypatch.setattr(fcsv, "_WRITE_BLOCK_ROWS", 300)
    monkeypatch.setattr(fcsv, "_threads", lambda: 2)
    overlapped = tmp_path / "overlapped.csv"
    run_filter(roll_csv, overlapped, stream_mb=0, chunk_rows=2500)
    assert overlapped.read_bytes() == text and copied[-1] == copied[0]
    monkeypatch.setattr(fcsv.CsvWriter, "set_final_meta", _set_at_close)
    late = tmp_path / "late.csv"
    run_filter(roll_csv, late, stream_mb=0, chunk_rows=2500)
    assert late.read_bytes() == text


def _set_at_close(self, meta):
    """CsvWriter.set_final_meta that keeps the metadata back until close (as before the stream looked ahead)."""
    self._late = {**getattr(self, "_late", {}), **meta}
    if not getattr(self, "_wrapped", False):
        self._wrapped = True
        finish = self._finish

        def at_close():
            self.final_meta = {**self.final_meta, **self._late}
            finish()

        self._finish = at_close
