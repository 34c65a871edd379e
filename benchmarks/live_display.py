"""`imutool live --http`: the bridge page's update rate and the server's CPU with five browsers connected.

    python benchmarks/live_display.py [--browsers 5] [--seconds 20]
    python benchmarks/live.py --only display           # the same, from the live benchmark

A simulated ship recording is replayed at real time by `imutool live --http` (a process of its own); its CPU
(user + system, /proc) is measured over ``--seconds`` with no browser, then with ``--browsers`` headless
Chromium pages (Debian's chromium + chromedriver through selenium; nothing downloaded) showing the page. The
update rate is each page's count of messages shown (``window.imutoolDisplay.messages``) over the same window.
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from imutool.sim import run_simulate  # noqa: E402


def _cpu(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _wait_valid(url: str, timeout: float) -> None:
    import json
    import urllib.request

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            with urllib.request.urlopen(url, timeout=2) as r:
                snap = json.loads(r.read())
            if snap and snap["status"] == "A":
                return
        except OSError:
            pass
        time.sleep(0.5)
    raise RuntimeError(f"no status A from {url} in {timeout:g} s")


def _browser(tmp: Path, i: int):
    os.environ["SE_OFFLINE"] = "true"
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for a in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
              "--disable-background-networking", "--disable-component-update", "--disable-sync",
              f"--user-data-dir={tmp / f'chromium{i}'}", "--window-size=1280,800"):  # fmt: skip
        opts.add_argument(a)
    return webdriver.Chrome(service=Service(shutil.which("chromedriver") or "/usr/bin/chromedriver"), options=opts)


def display(browsers: int = 5, seconds: float = 20.0) -> dict:
    """CPU of the server without and with ``browsers`` pages, and each page's messages per second."""
    tmp = Path(tempfile.mkdtemp(prefix="imutool-display-bench-"))
    csv = tmp / "ship.csv"
    run_simulate("ship-roll", csv, seed=7, duration=600.0, rate_hz=100.0)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    args = [sys.executable, "-c", "from imutool.cli import main; main()", "live", "--replay", str(csv), "--speed",
            "1", "--motion", "ship", "--settle", "5", "--http", f"127.0.0.1:{port}", "-q"]  # fmt: skip
    proc = subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    drivers = []
    try:
        _wait_valid(f"http://127.0.0.1:{port}/api/latest", 180.0)  # kernels compiled, filter settled
        time.sleep(2.0)
        c0, w0 = _cpu(proc.pid), time.monotonic()
        time.sleep(seconds)
        idle = (_cpu(proc.pid) - c0) / (time.monotonic() - w0)
        for i in range(browsers):
            d = _browser(tmp, i)
            d.get(f"http://127.0.0.1:{port}/")
            drivers.append(d)
        time.sleep(5.0)
        counts0 = [d.execute_script("return window.imutoolDisplay.messages") for d in drivers]
        c0, w0 = _cpu(proc.pid), time.monotonic()
        time.sleep(seconds)
        wall = time.monotonic() - w0
        busy = (_cpu(proc.pid) - c0) / wall
        counts1 = [d.execute_script("return window.imutoolDisplay.messages") for d in drivers]
        rates = [(b - a) / wall for a, b in zip(counts0, counts1, strict=True)]
    finally:
        for d in drivers:
            d.quit()
        proc.terminate()
        proc.wait(timeout=30)
        shutil.rmtree(tmp, ignore_errors=True)
    return {"browsers": browsers, "seconds": seconds, "cpu_no_browser": idle, "cpu_with_browsers": busy,
            "page_hz_min": min(rates), "page_hz_mean": sum(rates) / len(rates)}  # fmt: skip


def report(r: dict) -> str:
    """One line of figures."""
    return (
        f"bridge display, replay of a 100 Hz ship recording at real time: {r['browsers']} headless Chromium pages "
        f"update at {r['page_hz_mean']:.1f} Hz (slowest {r['page_hz_min']:.1f} Hz); the server's CPU "
        f"{100 * r['cpu_with_browsers']:.1f} % of one core with them, {100 * r['cpu_no_browser']:.1f} % without "
        f"(over {r['seconds']:g} s each; load average {os.getloadavg()[0]:.2f})"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--browsers", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=20.0)
    a = ap.parse_args()
    print(report(display(a.browsers, a.seconds)))


if __name__ == "__main__":
    main()
