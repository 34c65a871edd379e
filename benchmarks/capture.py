"""Sustained capture throughput through a pseudo-terminal: frames/s and CPU share of the capture process.

    python benchmarks/capture.py [--rate 5000] [--seconds 10]

For each protocol (NMEA, bridge text, bridge binary) the simulator streams at ``--rate`` frames/s into a pty
while `imutool capture serial` records it; the capture process's CPU time is read when it exits.
Target (issue 9): ≥ 5 000 frames/s with ≤ 20 % of one core.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time


def _imutool(*args: str) -> list[str]:
    return [sys.executable, "-c", "from imutool.cli import main; main()", *args]


def measure(protocol: str, rate: float, seconds: float) -> dict:
    work = tempfile.mkdtemp(prefix="imutool-capbench-")
    link = os.path.join(work, "port")
    server = subprocess.Popen(_imutool("simulate", "--serve", link, "--protocol", protocol, "--rate", str(rate),
                                       "--duration", str(seconds), "--start-delay", "2", "--quiet"))
    while not os.path.lexists(link):
        time.sleep(0.02)
    out = os.path.join(work, "out.csv")
    t0 = time.monotonic()
    cap = subprocess.Popen(_imutool("capture", "serial", link, "--protocol", protocol, "-o", out, "--duration",
                                    str(seconds + 3.5), "--json", "--status", "0"), stdout=subprocess.PIPE, text=True)
    stdout = cap.stdout.read()
    _, _, usage = os.wait4(cap.pid, 0)  # the capture process alone (the simulator is another child)
    wall = time.monotonic() - t0
    server.wait()
    cpu = usage.ru_utime + usage.ru_stime
    summary = json.loads(stdout)
    frames = summary["frames"]
    return {"protocol": protocol, "frames": frames, "frames_per_s_streamed": rate,
            "capture_cpu_s": round(cpu, 2), "streaming_s": seconds,
            "cpu_share_of_one_core": round(cpu / wall, 3), "errors": summary["errors"],
            "dropped": summary["dropped"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rate", type=float, default=5000.0)
    ap.add_argument("--seconds", type=float, default=10.0)
    args = ap.parse_args()
    print(f"{'protocol':15s} {'frames':>8s} {'rate/s':>8s} {'CPU s':>7s} {'core %':>7s} {'errors':>6s} {'drops':>6s}")
    for proto in ("nmea", "bridge", "bridge-binary"):
        r = measure(proto, args.rate, args.seconds)
        print(f"{proto:15s} {r['frames']:8d} {r['frames_per_s_streamed']:8.0f} {r['capture_cpu_s']:7.2f} "
              f"{100 * r['cpu_share_of_one_core']:6.1f}% {r['errors']:6d} {r['dropped']:6d}")


if __name__ == "__main__":
    main()
