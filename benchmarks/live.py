"""`imutool live`: latency, CPU and memory (figures for the README; no asserts).

    python benchmarks/live.py                      # latency at 100 and 200 Hz, CPU at 100 Hz, a day replayed
    python benchmarks/live.py --seconds 60 --hours 24
    python benchmarks/live.py --only latency|memory|engine|display

Latency: bridge text frames of a rolling ship written one by one, paced at 100 / 200 Hz, into a pseudo-terminal
that `imutool live --clock sensor` reads; its XDR and PASHR (at the sample rate) read from another pseudo-terminal.
A PASHR's time stamp names its sample (the first PASHR is the first sample; the MCU clock is exact), so each
line's latency is its arrival minus the write of its sample. p50/p99 over the run after the start-up span.
CPU: the live process's user+system time over the steady part of the 100 Hz run, as a share of one core.
Engine: the engine alone in this process, one sample per block, XDR/PASHR at the sample rate to a null output:
CPU per block (``--only engine``; the live process's CPU less its port and output threads).
Memory: a day of samples at 100 Hz (a 10-minute ship recording tiled, times continued) through the engine as fast
as it goes, with HRM 1 Hz, XDR/PASHR 10 Hz to UDP and a hub subscriber; RSS at the first and the last hour.
"""

from __future__ import annotations

import argparse
import os
import resource
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from imutool.capture.bridge import Frame, Scales, encode_text  # noqa: E402
from imutool.capture.serve import open_pty  # noqa: E402
from imutool.sim import simulate  # noqa: E402


def _frames(rate: float, seconds: float) -> list[bytes]:
    rec = simulate("ship-roll", seed=3, duration=seconds, rate_hz=rate)
    sc = Scales()
    acc = np.clip(np.round(rec["accel"] / sc.accel), -32768, 32767).astype(int)
    gyr = np.clip(np.round(rec["gyro"] / sc.gyro), -32768, 32767).astype(int)
    mag = np.clip(np.round(rec["mag"] / sc.mag_ut), -32768, 32767).astype(int)
    t_us = np.round(rec.time * 1e6).astype(np.int64)
    return [encode_text(Frame(i & 0xFFFF, int(t_us[i]), (*acc[i], *gyr[i], *mag[i], 0))) for i in range(len(rec))]


def _cpu(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def latency(rate: float, seconds: float) -> dict:
    frames = _frames(rate, seconds)
    m_in, s_in, name_in = open_pty()
    m_out, s_out, name_out = open_pty()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    code = "import sys; from imutool.cli import main; sys.exit(main())"
    args = [name_in, "--clock", "sensor", "--motion", "ship", "--settle", "5", "--sentences", "XDR,PASHR",
            "--rate", f"XDR={rate:g}", "--rate", f"PASHR={rate:g}",
            "--out", f"serial://{name_out}?baud=921600"]  # fmt: skip
    proc = subprocess.Popen([sys.executable, "-c", code, "live", *args], env=env, stderr=subprocess.PIPE, text=True)
    while "reading " not in (proc.stderr.readline() or "reading "):
        pass
    arrivals: list[tuple[float, str]] = []
    stop = False

    def reader() -> None:
        buf = b""
        while not stop:
            r, _, _ = select.select([m_out], [], [], 0.1)
            if r:
                chunk = os.read(m_out, 65536)
                now = time.monotonic()
                buf += chunk
                *lines, buf = buf.split(b"\r\n")
                arrivals.extend((now, ln.decode()) for ln in lines)

    th = threading.Thread(target=reader, daemon=True)
    th.start()
    writes = np.empty(len(frames))
    t0 = time.monotonic()
    cpu0 = None
    for k, fr in enumerate(frames):
        due = t0 + k / rate
        while (d := due - time.monotonic()) > 0:
            time.sleep(d)
        os.write(m_in, fr)
        writes[k] = time.monotonic()
        if k == int(10 * rate):
            cpu0, w0 = _cpu(proc.pid), time.monotonic()
    cpu1, w1 = _cpu(proc.pid), time.monotonic()
    time.sleep(1.0)
    stop = True
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=30)
    pashr = [(a, ln) for a, ln in arrivals if ln.startswith("$PASHR")]
    tod = np.array([int(ln[7:9]) * 3600 + int(ln[9:11]) * 60 + float(ln[11:17]) for _, ln in pashr])
    k = np.round((tod - tod[0]) * rate).astype(int)
    arr = np.array([a for a, _ in pashr])
    ok = (k >= int(8 * rate)) & (k < len(frames))
    lat = (arr[ok] - writes[k[ok]]) * 1000.0
    for fd in (m_in, s_in, m_out, s_out):
        os.close(fd)
    out = {"rate_hz": rate, "lines": int(ok.sum()), "p50_ms": float(np.percentile(lat, 50)),
           "p99_ms": float(np.percentile(lat, 99)), "max_ms": float(lat.max())}  # fmt: skip
    if cpu0 is not None:
        out["cpu_share"] = (cpu1 - cpu0) / (w1 - w0)
    return out


class TiledSource:
    """A recording repeated with its times continued, handed out in blocks of ``block_s``, up to ``hours``."""

    def __init__(self, rec, hours: float, block_s: float = 1.0) -> None:
        self.t = np.asarray(rec.time, float)
        self.g, self.a, self.m = rec["gyro"], rec["accel"], rec["mag"]
        self.span = float(self.t[-1] - self.t[0] + (self.t[1] - self.t[0]))
        self.block = max(1, int(round(block_s / (self.t[1] - self.t[0]))))
        self.total = int(round(hours * 3600 / (self.t[1] - self.t[0])))
        self.i = 0
        self.finished, self.connected, self.stats, self.description = False, True, {}, "tiled"

    def read(self, timeout: float):
        from imutool.live.sources import SampleBlock

        if self.i >= self.total:
            self.finished = True
            return None
        n = len(self.t)
        j0 = self.i % n
        j1 = min(n, j0 + self.block)
        lap = self.i // n
        blk = SampleBlock(self.t[j0:j1] + lap * self.span, self.g[j0:j1], self.a[j0:j1], self.m[j0:j1])
        self.i += j1 - j0
        self.finished = self.i >= self.total
        return blk

    def close(self) -> None:
        pass


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def memory(hours: float, progress: bool = True) -> dict:
    from imutool.live import LiveHub
    from imutool.live.engine import EngineOptions, LiveEngine
    from imutool.live.outputs import open_output
    from imutool.live.route import warm_kernels

    rec = simulate("ship-roll", seed=3, duration=600.0, rate_hz=100.0)
    opts = EngineOptions(settle_s=30, rates={"HRM": 1.0, "XDR": 10.0, "PASHR": 10.0})
    opts.params = opts.params.__class__(motion="ship")
    warm_kernels(opts.params)
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    out = open_output(f"udp://127.0.0.1:{udp.getsockname()[1]}")
    hub = LiveHub()
    sub = hub.subscribe(64)
    src = TiledSource(rec, hours)
    eng = LiveEngine(src, opts, [out], hub, lambda m: None)
    marks: list[tuple[float, float, float]] = []
    t0 = time.monotonic()

    def stop() -> str:
        span = 0.0 if eng.t_first is None else eng.t_last - eng.t_first
        if not marks or span - marks[-1][0] >= 3600.0:
            marks.append((span, _rss_mb(), time.monotonic() - t0))
            if progress:
                print(f"  {span / 3600:.1f} h of input: RSS {marks[-1][1]:.1f} MB after {marks[-1][2]:.0f} s",
                      flush=True)  # fmt: skip
        while sub.get(0) is not None:
            pass
        try:
            while udp.recv(4096, socket.MSG_DONTWAIT):
                pass
        except BlockingIOError:
            pass
        return ""

    s = eng.run(stop)
    wall = time.monotonic() - t0
    out.close()
    marks.append((s["input_span_s"], _rss_mb(), wall))
    first = next((m for m in marks if m[0] >= 3600.0), marks[-1])
    return {"hours": hours, "samples": s["samples"], "wall_s": round(wall, 1),
            "rate_samples_per_s": round(s["samples"] / wall), "x_real_time": round(s["input_span_s"] / wall, 1),
            "rss_mb_at_1h": round(first[1], 1), "rss_mb_end": round(marks[-1][1], 1),
            "rss_growth_mb": round(marks[-1][1] - first[1], 1),
            "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)}  # fmt: skip


def engine_cpu(rate: float, seconds: float) -> dict:
    """The engine alone, in this process: a simulated ship fed one sample per block (as a serial IMU gives them),
    XDR and PASHR at the sample rate to an output that only counts; CPU per block after the first 10 s."""
    from imutool.attitude import EkfParams
    from imutool.live.engine import EngineOptions, LiveEngine
    from imutool.live.hub import LiveHub
    from imutool.live.sources import SampleBlock

    rec = simulate("ship-roll", seed=3, duration=seconds, rate_hz=rate)
    g, a, m = rec["gyro"], rec["accel"], rec["mag"]

    class Null:
        def send(self, data: bytes) -> None:
            pass

        def stats(self) -> dict:
            return {}

    opts = EngineOptions(params=EkfParams(motion="ship"), settle_s=5, rates={"XDR": rate, "PASHR": rate})
    eng = LiveEngine(TiledSource(rec, 1.0), opts, [Null()], LiveHub(), log=lambda m: None)  # type: ignore[list-item]
    n0 = int(10 * rate)
    c0 = 0.0
    for i in range(len(rec)):
        if i == n0:
            c0 = time.process_time()
        eng.feed(SampleBlock(rec.time[i : i + 1], g[i : i + 1], a[i : i + 1], m[i : i + 1]))
        eng._flush()
    cpu = time.process_time() - c0
    blocks = len(rec) - n0
    return {"rate_hz": rate, "us_per_block": 1e6 * cpu / blocks, "cpu_share": cpu / (blocks / rate)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0, help="latency run length (s)")
    ap.add_argument("--hours", type=float, default=24.0, help="the replayed span of the memory run (h)")
    ap.add_argument("--only", choices=["latency", "memory", "display", "engine"], default=None)
    a = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}")
    if a.only in (None, "latency"):
        for rate in (100.0, 200.0):
            r = latency(rate, a.seconds)
            cpu = f", CPU {100 * r['cpu_share']:.1f} % of one core" if "cpu_share" in r else ""
            print(f"latency at {rate:.0f} Hz: p50 {r['p50_ms']:.1f} ms, p99 {r['p99_ms']:.1f} ms, "
                  f"max {r['max_ms']:.1f} ms over {r['lines']} PASHR lines{cpu}")  # fmt: skip
    if a.only in (None, "engine"):
        for rate in (100.0, 200.0):
            r = engine_cpu(rate, 150.0)
            print(f"engine alone at {rate:.0f} Hz, one sample per block: {r['us_per_block']:.0f} us per block, "
                  f"{100 * r['cpu_share']:.1f} % of one core")  # fmt: skip
    if a.only in (None, "memory"):
        r = memory(a.hours)
        print(f"{a.hours:g} h at 100 Hz as fast as it goes: {r['samples']} samples in {r['wall_s']} s "
              f"({r['rate_samples_per_s']} samples/s, {r['x_real_time']}x real time); RSS {r['rss_mb_at_1h']} MB "
              f"after 1 h, {r['rss_mb_end']} MB at the end: growth {r['rss_growth_mb']} MB")  # fmt: skip
    if a.only in (None, "display"):  # the bridge page: its update rate and the server's CPU with 5 browsers
        from benchmarks.live_display import display, report

        print(report(display(5, 20.0)))


if __name__ == "__main__":
    main()
