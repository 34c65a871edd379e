"""`imutool filter` on one big CSV against a plain polars read + write of the same file, in the same run.

The goal (issue 37): the whole filter — read, validate, plausibility, EKF, self-checks, format, write — within
1.5× of what polars needs only to read and write the file. Each side runs in its own process, interleaved in
``--repeat`` rounds (``--baseline``: another clone too, for an A/B); best and median wall time (what a user waits),
median CPU time, and the ratio to polars of each round (on a shared machine the load decides the best round).
The filter's stages are timed in a separate run (``--stages``): wall and thread CPU of each stage, the background
threads (reader, parse, writer, format) included, imports and the kernels' first calls apart.

Usage::

    python benchmarks/filter_csv.py                  # 2 M rows at 200 Hz (a 370 MB CSV, written once to --dir)
    python benchmarks/filter_csv.py --rows 500000 --repeat 3 --stages
    python benchmarks/filter_csv.py --repeat 0 --stages   # the stages alone (wall and CPU per stage, per thread)
    python benchmarks/filter_csv.py --repeat 8 --baseline ../main   # A/B: another clone in the same rounds
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

POLARS = """
import sys, polars as pl
df = pl.read_csv(sys.argv[1], comment_prefix="#")
df.write_csv(sys.argv[2])
"""
FILTER = "from imutool.cli import main; main()"


def make_csv(path: Path, rows: int) -> None:
    """A ship-roll recording of ``rows`` samples at 200 Hz: time, gyro, accel, mag (10 columns)."""
    import formats
    from imutool.sim import simulate

    rec = simulate("ship-roll", duration=(rows - 1) / 200.0, seed=3)
    keep = formats.Recording(rec.time, {c: rec[c] for c in ("gyro", "accel", "mag")})
    for c in ("gyro", "accel", "mag"):
        keep.units[c] = rec.units[c]
    formats.write(keep, path)


def timed(cmd: list[str], cwd: Path, tree: Path | None = None) -> tuple[float, float]:
    """(wall s, CPU s of the child) of one command, run in ``cwd`` (``python -c`` puts the working folder first on
    the path: never the folder holding a clone), with ``tree`` (a clone of imutool) first on its path."""
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = str(tree)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, cwd=cwd, env=env)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


# (stage, module, attribute, kind): the functions timed by --stages, in the order of a sample's way through the run.
# kind "call" times each call, "iter" each step of a generator; CPU is the thread CPU of the thread that runs it.
STAGES = (
    ("read + parse: reader thread (read, cut, channel copies)", "formats.csv", "_iter_csv", "iter"),
    ("  of which the channel copies", "formats.csv", "_to_recording", "call"),
    ("read + parse: parse threads", "formats.csv", "_BlockParser.parse", "call"),
    ("validation + plausibility", "imutool.loading", "ChunkChecks.prepare", "call"),
    ("motion analysis", "imutool.filtering", "choose_motion", "call"),
    ("saturation (clipping) check", "imutool.filtering", "drop_clipped", "call"),
    ("EKF (run_ekf: inputs, kernel, outputs)", "imutool.filtering", "run_ekf", "call"),
    ("  of which the kernel", "imutool.attitude.run", "ekf_kernel", "call"),
    ("self-checks (per chunk)", "imutool.attitude.selfcheck", "SelfCheck.add", "call"),
    ("  of which the gyro-scale check", "imutool.attitude.selfcheck", "SelfCheck._add_scale", "call"),
    ("  of which the turns", "imutool.attitude.selfcheck", "SelfCheck._add_turns", "call"),
    ("self-checks (report)", "imutool.attitude.selfcheck", "SelfCheck.report", "call"),
    ("output channels (degrees, flags)", "imutool.filtering", "result_recording", "call"),
    ("format + write: writer thread", "formats.csv", "_write_rows", "call"),
    ("format: format threads", "formats.csv", "_format_block", "call"),
    ("final header: rows copied behind it", "formats.csv", "copy_range", "call"),
    ("main thread waiting for the reader", "formats", "iter_chunks", "iter"),
)


def stage_run(src: str, out: str) -> None:
    """One streamed `filter` run in this (fresh) process with every stage of :data:`STAGES` timed: wall and
    thread-CPU per stage, summed over its calls and threads; imports and the kernels' first calls (numba's
    start-up and the load from the cache) apart."""
    import importlib
    import threading
    from collections import defaultdict

    t0, c0 = time.perf_counter(), time.process_time()
    from numba.core.dispatcher import Dispatcher

    from imutool.filtering import run_filter

    imports = (time.perf_counter() - t0, time.process_time() - c0)
    # the kernels' first calls (numba's start-up, each kernel loaded from the cache) in a streamed run of the file's
    # first 2 000 rows, so that the stages below are the work proper
    tiny = Path(out).with_suffix(".first_rows.csv")
    with open(src, "rb") as f, open(tiny, "wb") as g:
        g.writelines(line for _, line in zip(range(2000), f, strict=False))
    t0, c0 = time.perf_counter(), time.process_time()
    run_filter(tiny, Path(out).with_suffix(".first_rows.out.csv"), stream_mb=0)
    first = (time.perf_counter() - t0, time.process_time() - c0)
    for p in (tiny, Path(out).with_suffix(".first_rows.out.csv")):
        p.unlink()
    acc: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0, 0])
    threads: dict[str, set[str]] = defaultdict(set)

    def record(stage: str, w0: float, cpu0: float) -> None:
        a = acc[stage]
        a[0] += time.perf_counter() - w0
        a[1] += time.thread_time() - cpu0
        a[2] += 1
        threads[stage].add(threading.current_thread().name.rstrip("_0123456789"))

    def timed_call(f, stage):
        def w(*a, **k):
            w0, cpu0 = time.perf_counter(), time.thread_time()
            try:
                return f(*a, **k)
            finally:
                record(stage, w0, cpu0)

        return w

    def timed_iter(f, stage):
        def w(*a, **k):
            it = iter(f(*a, **k))
            while True:
                w0, cpu0 = time.perf_counter(), time.thread_time()
                try:
                    x = next(it)
                except StopIteration:
                    return
                finally:
                    record(stage, w0, cpu0)
                yield x

        return w

    for stage, module, attr, kind in STAGES:
        owner = importlib.import_module(module)
        *path, name = attr.split(".")
        for p in path:
            owner = getattr(owner, p)
        f = getattr(owner, name)
        setattr(owner, name, (timed_iter if kind == "iter" else timed_call)(f, stage))
    first_calls = Dispatcher._compile_for_args  # a kernel's first call (none expected any more)
    Dispatcher._compile_for_args = timed_call(first_calls, "kernels' first calls in the run proper")
    t0, c0 = time.perf_counter(), time.process_time()
    run_filter(src, out)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"imports {imports[0]:.2f} s wall, {imports[1]:.2f} s CPU")
    print(
        "kernels' first calls (numba start-up, loads from the cache; 2 000 rows): "
        f"{first[0]:.2f} s wall, {first[1]:.2f} s CPU"
    )
    print(f"run_filter {wall:.2f} s wall, {cpu:.2f} s CPU (all threads)")
    print(f"{'stage':58s} {'wall s':>7s} {'CPU s':>7s} {'calls':>6s}  threads")
    order = [s[0] for s in STAGES] + ["kernels' first calls in the run proper"]
    for stage in order:
        if stage in acc:
            w, c, n = acc[stage]
            print(f"{stage:58s} {w:7.2f} {c:7.2f} {n:6d}  {', '.join(sorted(threads[stage]))}")
    print("(wall: summed over the calls of each thread; the threads overlap)")


def stages(src: Path, out: Path) -> None:
    """Where the time goes: :func:`stage_run` in a fresh process (its imports and kernel loads as a user's)."""
    subprocess.run([sys.executable, __file__, "--stage-run", str(src), str(out)], check=True, cwd=out.parent)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rows", type=int, default=2_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--dir", default="/tmp")
    ap.add_argument("--stages", action="store_true", help="also time the stages of one run (in a fresh process)")
    ap.add_argument("--baseline", help="another clone of imutool (e.g. main's) run in the same rounds, for an A/B")
    ap.add_argument("--stage-run", nargs=2, metavar=("SRC", "OUT"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.stage_run:
        stage_run(*a.stage_run)
        return
    work = Path(a.dir) / f"imutool_filter_csv_{a.rows}"
    work.mkdir(parents=True, exist_ok=True)
    src = work / "in.csv"
    if not src.exists():
        print(f"writing {src} ({a.rows} rows) ...", flush=True)
        make_csv(src, a.rows)
    print(f"{src}: {src.stat().st_size / 1e6:.0f} MB; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    sides = {"filter": ROOT} | ({"baseline": Path(a.baseline).resolve()} if a.baseline else {})
    for name, tree in sides.items():  # compiled kernels cached, files in the page cache
        warm = work / f"warm_{name}.csv"
        warm.unlink(missing_ok=True)
        timed([sys.executable, "-c", FILTER, "filter", str(src), "-o", str(warm), "-q"], work, tree)
    runs: dict[str, list[tuple[float, float]]] = {name: [] for name in [*sides, "polars"]}
    loads = []
    for k in range(a.repeat):
        loads.append(os.getloadavg()[0])
        for name, tree in sides.items():
            out = work / f"est_{name}.csv"
            out.unlink(missing_ok=True)
            runs[name].append(
                timed([sys.executable, "-c", FILTER, "filter", str(src), "-o", str(out), "-q"], work, tree)
            )
        runs["polars"].append(timed([sys.executable, "-c", POLARS, str(src), str(work / "polars.csv")], work))
        p = runs["polars"][-1][0]
        print(
            f"round {k + 1}: load {loads[-1]:.1f}: "
            + ", ".join(f"{name} {runs[name][-1][0]:.2f} s ({runs[name][-1][0] / p:.2f}x)" for name in sides)
            + f", polars {p:.2f} s"
        )
    if a.repeat:
        print(f"{a.repeat} rounds (load {min(loads):.1f}–{max(loads):.1f}): best / median wall, median CPU; ratios")
        for name in runs:
            wall = sorted(r[0] for r in runs[name])
            cpu = sorted(r[1] for r in runs[name])
            line = f"{name:9s}: {wall[0]:6.2f} / {wall[len(wall) // 2]:6.2f} s wall, {cpu[len(cpu) // 2]:6.2f} s CPU"
            if name != "polars":
                ratios = sorted(r[0] / p[0] for r, p in zip(runs[name], runs["polars"], strict=True))
                line += f"; ratio median {ratios[len(ratios) // 2]:.2f}x ({ratios[0]:.2f}–{ratios[-1]:.2f})"
            print(line)
        if a.baseline:
            same = (work / "est_filter.csv").read_bytes() == (work / "est_baseline.csv").read_bytes()
            print(f"outputs byte-identical: {same}")
        print("goal: filter <= 1.5x polars")
    if a.stages:
        out = work / "est_stages.csv"
        out.unlink(missing_ok=True)
        stages(src, out)


if __name__ == "__main__":
    main()
