"""Batch scaling: `imutool batch` over N simulated voyages with 1, 2, ... local workers and a Dask LocalCluster.

Usage::

    python benchmarks/batch.py                          # 8 voyages of 600 s at 50 Hz, `filter`; 1 and 2 workers
                                                        # and a 2-worker Dask LocalCluster
    python benchmarks/batch.py --voyages 16 --workers 1,2,4 --command 'events detect' \\
        --args '--roll-channel ref_roll --pitch-channel ref_pitch'
    python benchmarks/batch.py --fleet                  # the fleet case (issue 37): 48 voyages (5.8 M rows) as CSV
    python benchmarks/batch.py --fleet --format parquet #   and as Parquet; 1, 2, 4, 8, 16 workers (those the machine
                                                        #   has cores for) and a Dask LocalCluster of all cores

Each configuration runs the real command line (``imutool batch COMMAND DIR -o ... --json``) in a fresh process
and prints wall time, files/s, rows/s and rows/s per worker (ideal scaling keeps rows/s per worker constant), and
the summed time of the jobs themselves (job s; wall minus job s / workers ≈ start-up: pool or cluster,
imports) and their CPU time per wall second (job cpu/s: how many cores a job kept busy; batch gives each of N
workers cores ÷ N threads, formats/jit/threads.py, so it stays at or under that share). One warm-up run first fills
the numba cache so no configuration pays the JIT compile. The machine is
shared; run on a quiet machine for figures worth quoting.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import formats  # noqa: E402
from imutool.sim import simulate  # noqa: E402


def _imutool(args: list[str], env: dict[str, str]) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", "from imutool.cli import main; main()", *args], env=env, capture_output=True, text=True
    )


def busy(tot: dict) -> float:
    """The jobs' CPU seconds per wall second: how many cores one job kept busy on average."""
    return tot.get("job_cpu_seconds", 0.0) / max(tot["job_seconds"], 1e-9)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--voyages", type=int, default=8)
    ap.add_argument("--duration", type=float, default=600.0, help="s per voyage")
    ap.add_argument("--rate", type=float, default=50.0, help="Hz")
    ap.add_argument("--command", default="filter")
    ap.add_argument("--args", default="", help="options for the command")
    ap.add_argument("--workers", default="1,2", help="local worker counts, comma-separated")
    ap.add_argument("--dask", type=int, default=2, help="Dask LocalCluster workers (0: skip)")
    ap.add_argument("--format", choices=("csv", "parquet"), default="csv", help="the voyages' file format")
    ap.add_argument("--fleet", action="store_true", help="48 voyages of 1 h at 33.3 Hz; workers 1..16 up to the cores")
    ap.add_argument("--tmp", default=None)
    a = ap.parse_args()
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    if a.fleet:
        a.voyages, a.duration, a.rate = 48, 3600.0, 100.0 / 3.0
        a.workers = ",".join(str(n) for n in (1, 2, 4, 8, 16) if n <= cores)
        a.dask = cores
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    with tempfile.TemporaryDirectory(dir=a.tmp) as d:
        src = Path(d) / "voyages"
        src.mkdir()
        rows = 0
        for k in range(a.voyages):
            rec = simulate("ship-at-sea", duration=a.duration, rate_hz=a.rate, seed=k)
            formats.write(rec, src / f"voyage{k:03d}.{a.format}")
            rows += len(rec)
        ext = ".json" if a.command.startswith("events") else ".csv"
        print(
            f"{a.voyages} voyages x {a.duration:.0f} s at {a.rate:g} Hz ({rows:,} rows, "
            f"{sum(p.stat().st_size for p in src.iterdir()) / 1e6:.0f} MB {a.format}); command: imutool {a.command} "
            f"{a.args}; {cores} usable cores"
        )
        one = next(iter(sorted(src.iterdir())))
        warm = _imutool(
            [*shlex.split(a.command), str(one), "-o", str(Path(d) / f"warm{ext}"), *shlex.split(a.args)], env
        )
        if warm.returncode:
            sys.exit(f"warm-up failed: {warm.stderr.strip()}")
        configs = [(f"local {n} worker{'s' if n > 1 else ''}", n, []) for n in map(int, a.workers.split(","))]
        if a.dask:
            configs.append((f"dask LocalCluster {a.dask} workers", a.dask, ["--dask"]))
        print(
            f"{'configuration':32s} {'wall s':>7s} {'files/s':>8s} {'k rows/s':>9s} {'k rows/s/worker':>16s} "
            f"{'ok':>4s} {'job s':>7s} {'job cpu/s':>9s}"
        )
        base = None
        for label, n, extra in configs:
            out = Path(d) / f"out_{label.replace(' ', '_')}"
            t0 = time.perf_counter()
            r = _imutool(
                [
                    "batch",
                    a.command,
                    str(src),
                    "-o",
                    str(out / f"{{stem}}{ext}"),
                    "-j",
                    str(n),
                    *extra,
                    "--args",
                    a.args,
                    "--json",
                ],
                env,
            )
            wall = time.perf_counter() - t0
            try:
                tot = json.loads(r.stdout)["totals"]
            except (ValueError, KeyError):
                print(f"{label:32s} failed: {r.stderr.strip()[-300:]}")
                continue
            rate = rows / wall
            base = base or rate
            print(
                f"{label:32s} {wall:7.1f} {a.voyages / wall:8.2f} {rate / 1e3:9.1f} {rate / n / 1e3:16.1f} "
                f"{tot['ok']:4d} {tot['job_seconds']:7.1f} {busy(tot):9.2f}"
                f"   speed-up {rate / base:.2f}"
            )


if __name__ == "__main__":
    main()
