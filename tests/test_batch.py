"""imutool batch: mixed good/broken inputs, resume after SIGKILL, Dask LocalCluster equivalence, templates."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli_on_pty

import formats
from formats import Recording
from imutool import batch
from imutool.cli import main

pytest.importorskip("pyarrow", reason="the batch tests write Parquet (the [parquet] extra)")


def _write_good(path: Path, n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    rec = Recording(
        t,
        {"gyro": rng.normal(0, 0.01, (n, 3)), "accel": rng.normal(0, 0.1, (n, 3)) + [0, 0, -9.81]},
        meta={"ship": f"ship{seed % 2}", "seed": seed},
    )
    formats.write(rec, path)


def _mixed_dir(root: Path) -> dict[str, str]:
    """Three good recordings (one in a sub-folder) and three broken ones; returns {name: expected error part}."""
    (root / "sub").mkdir(parents=True)
    _write_good(root / "a.csv", 500, 1)
    _write_good(root / "b.csv", 700, 2)
    _write_good(root / "sub" / "c.csv", 300, 3)
    (root / "garbage.csv").write_bytes(b"\x00\x01\x02 not a csv \xff\n")
    (root / "backwards.csv").write_text("# imutool-csv: 1\ntime,roll\n0,1\n1,2\n0.5,3\n")
    (root / "empty.csv").write_text("")
    (root / "notes.txt").write_text("not picked: not a data extension\n")
    return {"garbage.csv": "not text", "backwards.csv": "time goes backwards", "empty.csv": "no header row"}


def _run(args: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as e:
        main(args)
    out = capsys.readouterr()
    return e.value.code, out.out, out.err


def test_mixed_good_and_broken(tmp_path, capsys):
    broken = _mixed_dir(tmp_path / "in")
    out = tmp_path / "out"
    code, stdout, err = _run(
        [
            "batch",
            "convert",
            str(tmp_path / "in"),
            "-o",
            str(out / "{rel}" / "{stem}.parquet"),
            "-j",
            "2",
            "--summary",
            str(out / "batch.csv"),
        ],
        capsys,
    )
    assert code == 1, err  # some failed
    for name, n in (("a", 500), ("b", 700), ("sub/c", 300)):
        rec = formats.read(out / f"{name}.parquet")
        assert len(rec) == n and rec["gyro"].shape == (n, 3)
        src = formats.read(tmp_path / "in" / f"{name}.csv")
        assert rec["gyro"].tobytes() == src["gyro"].tobytes()
        assert batch.marker_path(str(out / f"{name}.parquet")).exists()
    for name, why in broken.items():
        stem = name[:-4]
        assert not (out / f"{stem}.parquet").exists()
        assert f"FAILED {tmp_path / 'in' / name}" in stdout and why in stdout
    assert "6 jobs: 3 ok, 3 failed" in stdout
    with open(out / "batch.csv", newline="") as f:
        rows = {Path(r["input"]).name: r for r in csv.DictReader(f)}
    assert set(rows) == {"a.csv", "b.csv", "c.csv", "garbage.csv", "backwards.csv", "empty.csv"}
    assert rows["b.csv"]["status"] == "ok" and rows["b.csv"]["rows"] == "700"
    assert rows["backwards.csv"]["status"] == "failed" and "time goes backwards" in rows["backwards.csv"]["error"]
    # no temporary files left anywhere
    assert not [p for p in out.rglob("*.tmp")]
    # --json: machine-readable totals and per-file results
    code, stdout, _ = _run(
        [
            "batch",
            "convert",
            str(tmp_path / "in"),
            "-o",
            str(out / "{rel}" / "{stem}.parquet"),
            "-j",
            "1",
            "--resume",
            "--json",
        ],
        capsys,
    )
    d = json.loads(stdout)
    assert code == 1 and d["totals"]["skipped"] == 3 and d["totals"]["failed"] == 3 and d["totals"]["ok"] == 0


def test_all_ok_exit_0_and_manifest_fields(tmp_path, capsys):
    for i in range(3):
        _write_good(tmp_path / f"r{i}.csv", 200 + i, i)
    man = tmp_path / "fleet.csv"
    man.write_text("input,ship,voyage\nr0.csv,Aurora,V1\nr1.csv,Aurora,V2\nr2.csv,Borealis,V1\n")
    code, stdout, err = _run(
        [
            "batch",
            "convert",
            "--manifest",
            str(man),
            "-o",
            str(tmp_path / "out" / "{ship}" / "{voyage}_{stem}.csv"),
            "-j",
            "1",
            "--summary",
            str(tmp_path / "s.parquet"),
            "--figure",
            "rows_in",
        ],
        capsys,
    )
    assert code == 0, err
    assert (tmp_path / "out" / "Borealis" / "V1_r2.csv").exists()
    import pyarrow.parquet as pq

    t = pq.read_table(tmp_path / "s.parquet").to_pydict()
    assert t["ship"] == ["Aurora", "Aurora", "Borealis"] and t["rows_in"] == [200.0, 201.0, 202.0]
    assert t["status"] == ["ok"] * 3


def test_template_errors(tmp_path, capsys):
    _write_good(tmp_path / "a.csv", 50, 0)
    _write_good(tmp_path / "b.csv", 50, 1)
    code, _, err = _run(
        ["batch", "convert", str(tmp_path / "a.csv"), str(tmp_path / "b.csv"), "-o", str(tmp_path / "same.csv")], capsys
    )
    assert code == 2 and "both map to output" in err
    code, _, err = _run(["batch", "convert", str(tmp_path / "a.csv"), "-o", str(tmp_path / "{nope}.csv")], capsys)
    assert code == 2 and "unknown field {nope}" in err
    code, _, err = _run(["batch", "convert", str(tmp_path / "a.csv"), "-o", str(tmp_path / "{stem}.csv")], capsys)
    assert code == 2 and "overwrite an input" in err
    code, _, err = _run(["batch", "nosuchcommand", str(tmp_path / "a.csv")], capsys)
    assert code == 2 and "unknown command" in err


def _stamp(p: Path) -> tuple[int, int]:
    st = p.stat()
    return st.st_ino, st.st_mtime_ns


@pytest.mark.slow
def test_resume_after_sigkill(tmp_path):
    n_files = 8
    src = tmp_path / "in"
    src.mkdir()
    for i in range(n_files):
        _write_good(src / f"v{i}.csv", 60_000, i)
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-c",
        "from imutool.cli import main; main()",
        "batch",
        "convert",
        str(src),
        "-o",
        str(out / "{stem}.parquet"),
        "-j",
        "1",
        "--args",
        "--chunk-rows 1500",
        "-q",
    ]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([os.getcwd(), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen(cmd, start_new_session=True, env=env)
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline:
            done = list(out.glob(f".*{batch.MARKER_SUFFIX}")) if out.exists() else []
            if len(done) >= 2 or proc.poll() is not None:
                break
            time.sleep(0.01)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)  # the batch and its worker, mid-batch
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the batch finished before it could be killed (make jobs longer)"
    done = sorted(p.name[1 : -len(batch.MARKER_SUFFIX)] for p in out.glob(f".*{batch.MARKER_SUFFIX}"))
    assert 2 <= len(done) < n_files
    before = {name: _stamp(out / name) for name in done}
    # a stale output of an unfinished job (e.g. an earlier run's, no marker) must be redone, not trusted
    pending = [f"v{i}.parquet" for i in range(n_files) if f"v{i}.parquet" not in done]
    (out / pending[-1]).write_bytes(b"PAR1 half written")
    r = subprocess.run(cmd[:-1] + ["--resume", "--json"], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["totals"]["skipped"] == len(done) and d["totals"]["ok"] == n_files - len(done)
    for name, st in before.items():
        assert _stamp(out / name) == st, f"{name} was redone"
    for i in range(n_files):
        rec = formats.read(out / f"v{i}.parquet")
        assert len(rec) == 60_000
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.slow
def test_dask_local_cluster_gives_identical_outputs(tmp_path, capsys):
    pytest.importorskip("dask.distributed", reason="dask[distributed] not installed (the [dask] extra)")
    _mixed_dir(tmp_path / "in")
    base = ["batch", "convert", str(tmp_path / "in"), "--args", "--chunk-rows 200"]
    code_p, out_p, _ = _run(
        base + ["-o", str(tmp_path / "pool" / "{rel}" / "{stem}.parquet"), "-j", "2", "--json"], capsys
    )
    code_d, out_d, err = _run(
        base + ["-o", str(tmp_path / "dask" / "{rel}" / "{stem}.parquet"), "--dask", "-j", "2", "--json"], capsys
    )
    assert code_p == code_d == 1, err
    rp, rd = json.loads(out_p)["results"], json.loads(out_d)["results"]
    assert [(r["input"], r["status"], r["error"], r["rows"]) for r in rp] == [
        (r["input"], r["status"], r["error"], r["rows"]) for r in rd
    ]
    files_p = sorted(p.relative_to(tmp_path / "pool") for p in (tmp_path / "pool").rglob("*.parquet"))
    files_d = sorted(p.relative_to(tmp_path / "dask") for p in (tmp_path / "dask").rglob("*.parquet"))
    assert files_p == files_d and len(files_p) == 3
    for rel in files_p:
        assert (tmp_path / "pool" / rel).read_bytes() == (tmp_path / "dask" / rel).read_bytes()


def _double_rows(job: batch.Job) -> dict:
    rec = formats.read(job.input)
    if len(rec) < 100:
        raise ValueError("too short")
    formats.write(rec.select(slice(0, len(rec) // 2)), job.output)
    return {"rows": len(rec) // 2, "ship": rec.meta["ship"]}


def test_library_route_with_a_python_runner(tmp_path):
    _write_good(tmp_path / "a.csv", 400, 1)
    _write_good(tmp_path / "b.csv", 50, 2)
    jobs = batch.make_jobs([str(tmp_path / "*.csv")], str(tmp_path / "o" / "{stem}_half.csv"))
    seen = []
    res = batch.run_batch(jobs, _double_rows, workers=1, on_result=seen.append)
    assert [r.status for r in res] == ["ok", "failed"] and len(seen) == 2
    assert res[0].rows == 200 and res[1].error == "ValueError: too short"
    assert len(formats.read(tmp_path / "o" / "a_half.csv")) == 200
    again = batch.run_batch(jobs, _double_rows, workers=1, resume=True)
    assert [r.status for r in again] == ["skipped", "failed"]


def test_library_call_runner_equals_the_command(tmp_path, capsys):
    """batch.Call(run_filter) — the library route, no click — writes what `imutool batch filter` writes, bit for
    bit, and reports the same rows; in worker processes too."""
    from imutool.filtering import run_filter
    from imutool.sim import simulate

    for i in range(3):
        formats.write(simulate("ship-roll", duration=10, seed=i), tmp_path / "in" / f"v{i}.csv")
    code, out, err = _run(
        ["batch", "filter", str(tmp_path / "in"), "-o", str(tmp_path / "cli" / "{stem}.csv"), "-j", "1", "--quiet"],
        capsys,
    )
    assert code == 0, err
    jobs = batch.make_jobs([str(tmp_path / "in")], str(tmp_path / "lib" / "{stem}.csv"))
    res = batch.run_batch(jobs, batch.Call(run_filter), workers=2)
    assert [r.status for r in res] == ["ok"] * 3 and [r.rows for r in res] == [2001] * 3
    for i in range(3):
        a = (tmp_path / "cli" / f"v{i}.csv").read_text().splitlines()
        b = (tmp_path / "lib" / f"v{i}.csv").read_text().splitlines()
        assert a == b and len(a) > 2001


def _on_pty(args: list[str], cwd: Path) -> tuple[int, str]:
    """`imutool ARGS` with stderr on a pseudo-terminal; (exit status, what the terminal showed)."""
    env = {**os.environ, "COLUMNS": "100", "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    rc, _, term = run_cli_on_pty(args, cwd, env)
    return rc, term


@pytest.mark.slow
def test_progress_is_the_shared_bar_and_respects_quiet(tmp_path):
    """The batch bar is imutool.progress.bar (label, done/total files, ETA) on a terminal; --quiet: nothing."""
    for i in range(3):
        _write_good(tmp_path / "in" / f"v{i}.csv", 200, i)
    rc, term = _on_pty(["batch", "convert", "in", "-o", "a/{stem}.parquet", "-j", "1"], tmp_path)
    assert rc == 0, term
    assert "batch:" in term and "/3 [" in term and "file/s" in term, term  # done/total, elapsed<ETA, rate
    rc, term = _on_pty(["batch", "convert", "in", "-o", "b/{stem}.parquet", "-j", "1", "--quiet"], tmp_path)
    assert rc == 0 and "batch:" not in term and "file" not in term, term


def _threads_seen(job: batch.Job) -> dict:
    """A job that reports the thread budget it ran under (in its worker process)."""
    from formats.csv import _threads
    from formats.jit.threads import thread_budget

    return {
        "rows": 1,
        "budget": thread_budget(),
        "csv_threads": _threads(),
        "omp": int(os.environ.get("OMP_NUM_THREADS", "0")),
    }


def test_a_worker_whose_numba_pool_runs_can_still_compile():
    """A forked batch worker inherits numba with its thread pool launched; the thread limit must not change
    NUMBA_NUM_THREADS under it, or the worker's first compile (a cold kernel cache) fails with numba's "Cannot set
    NUMBA_NUM_THREADS to a different value once the threads have been launched" and every job fails."""
    code = (
        "import os, sys\n"
        "os.environ.pop('NUMBA_NUM_THREADS', None)\n"
        "import numba\n"
        "numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)  # launches the pool, as a parent's kernels do\n"
        "from formats.jit.threads import limit_threads\n"
        "limit_threads(1)\n"
        "f = numba.njit(lambda x: x + 1)  # a kernel not in any cache: compiled now\n"
        "assert f(1) == 2 and numba.get_num_threads() == 1, numba.get_num_threads()\n"
        "print('ok')\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_NUM_THREADS"}
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[1])
    if (os.cpu_count() or 1) < 2:
        pytest.skip("one core: numba's pool has one thread, no change to refuse")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-800:]


@pytest.mark.parametrize("scheduler", [None, pytest.param("local", marks=pytest.mark.slow)])
def test_workers_share_the_cores_and_no_job_takes_more(tmp_path, scheduler):
    """N workers on C cores: each job's thread pools (CSV parser/writer, pyarrow, numba, BLAS) get C ÷ N threads,
    so N workers never oversubscribe; one worker (no pool) leaves a job the whole machine."""
    from formats.jit.threads import usable_cores

    if scheduler:
        pytest.importorskip("dask.distributed", reason="dask[distributed] not installed (the [dask] extra)")
    cores = usable_cores()
    jobs = [batch.Job(str(tmp_path / f"in{k}.csv")) for k in range(4)]
    share = max(1, cores // 2)
    res = batch.run_batch(jobs, _threads_seen, workers=2, scheduler=scheduler, figures=("budget", "csv_threads", "omp"))
    assert [r.status for r in res] == ["ok"] * 4, [r.error for r in res]
    for r in res:
        assert r.figures == {"budget": share, "csv_threads": min(4, share), "omp": share}, r.figures
    if scheduler is None:
        (one,) = batch.run_batch(jobs[:1], _threads_seen, workers=1, figures=("budget",))
        assert one.figures["budget"] == cores  # in this process: not capped
