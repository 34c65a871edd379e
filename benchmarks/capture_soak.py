"""Capture soak test: the simulator streams bridge frames through a pseudo-terminal into `imutool capture`.

The port is unplugged and replugged several times, random bits are flipped, and the capture process is
killed with SIGKILL once and restarted with --append. Afterwards every frame the simulator reports as sent
must be in the output or inside a gap the capture reported (events file) — zero silent loss — and every
output file must parse.

    python benchmarks/capture_soak.py --duration 600 --rate 1000      # the full 10-minute soak
    python benchmarks/capture_soak.py --duration 60 --rate 500         # the CI version (tests/test_capture.py)
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _imutool(*args: str) -> list[str]:
    return [sys.executable, "-c", "from imutool.cli import main; main()", *args]


def run_soak(
    duration: float = 60.0,
    rate: float = 500.0,
    replugs: int = 5,
    corrupt: float = 0.002,
    kill: bool = True,
    workdir: str | None = None,
    protocol: str = "bridge",
) -> dict:
    work = Path(workdir or tempfile.mkdtemp(prefix="imutool-soak-"))
    link = str(work / "port")
    out = work / "soak.csv"
    sent_log = work / "sent.json"
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
            str(duration),
            "--corrupt",
            str(corrupt),
            "--replug-every",
            str(duration / (replugs + 1)),
            "--serve-log",
            str(sent_log),
            "--start-delay",
            "0.5",
            "--start-when",
            str(out.with_suffix(".events.jsonl")),
            "--quiet",
        ),
        stderr=subprocess.PIPE,
        text=True,
    )
    for _ in range(200):
        if os.path.lexists(link):
            break
        time.sleep(0.05)
    cap_args = ["capture", "serial", link, "--protocol", protocol, "-o", str(out), "--status", "0", "--quiet"]
    cpu0 = os.times()
    capture = subprocess.Popen(_imutool(*cap_args))
    killed_at = None
    if kill:
        time.sleep(duration * 0.45 + 3)
        capture.send_signal(signal.SIGKILL)
        capture.wait()
        killed_at = time.time()
        capture = subprocess.Popen(_imutool(*cap_args, "--append"))
    server.wait()
    time.sleep(1.0)
    capture.send_signal(signal.SIGTERM)
    capture.wait(timeout=30)
    cpu1 = os.times()
    return verify(
        out,
        sent_log,
        killed_at is not None,
        cpu_s=(cpu1.children_user + cpu1.children_system) - (cpu0.children_user + cpu0.children_system),
    )


def verify(out: Path, sent_log: Path, killed: bool, cpu_s: float = float("nan")) -> dict:
    """Account for every sent frame: received, or inside a reported sequence gap."""
    import numpy as np

    from formats.csv import read_csv

    sent = json.loads(Path(sent_log).read_text())
    rec = read_csv(str(out))
    seq = rec["seq"].astype(np.int64)
    events = [json.loads(x) for x in out.with_suffix(".events.jsonl").read_text().splitlines() if x.strip()]
    reported = {(e["after_seq"], e["missing"]) for e in events if e["event"] == "sequence_gap"}
    steps = (np.diff(seq) % 65536) - 1
    unreported = 0
    missing_total = 0
    for i in np.flatnonzero(steps > 0):
        missing_total += int(steps[i])
        if (int(seq[i]), int(steps[i])) not in reported:
            unreported += int(steps[i])
    first_id, last_id = sent["first_id"], sent["last_id"]
    before = int(seq[0]) - (first_id % 65536) if len(seq) else 0
    tail = (last_id - first_id + 1) - (len(seq) + missing_total + before)
    silent = unreported + max(before, 0) + max(tail, 0)
    return {
        "sent": sent["sent"],
        "received": int(len(seq)),
        "missing_reported": missing_total - unreported,
        "missing_unreported": unreported,
        "lost_before_first_frame": before,
        "lost_after_last_frame": tail,
        "silent_loss": silent,
        "corrupted_sent": len(sent["corrupted"]),
        "replugs": sent["reconnects"],
        "killed_and_restarted": killed,
        "port_reopen_events": sum(e["event"] == "port_reopened" for e in events),
        "restarts_resumed": sum(e["event"] == "resumed" for e in events),
        "rows_skipped_by_reader": int(rec.meta.get("skipped_rows", 0)),
        "capture_cpu_s": round(cpu_s, 2),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--replugs", type=int, default=5)
    ap.add_argument("--corrupt", type=float, default=0.002)
    ap.add_argument("--no-kill", action="store_true")
    args = ap.parse_args()
    res = run_soak(args.duration, args.rate, args.replugs, args.corrupt, not args.no_kill)
    print(json.dumps(res, indent=2))
    sys.exit(0 if res["silent_loss"] == 0 else 1)


if __name__ == "__main__":
    main()
