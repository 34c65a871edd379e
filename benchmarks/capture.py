"""Sustained capture throughput through a pseudo-terminal: frames/s and CPU share of the capture process.

    python benchmarks/capture.py [--rate 5000] [--seconds 10] [--protocol nmea] [--repeat 3]
    python benchmarks/capture.py --sentences     # µs per NMEA sentence: full path vs formats.nmea.decode_fast

For each protocol (NMEA, bridge text, bridge binary) the simulator streams at ``--rate`` frames/s into a pty
while `imutool capture serial` records it; the capture process's CPU time (start-up included) is read when
it exits, divided by its wall time. Target (issue 9): ≥ 5 000 frames/s with ≤ 20 % of one core.
The machine's load average is printed with each figure: other processes slow the capture down too.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

PROTOCOLS = ("nmea", "bridge", "bridge-binary")


def _imutool(*args: str) -> list[str]:
    return [sys.executable, "-c", "from imutool.cli import main; main()", *args]


def measure(protocol: str, rate: float, seconds: float) -> dict:
    work = tempfile.mkdtemp(prefix="imutool-capbench-")
    link = os.path.join(work, "port")
    server = subprocess.Popen(
        _imutool(
            "simulate",
            "--serve",
            link,
            "--protocol",
            protocol,
            "--rate",
            str(rate),
            "--duration",
            str(seconds),
            "--start-delay",
            "2",
            "--quiet",
        ),
        stderr=subprocess.DEVNULL,
    )
    while not os.path.lexists(link):
        time.sleep(0.02)
    out = os.path.join(work, "out.csv")
    t0 = time.monotonic()
    cap = subprocess.Popen(
        _imutool(
            "capture",
            "serial",
            link,
            "--protocol",
            protocol,
            "-o",
            out,
            "--duration",
            str(seconds + 3.5),
            "--json",
            "--status",
            "0",
        ),
        stdout=subprocess.PIPE,
        text=True,
    )
    stdout = cap.stdout.read()
    _, _, usage = os.wait4(cap.pid, 0)  # the capture process alone (the simulator is another child)
    wall = time.monotonic() - t0
    server.wait()
    cpu = usage.ru_utime + usage.ru_stime
    summary = json.loads(stdout)
    frames = summary["frames"]
    return {
        "protocol": protocol,
        "frames": frames,
        "frames_per_s_streamed": rate,
        "capture_cpu_s": round(cpu, 2),
        "streaming_s": seconds,
        "cpu_share_of_one_core": round(cpu / wall, 3),
        "errors": summary["errors"],
        "dropped": summary["dropped"],
    }


def sentence_timings(number: int = 2000, repeat: int = 15) -> None:
    """Best-of-``repeat`` µs per call for the full path (parse_sentence + decode) and decode_fast."""
    import timeit

    from formats import nmea

    lines = {
        "HDT": nmea.hdt_sentence(123.4),
        "THS": nmea.ths_sentence(123.4),
        "XDR (roll + pitch)": nmea.xdr_roll_pitch(3.2, -1.5),
        "HDG": nmea.hdg_sentence(120.3, 1.2, -3.4),
        "ROT": nmea.rot_sentence(-3.2),
        "PASHR": nmea.pashr_sentence(3600.0, 12.0, 1.0, 2.0, 0.3),
        "HRM": nmea.hrm_sentence(1.5, 8, 3, 4, True),
    }
    print(f"load average {os.getloadavg()[0]:.2f}")
    print("| sentence | `parse_sentence` + `decode` (µs) | `decode_fast` (µs) |\n|---|---:|---:|")
    for name, line in lines.items():

        def full_path(line: str = line) -> dict:
            return nmea.decode(nmea.parse_sentence(line))

        full = min(timeit.repeat(full_path, number=number, repeat=repeat))
        fast = min(timeit.repeat(lambda line=line: nmea.decode_fast(line), number=number, repeat=repeat))
        print(f"| {name} | {1e6 * full / number:.1f} | {1e6 * fast / number:.1f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rate", type=float, default=5000.0)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--protocol", choices=PROTOCOLS, action="append", help="only this protocol (repeatable)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per protocol (the machine may be shared)")
    ap.add_argument("--sentences", action="store_true", help="only time the NMEA decoders per sentence")
    args = ap.parse_args()
    if args.sentences:
        sentence_timings()
        return
    print(
        f"{'protocol':15s} {'frames':>8s} {'rate/s':>8s} {'CPU s':>7s} {'core %':>7s} {'errors':>6s} {'drops':>6s}"
        f"  load avg (1 min, before → after)",
        flush=True,
    )
    for proto in args.protocol or PROTOCOLS:
        for _ in range(args.repeat):
            load0 = os.getloadavg()[0]
            r = measure(proto, args.rate, args.seconds)
            print(
                f"{proto:15s} {r['frames']:8d} {r['frames_per_s_streamed']:8.0f} {r['capture_cpu_s']:7.2f} "
                f"{100 * r['cpu_share_of_one_core']:6.1f}% {r['errors']:6d} {r['dropped']:6d}"
                f"  {load0:.2f} → {os.getloadavg()[0]:.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
