"""`imutool filter` on one big CSV against a plain polars read + write of the same file, in the same run.

The goal (issue 37): the whole filter — read, validate, plausibility, EKF, self-checks, format, write — within
1.5× of what polars needs only to read and write the file. Each side runs in its own process, interleaved, best of
``--repeat``; wall time (what a user waits) with CPU time alongside. The filter's stages are timed in a separate
in-process run (``--stages``): its main thread's profile, the kernel apart.

Usage::

    python benchmarks/filter_csv.py                  # 2 M rows at 200 Hz (a 370 MB CSV, written once to --dir)
    python benchmarks/filter_csv.py --rows 500000 --repeat 3 --stages
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


def timed(cmd: list[str]) -> tuple[float, float]:
    """(wall s, CPU s of the child) of one command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def stages(src: Path, out: Path) -> None:
    """The main thread's profile of one in-process run: where the time goes besides the kernel."""
    import cProfile
    import pstats

    from imutool.filtering import run_filter

    prof = cProfile.Profile()
    prof.enable()
    run_filter(src, out)
    prof.disable()
    pstats.Stats(prof).sort_stats("tottime").print_stats(12)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rows", type=int, default=2_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--dir", default="/tmp")
    ap.add_argument("--stages", action="store_true", help="also profile one in-process run")
    a = ap.parse_args()
    work = Path(a.dir) / f"imutool_filter_csv_{a.rows}"
    work.mkdir(parents=True, exist_ok=True)
    src = work / "in.csv"
    if not src.exists():
        print(f"writing {src} ({a.rows} rows) ...", flush=True)
        make_csv(src, a.rows)
    print(f"{src}: {src.stat().st_size / 1e6:.0f} MB; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    warm = work / "warm.csv"
    subprocess.run([sys.executable, "-c", FILTER, "filter", str(src), "-o", str(warm), "-q", "--force"], check=True)
    best = {"filter": (1e9, 0.0), "polars": (1e9, 0.0)}
    for _ in range(a.repeat):
        out = work / "est.csv"
        out.unlink(missing_ok=True)
        w = timed([sys.executable, "-c", FILTER, "filter", str(src), "-o", str(out), "-q"])
        best["filter"] = min(best["filter"], w)
        w = timed([sys.executable, "-c", POLARS, str(src), str(work / "polars.csv")])
        best["polars"] = min(best["polars"], w)
    (fw, fc), (pw, pc) = best["filter"], best["polars"]
    print(f"imutool filter : {fw:6.2f} s wall, {fc:6.2f} s CPU")
    print(f"polars r + w   : {pw:6.2f} s wall, {pc:6.2f} s CPU")
    print(f"ratio (wall)   : {fw / pw:.2f}x  (goal <= 1.5x)")
    if a.stages:
        out = work / "est_stages.csv"
        out.unlink(missing_ok=True)
        stages(src, out)


if __name__ == "__main__":
    main()
