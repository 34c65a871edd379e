"""`imutool filter` on one big CSV against the pipeline a user who knows the field would write (issue 52).

The peers, each on the same file in its own process, interleaved in ``--repeat`` rounds (what runs first in a round
is rotated): **polars reads the CSV → VQF (C++, ``vqf.VQF.updateBatch``) → polars writes roll/pitch/heading and the
quaternion**; the same with ``vqf.offlineVQF``; and polars read + write alone (the floor). For each: best and
median wall time (what a user waits), median CPU, the median of its peak RSS (``ru_maxrss`` of the child), and
imutool's wall / the peer's per round (issue 52's acceptance: ≤ 1.0, goal 0.7, peak RSS ≤ the peer's).
``--baseline`` runs another clone of imutool in the same rounds (an A/B).

``--day``: a day at 200 Hz (17.28 M rows, ~3 GB, built once from the 2 M-row file with shifted times, deleted at
the end unless ``--keep``): one run of each — imutool streams it (``filter`` streams a CSV above ``--stream-mb``,
300 MB), the polars + VQF peer holds it all in memory — wall and peak RSS of both.

The filter's stages are timed in a separate run (``--stages``): wall and thread CPU of each stage, the background
threads (reader, parse, writer, format) included, imports and the kernels' first calls apart.

Usage::

    python benchmarks/filter_csv.py                  # 2 M rows at 200 Hz (a 370 MB CSV, written once to --dir)
    python benchmarks/filter_csv.py --rows 500000 --repeat 3 --stages
    python benchmarks/filter_csv.py --repeat 0 --stages   # the stages alone (wall and CPU per stage, per thread)
    python benchmarks/filter_csv.py --repeat 8 --baseline ../main   # A/B: another clone in the same rounds
    python benchmarks/filter_csv.py --repeat 0 --stages --baseline ../main   # the stages of both
    python benchmarks/filter_csv.py --repeat 0 --day      # the day: streamed imutool against the peer, once each

imutool's children keep their modules' bytecode (``--no-bytecode``: not, as before 2026-12-06; see :func:`tree_env`).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path and not os.environ.get("IMUTOOL_BENCH_TREE"):  # (--stages of a --baseline: its tree)
    sys.path.insert(0, str(ROOT))

POLARS = """
import sys, polars as pl
df = pl.read_csv(sys.argv[1], comment_prefix="#")
df.write_csv(sys.argv[2])
"""
# the peer a user would write: polars in, VQF (C++) on the whole arrays, polars out (roll/pitch/heading, quaternion).
# VQF's body frame is z up (it reads +g at rest): FRD's y and z are turned over on the way in; the angles (ZYX, deg)
# and the quaternion are written in VQF's own frames (a user would turn them back: a few array operations more)
VQF_PEER = """
import sys, numpy as np, polars as pl, vqf
df = pl.read_csv(sys.argv[1], comment_prefix="#")
t = df["time"].to_numpy()
flu = np.array([1.0, -1.0, -1.0])
def axes(name):
    return np.ascontiguousarray(df.select([f"{name}_x", f"{name}_y", f"{name}_z"]).to_numpy(), dtype=np.float64) * flu
gyr, acc, mag = axes("gyro"), axes("accel"), axes("mag")
ts = float(np.median(np.diff(t[:10000])))
if sys.argv[3] == "offline":
    q = vqf.offlineVQF(gyr, acc, mag, ts)["quat9D"]
else:
    q = vqf.VQF(ts).updateBatch(gyr, acc, mag)["quat9D"]
del gyr, acc, mag
w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
roll = np.degrees(np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)))
pitch = np.degrees(np.arcsin(np.clip(2 * (w * y - z * x), -1, 1)))
heading = np.degrees(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))) % 360
pl.DataFrame({"time": t, "roll": roll, "pitch": pitch, "heading": heading, "q_w": w, "q_x": x, "q_y": y, "q_z": z}
             ).write_csv(sys.argv[2])
"""
# what the `imutool` executable runs: its console script (pyproject: imutool.cli:run, which ends the process without
# Python's module teardown; a clone from before it has main only)
FILTER = "from imutool import cli; getattr(cli, 'run', cli.main)()"


def make_csv(path: Path, rows: int) -> None:
    """A ship-roll recording of ``rows`` samples at 200 Hz: time, gyro, accel, mag (10 columns)."""
    import formats
    from imutool.sim import simulate

    rec = simulate("ship-roll", duration=(rows - 1) / 200.0, seed=3)
    keep = formats.Recording(rec.time, {c: rec[c] for c in ("gyro", "accel", "mag")})
    for c in ("gyro", "accel", "mag"):
        keep.units[c] = rec.units[c]
    formats.write(keep, path)


BYTECODE = {"on": True}  # imutool's children with their bytecode (--no-bytecode: compiled from source each run)


def tree_env(tree: Path, cwd: Path) -> dict[str, str]:
    """The environment of a child running the clone ``tree``: it first on the path and, unless --no-bytecode, its
    modules' bytecode kept (in ``cwd``/pycache, outside the clone) as an installed package has it. Where
    ``PYTHONDONTWRITEBYTECODE`` is set (this project's sessions set it) a clone without ``__pycache__`` compiles its
    ~60 modules from source at every start: 0.24 s of CPU that no installed imutool spends (`-X importtime`: our
    modules' self time 314 against 73 ms), while the peers' libraries come with their bytecode."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    if BYTECODE["on"]:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(cwd / "pycache")
    return env


def timed(cmd: list[str], cwd: Path, tree: Path | None = None) -> tuple[float, float, float]:
    """(wall s, CPU s, peak RSS MB) of one command's child process, run in ``cwd`` (``python -c`` puts the working
    folder first on the path: never the folder holding a clone), with ``tree`` (a clone of imutool) first on its
    path (:func:`tree_env`). The peak is the child's own ``ru_maxrss`` (from ``wait4``, not the maximum over all
    children so far)."""
    env = dict(os.environ) if tree is None else tree_env(tree, cwd)
    t0 = time.perf_counter()
    for arg in cmd:  # the previous run's output (filter refuses to overwrite a file)
        if arg.endswith(".csv") and Path(arg).name.startswith(("est_", "peer_", "polars")):
            Path(arg).unlink(missing_ok=True)
    child = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, cwd=cwd, env=env)
    _, status, use = os.wait4(child.pid, 0)
    wall = time.perf_counter() - t0
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode:
        raise subprocess.CalledProcessError(child.returncode, cmd)
    return wall, use.ru_utime + use.ru_stime, use.ru_maxrss / 1024.0


# (stage, module, attribute, kind): the functions timed by --stages, in the order of a sample's way through the run.
# kind "call" times each call, "iter" each step of a generator; CPU is the thread CPU of the thread that runs it. A
# function not found (the CSV engine's, once replaced) is said and left out.
STAGES = (
    ("rows expected (the input's first MiB)", "imutool.filtering", "expected_rows", "call"),
    ("read + parse: reader thread (read, cut, channel copies)", "formats.csv", "_iter_csv", "iter"),
    ("  of which the channel copies", "formats.csv", "_to_recording", "call"),
    ("read + parse: parse threads", "formats.csv", "_BlockParser.parse", "call"),
    ("validation + plausibility (per chunk)", "imutool.loading", "ChunkChecks.prepare", "call"),
    ("  of which absurd samples bridged", "formats.plausibility", "bridge_absurd", "call"),
    ("  of which the plausibility checks", "imutool.loading", "ChunkChecks._check_plausibility", "call"),
    ("motion analysis", "imutool.filtering", "choose_motion", "call"),
    ("lever-arm estimate (first 600 s)", "imutool.filtering", "_stream_lever_arm", "call"),
    ("  of which its filter runs", "imutool.attitude.recording", "run_ekf", "call"),
    ("  of which its regressions", "imutool.attitude.lever_estimate", "lever_arm_regression", "call"),
    ("saturation (clipping) check", "imutool.filtering", "drop_clipped", "call"),
    ("EKF (EkfStepper.step: inputs, kernel, outputs)", "imutool.attitude.run", "EkfStepper.step", "call"),
    ("  of which the kernel", "imutool.attitude.run", "ekf_kernel", "call"),
    ("GNSS-aided pass", "imutool.filtering", "aided_result", "call"),
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

    missing = []
    for stage, module, attr, kind in STAGES:
        owner = importlib.import_module(module)
        *path, name = attr.split(".")
        for p in path:
            owner = getattr(owner, p, None)
        f = getattr(owner, name, None)
        if f is None:
            missing.append(f"{module}.{attr}")
            continue
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
    if missing:
        print(f"not timed (not found in this tree): {', '.join(missing)}")


def stages(src: Path, out: Path, tree: Path = ROOT) -> None:
    """Where the time goes: :func:`stage_run` in a fresh process (its imports and kernel loads as a user's), with
    ``tree`` (a clone of imutool) on its path."""
    env = dict(tree_env(tree, out.parent), IMUTOOL_BENCH_TREE=str(tree))
    print(f"stages of {tree}:", flush=True)
    subprocess.run([sys.executable, __file__, "--stage-run", str(src), str(out)], check=True, cwd=out.parent, env=env)


def peers(src: Path, work: Path, tree_sides: dict[str, Path]) -> dict[str, tuple[list[str], Path | None]]:
    """name → (command, tree on its path) of every side run in a round: the imutool clone(s), the VQF peers, polars."""
    sides: dict[str, tuple[list[str], Path | None]] = {}
    for name, tree in tree_sides.items():
        sides[name] = (
            [sys.executable, "-c", FILTER, "filter", str(src), "-o", str(work / f"est_{name}.csv"), "-q"],
            tree,
        )
    for kind in ("vqf", "offline"):
        sides[f"polars+{kind}"] = (
            [sys.executable, "-c", VQF_PEER, str(src), str(work / f"peer_{kind}.csv"), kind],
            None,
        )
    sides["polars r+w"] = ([sys.executable, "-c", POLARS, str(src), str(work / "polars.csv")], None)
    return sides


def rounds(sides: dict[str, tuple[list[str], Path | None]], work: Path, repeat: int) -> None:
    """``repeat`` rounds of every side (the order rotated each round); per round and in summary: wall, CPU, peak RSS
    and imutool's wall / each peer's."""
    runs: dict[str, list[tuple[float, float, float]]] = {name: [] for name in sides}
    names, loads = list(sides), []
    for k in range(repeat):
        loads.append(os.getloadavg()[0])
        order = names[k % len(names) :] + names[: k % len(names)]
        for name in order:
            cmd, tree = sides[name]
            runs[name].append(timed(cmd, work, tree))
        f = runs["filter"][-1][0]
        print(
            f"round {k + 1} (load {loads[-1]:.1f}): "
            + ", ".join(f"{n} {runs[n][-1][0]:.2f} s {runs[n][-1][2]:.0f} MB" for n in names)
            + "; filter / "
            + ", ".join(f"{n} {f / runs[n][-1][0]:.2f}" for n in names if n != "filter"),
            flush=True,
        )
    print(f"{repeat} rounds (load {min(loads):.1f}–{max(loads):.1f} on {os.cpu_count()} cores): best / median wall, "
          "median CPU, median peak RSS; imutool's wall / the side's per round: median (range)")  # fmt: skip
    for name in names:
        wall = sorted(r[0] for r in runs[name])
        cpu = sorted(r[1] for r in runs[name])
        rss = sorted(r[2] for r in runs[name])
        m = len(wall) // 2
        line = f"{name:14s}: {wall[0]:6.2f} / {wall[m]:6.2f} s wall, {cpu[m]:6.2f} s CPU, {rss[m]:6.0f} MB peak"
        if name != "filter":
            ratios = sorted(f[0] / r[0] for f, r in zip(runs["filter"], runs[name], strict=True))
            line += f"; filter/{name} {ratios[m]:.2f} ({ratios[0]:.2f}–{ratios[-1]:.2f})"
        print(line)
    print("acceptance (issue 52): filter / polars+vqf <= 1.0 (goal 0.7), filter's peak RSS <= the peer's")


DAY_ROWS = 86_400 * 200


def make_day(src: Path, day: Path) -> None:
    """A day at 200 Hz from the 2 M-row file: its rows repeated with the time shifted on (a step in the attitude at
    each seam, as a sensor re-seated; the filter takes it), written by polars in one pass per copy."""
    import polars as pl

    df = pl.read_csv(src, comment_prefix="#")
    span = float(df["time"][-1] - df["time"][0]) + float(df["time"][1] - df["time"][0])
    head = [line for line in src.read_text(errors="replace").splitlines()[:5] if line.startswith("#")]
    with open(day, "w") as f:
        f.write("".join(h + "\n" for h in head))
        done, k = 0, 0
        while done < DAY_ROWS:
            part = df.head(DAY_ROWS - done).with_columns(pl.col("time") + k * span)
            part.write_csv(f, include_header=k == 0)
            done, k = done + len(part), k + 1


def day_case(src: Path, work: Path, keep: bool) -> None:
    """One streamed imutool run and one polars + VQF run over a day's CSV: wall and peak RSS of each."""
    day = work / "day.csv"
    if not day.exists():
        print(f"writing {day} ({DAY_ROWS} rows) ...", flush=True)
        make_day(src, day)
    print(f"{day}: {day.stat().st_size / 1e9:.2f} GB; load average {os.getloadavg()[0]:.1f}", flush=True)
    try:
        sides = peers(day, work, {"filter": ROOT})
        for name in ("filter", "polars+vqf"):
            wall, cpu, rss = timed(*sides[name][:1], work, sides[name][1])
            print(f"day, {name:11s}: {wall:7.1f} s wall, {cpu:7.1f} s CPU, {rss:7.0f} MB peak RSS", flush=True)
    finally:
        for f in (day, work / "est_filter.csv", work / "peer_vqf.csv"):
            if f != day or not keep:
                f.unlink(missing_ok=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rows", type=int, default=2_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--dir", default="/tmp")
    ap.add_argument("--stages", action="store_true", help="also time the stages of one run (in a fresh process)")
    ap.add_argument("--baseline", help="another clone of imutool (e.g. main's) run in the same rounds, for an A/B")
    ap.add_argument("--day", action="store_true", help="a day at 200 Hz: streamed imutool vs the peer, once each")
    ap.add_argument("--keep", action="store_true", help="keep the day's CSV (3 GB) for another run")
    ap.add_argument(
        "--no-bytecode", action="store_true", help="imutool's modules compiled from source at each start (as before)"
    )
    ap.add_argument("--stage-run", nargs=2, metavar=("SRC", "OUT"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    BYTECODE["on"] = not a.no_bytecode
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
    trees = {"filter": ROOT} | ({"baseline": Path(a.baseline).resolve()} if a.baseline else {})
    sides = peers(src, work, trees)
    for name in trees:  # compiled kernels cached, files in the page cache
        timed(*sides[name][:1], work, sides[name][1])
    if a.repeat:
        rounds(sides, work, a.repeat)
        if a.baseline:
            same = (work / "est_filter.csv").read_bytes() == (work / "est_baseline.csv").read_bytes()
            print(f"outputs byte-identical: {same}")
    if a.day:
        day_case(src, work, a.keep)
    if a.stages:  # (with --baseline: its stages too, first)
        for tree in reversed(trees.values()):
            out = work / "est_stages.csv"
            out.unlink(missing_ok=True)
            stages(src, out, tree)


if __name__ == "__main__":
    main()
