"""I/O speed: CSV read/write rows/s (CSV section) and ROS bag read messages/s (bag section).

Run: ``python benchmarks/io.py [--bag-messages 200000] [--repeat 3]``. Prints figures; no assertions.
Sections are independent functions called from :func:`main`.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time

import numpy as np


# -- ROS bags ---------------------------------------------------------------------------------------------------
def bench_bag_read(n_messages: int = 200_000, repeat: int = 3) -> dict[str, dict[str, float]]:
    """Write an n-message sensor_msgs/Imu bag (ROS1 .bag and ROS2 sqlite3 folder) with formats.rosbag.write_bag,
    then time formats.rosbag.read_bag (fast path) and, on a 20 000-message slice, rosbags' own per-message
    deserialise for comparison. Returns {format: {"write_s", "read_msgs_per_s", "rosbags_deserialise_msgs_per_s"}}.
    """
    from pathlib import Path

    from formats import Recording
    from formats.rosbag import read_bag, write_bag

    rng = np.random.default_rng(0)
    rec = Recording(1_700_000_000.0 + np.arange(n_messages) * 0.005)
    rec.add("gyro", rng.normal(size=(n_messages, 3)) * 0.1)
    rec.add("accel", rng.normal(size=(n_messages, 3)) + [0, 0, -9.81])
    rec.add("q", np.tile([1.0, 0.0, 0.0, 0.0], (n_messages, 1)))
    rec.add("roll_std", np.full(n_messages, 0.5))
    rec.add("pitch_std", np.full(n_messages, 0.5))
    rec.add("heading_std", np.full(n_messages, 2.0))
    results: dict[str, dict[str, float]] = {}
    tmp = tempfile.mkdtemp(prefix="imutool-bench-bag-")
    try:
        read_bag(_small_bag(tmp))  # compile / warm numba kernels outside the timing
        for label, name in (("ROS1 .bag", "b.bag"), ("ROS2 sqlite3", "b_sqlite3"), ("ROS2 MCAP", "b.mcap")):
            path = os.path.join(tmp, name)
            t0 = time.perf_counter()
            write_bag(rec, path)
            t_write = time.perf_counter() - t0
            best = best_cpu = np.inf
            for _ in range(repeat):
                t0, c0 = time.perf_counter(), time.process_time()
                out = read_bag(path)
                best = min(best, time.perf_counter() - t0)
                best_cpu = min(best_cpu, time.process_time() - c0)
            assert len(out) == n_messages
            # rosbags' per-message deserialise for comparison (on the first 20 000 raw messages)
            from rosbags.highlevel import AnyReader

            k = min(n_messages, 20_000)
            with AnyReader([Path(path)]) as r:
                raws = []
                for c, _, raw in r.messages():
                    raws.append((c.msgtype, raw))
                    if len(raws) >= k:
                        break
                c0 = time.process_time()
                for typ, raw in raws:
                    r.deserialize(raw, typ)
                t_des = time.process_time() - c0
            results[label] = {"messages": n_messages, "write_s": t_write, "read_s": best,
                              "read_msgs_per_s": n_messages / best, "read_cpu_s": best_cpu,
                              "read_msgs_per_cpu_s": n_messages / best_cpu,
                              "rosbags_deserialise_msgs_per_cpu_s": k / t_des}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return results


def _small_bag(folder: str) -> str:
    from formats import Recording
    from formats.rosbag import write_bag

    r = Recording(np.arange(10) * 0.01)
    r.add("gyro", np.zeros((10, 3)))
    p = os.path.join(folder, "warm.bag")
    write_bag(r, p)
    return p


def print_bag(results: dict[str, dict[str, float]]) -> None:
    print("ROS bag read (sensor_msgs/Imu, formats.rosbag.read_bag; best of repeats; CPU = process time, the fair")
    print("figure on a shared machine)")
    print("| format | messages | read wall s | read CPU s | msgs/s (wall) | msgs/s (CPU) | rosbags deserialise "
          "msgs/s (CPU) | write s |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for label, r in results.items():
        print(f"| {label} | {r['messages']:,} | {r['read_s']:.2f} | {r['read_cpu_s']:.2f} | "
              f"{r['read_msgs_per_s']:,.0f} | {r['read_msgs_per_cpu_s']:,.0f} | "
              f"{r['rosbags_deserialise_msgs_per_cpu_s']:,.0f} | {r['write_s']:.1f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--bag-messages", type=int, default=200_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    try:
        print(f"load average: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    except OSError:
        pass
    # CSV section: added by the CSV benchmark (bench_csv...) — keep the bag section below independent.
    print_bag(bench_bag_read(args.bag_messages, args.repeat))


if __name__ == "__main__":
    main()
