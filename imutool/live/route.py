"""`run_live`: the one library route behind ``imutool live`` (and a Python user, and the tests).

    from imutool.live import run_live
    res = run_live(replay="sample_data/ship_imu.csv", speed=0, outputs=["udp://127.0.0.1:10110"],
                   sentences=["HRM", "XDR"], duration=300)
    res.summary["sentences"]

Start order: the kernels are compiled (or loaded from numba's cache) before the port is opened, then the
outputs, the recording and the hub's consumers are started, and the engine runs until the source ends, the
duration is reached, ``stop()`` gives a reason or SIGINT/SIGTERM arrive; SIGUSR1 resets the peak-hold. At the
end everything is flushed and closed and one summary line is logged.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import replace
from datetime import datetime, timezone
from typing import Any

import numpy as np

import formats
from formats.errors import ImutoolError
from imutool.attitude import EkfParams, EkfStepper
from imutool.attitude.params import params_from_options
from imutool.loading import load_recording
from imutool.routes import RouteResult

from .engine import EngineOptions, LiveEngine
from .hub import LiveHub
from .outputs import Output, open_output
from .record import Recorder
from .sentences import parse_rates
from .sources import AuxNmea, ReplaySource, SerialImu, i2c_source, modbus_source

LIVE_DEFAULTS: dict[str, Any] = {
    "speed": 1.0,
    "protocol": "bridge",
    "baud": 115200,
    "rate_hz": 100.0,
    "aux_baud": 4800,
    "sentences": ("HRM",),
    "talker": "II",
    "settle_s": 60.0,
    "rotate_s": 3600.0,
    "roll_window_s": 120.0,
}
"""The defaults of :func:`run_live` (and of the ``imutool live`` options and the TOML file's keys)."""

Consumer = Callable[[LiveHub], Any]
"""An extra reader of the hub started with the engine: ``start(hub) -> handle`` with ``handle.stop()``."""


def log_line(msg: str, stream: Any = None) -> None:
    """One log line on stderr with its UTC (ISO 8601, ms)."""
    now = datetime.now(timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")
    print(f"{now} imutool live: {msg}", file=stream or sys.stderr, flush=True)


def warm_kernels(params: EkfParams, protocol: str | None = None, record: bool = False) -> None:
    """Compile (or load from the cache) the kernels a live run calls — the EKF's, the roll statistics', the
    gyro-scale self-check's, the bridge decoder's and the CSV writer's — on a few synthetic rows, before any port
    is opened."""
    from formats.csv import format_array
    from imutool.gyro_check import GyroScaleCheck
    from imutool.roll import roll_cycles

    tr = np.arange(200) * 0.1
    roll_cycles(tr, 5.0 * np.sin(tr))
    if record:
        format_array(np.zeros((1, 3)))
    if protocol in ("bridge", "bridge-binary"):
        from imutool.capture.bridge import BridgeDecoder, Frame, encode_binary, encode_text

        frame = Frame(0, 0, (0, 0, 16384, 0, 0, 0, 0, 0, 0, 0))
        BridgeDecoder(binary=protocol == "bridge-binary").feed_arrays(
            (encode_binary if protocol == "bridge-binary" else encode_text)(frame)
        )
    n = 8
    t = np.arange(n) * 0.01
    acc = np.tile([0.0, 0.0, -9.81], (n, 1))
    mag = np.tile([20.0, 0.0, 40.0], (n, 1))
    EkfStepper(params, dt_nominal=0.01, keep_force=True).step(t, np.zeros((n, 3)), acc, mag)
    GyroScaleCheck().add(t, np.zeros((n, 3)), np.zeros((n, 3)), acc)
    EkfStepper(params, dt_nominal=0.01).step(t, np.zeros((n, 3)), acc, None, heading_deg=np.zeros(n))


def run_live(
    port: str | None = None,
    *,
    replay: str | os.PathLike | None = None,
    speed: float = LIVE_DEFAULTS["speed"],
    protocol: str = LIVE_DEFAULTS["protocol"],
    clock: str = "host",
    baud: int = LIVE_DEFAULTS["baud"],
    i2c: str | None = None,
    modbus_profile: str | None = None,
    rate_hz: float = LIVE_DEFAULTS["rate_hz"],
    aux: str | None = None,
    aux_baud: int = LIVE_DEFAULTS["aux_baud"],
    outputs: Iterable[str] = (),
    sentences: Iterable[str] | str = LIVE_DEFAULTS["sentences"],
    rates: dict[str, float] | list[str] | None = None,
    talker: str = LIVE_DEFAULTS["talker"],
    record: str | os.PathLike | None = None,
    rotate_s: float | None = LIVE_DEFAULTS["rotate_s"],
    duration: float | None = None,
    params: EkfParams | None = None,
    params_file: str | None = None,
    motion: str | None = None,
    settle_s: float = LIVE_DEFAULTS["settle_s"],
    lever_arm: Any = None,
    antenna_arm: Any = None,
    mounting: str | None = None,
    calibration_file: str | None = None,
    roll_window_s: float = LIVE_DEFAULTS["roll_window_s"],
    peak_state: str | None = None,
    consumers: Iterable[Consumer] = (),
    hub: LiveHub | None = None,
    stop: Callable[[], str] | None = None,
    log: Callable[[str], None] | None = None,
    opener: Callable | None = None,
    handle_signals: bool = True,
    replay_block_s: float = 0.25,
) -> RouteResult:
    """Read a live IMU (``port`` with ``protocol`` at ``baud``, times from the ``clock`` host|sensor; ``i2c``
    bus; ``port`` + ``modbus_profile``) or ``replay`` a recording at ``speed`` × real time (0: as fast as it
    goes), and keep writing the inclinometer's sentences to ``outputs`` (URLs, see :mod:`imutool.live.outputs`)
    until stopped or ``duration`` s of input.

    The estimator is ``filter``'s EKF (``params``/``params_file``, ``motion`` ship|handheld|auto — auto decided
    on the first ``settle_s`` — ``lever_arm``/``antenna_arm`` m body FRD, ``mounting``, ``calibration_file``);
    ``aux`` a second serial port with NMEA RMC/VTG (GNSS velocity) and HDT/THS (gyrocompass heading).
    ``sentences`` and ``rates`` ({name: Hz} or 'XDR=20' strings) choose what is sent; ``talker`` its talker ID.
    ``record`` a folder for the raw samples and estimates (rotating every ``rotate_s``); ``peak_state`` the file
    that keeps the peak-hold and its reset's UTC (default ``record/peak_hold.json`` when recording).
    ``replay_block_s``: the input time a replay at speed 0 hands over at once (s).
    ``consumers``: extra readers of the hub (``start(hub) -> handle`` with ``stop()``), e.g. a web page.
    """
    logf = log or log_line
    if replay is None and port is None and i2c is None:
        raise ImutoolError("give a source: a serial PORT, --i2c BUS or --replay FILE")
    if params is None:
        params, _notes = params_from_options(params_file)
    if motion is not None:
        if motion not in ("auto", "ship", "handheld"):
            raise ImutoolError(f"motion {motion!r}: expected auto, ship or handheld")
        params = replace(params, motion=motion)
    rate_table = parse_rates(list(sentences) if not isinstance(sentences, str) else sentences, rates)
    lever = _vector(lever_arm, "lever arm")
    antenna = _vector(antenna_arm, "antenna arm")
    cal = None
    if calibration_file:
        from calibration import load_calibration

        cal = load_calibration(calibration_file)
    mount = formats.parse_mounting(mounting) if mounting else None
    if lever is None and params.motion != "handheld":
        logf(
            "no lever arm given: none used (live does not estimate it, filter does from its first ten minutes; "
            "give --lever-arm for a sensor off the roll centre)"
        )

    t0 = time.monotonic()
    serial_protocol = protocol if port is not None and modbus_profile is None and replay is None else None
    warm_kernels(params, serial_protocol, record is not None)  # before the port is opened: no sample waits
    logf(f"kernels ready in {time.monotonic() - t0:.1f} s")

    utc_of = None
    if replay is not None:
        rec, _validation = load_recording(os.fspath(replay))
        source: Any = ReplaySource(
            rec, speed, block_s=replay_block_s, description=f"replay of {os.fspath(replay)} at {speed:g}x"
        )
        utc_of = _replay_clock(rec)
    elif i2c is not None:
        source = i2c_source(i2c, rate_hz)
    elif modbus_profile is not None:
        assert port is not None
        source = modbus_source(port, modbus_profile, rate_hz)
    else:
        assert port is not None
        source = SerialImu(port, baud, protocol, opener=opener, log=logf, clock=clock)
    aux_src = AuxNmea(aux, aux_baud, opener=opener) if aux else None

    outs: list[Output] = []
    recorder = None
    handles: list[Any] = []
    hub = hub or LiveHub()
    try:
        for url in outputs:
            outs.append(open_output(url))
        if record is not None:
            meta = {"source": source.description, **getattr(source, "meta", {}), "captured_by": "imutool live"}
            recorder = Recorder(record, meta, rotate_s)
            recorder.event("started", source=source.description, outputs=list(outputs))
            if peak_state is None:
                peak_state = os.path.join(os.fspath(record), "peak_hold.json")
        opts = EngineOptions(
            params=params, lever_arm=lever, antenna_arm=antenna, settle_s=settle_s, duration_s=duration,
            roll_window_s=roll_window_s, rates=rate_table, talker=talker, peak_state=peak_state,
            calibration=cal, mount=mount, utc_of=utc_of,
        )  # fmt: skip
        engine = LiveEngine(source, opts, outs, hub, logf, aux_src, recorder)
        for start in consumers:
            handles.append(start(hub))
        logf(
            f"reading {source.description}; sending {', '.join(f'{k} {v:g} Hz' for k, v in rate_table.items())} "
            f"to {', '.join(o.url for o in outs) or 'no output'}; status V while settling ({settle_s:g} s)"
        )
        stopper = _Stopper(stop, engine, handle_signals)
        try:
            summary = engine.run(stopper)
        finally:
            stopper.restore()
    finally:
        source.close()
        if aux_src is not None:
            aux_src.close()
        for o in outs:
            o.close()
        hub.close(getattr(locals().get("engine"), "stop_reason", "") or "stopped")
        for h in handles:
            try:
                h.stop()
            except Exception as e:  # a consumer's failure is logged, never fatal at the end
                logf(f"a hub consumer failed to stop: {e}")
    summary["outputs"] = [o.stats() for o in outs]
    if recorder is not None:
        recorder.event("stopped", reason=summary["stop_reason"], samples=summary["samples"])
        recorder.close({"samples": summary["samples"], "stop_reason": summary["stop_reason"]})
        summary["recording"] = {"rows": recorder.rows, "files": recorder.files, "stopped": recorder.stopped}
    logf(summary_line(summary))
    return RouteResult(summary)


def summary_line(s: dict[str, Any]) -> str:
    """The one line logged at the end."""
    sent = sum(s.get("sentences", {}).values())
    dropped = sum(o.get("dropped", 0) + o.get("client_dropped", 0) for o in s.get("outputs", []))
    rec = s.get("recording")
    rec_text = "" if not rec else f", recorded {rec['rows']} rows" + (" (stopped: disk)" if rec.get("stopped") else "")
    return (
        f"stopped ({s['stop_reason'] or 'stopped'}): {s['samples']} samples over {s['input_span_s']:.1f} s, "
        f"{sent} sentences sent, {dropped} dropped, status {s['status']} at the end, "
        f"{s['status_changes']} status changes{rec_text}"
    )


class _Stopper:
    """The engine's stop test: SIGINT/SIGTERM (reason = the signal), the caller's ``stop()``; SIGUSR1 resets."""

    def __init__(self, stop: Callable[[], str] | None, engine: LiveEngine, install: bool) -> None:
        self.stop, self.engine, self.reason = stop, engine, ""
        self._old: dict[int, Any] = {}
        if install and threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._on_stop)
            self._old[signal.SIGUSR1] = signal.signal(signal.SIGUSR1, self._on_reset)

    def _on_stop(self, signum: int, frame: Any) -> None:
        self.reason = signal.Signals(signum).name

    def _on_reset(self, signum: int, frame: Any) -> None:
        self.engine.hub.request_reset("SIGUSR1")

    def __call__(self) -> str:
        if self.reason:
            return self.reason
        return self.stop() if self.stop is not None else ""

    def restore(self) -> None:
        for sig, h in self._old.items():
            signal.signal(sig, h)


def _vector(v: Any, what: str) -> np.ndarray | None:
    if v is None:
        return None
    if isinstance(v, str):
        v = [float(x) for x in v.replace(" ", "").split(",") if x]
    a = np.asarray(v, dtype=float).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ImutoolError(f"{what} {v!r}: expected three finite numbers (m, body FRD)")
    return a


def _replay_clock(rec: Any) -> Callable[[float], float]:
    """Input time → UTC for a replay: the recording's own (Unix-second times, or ``utc_start``), else the time of
    the replay's start plus the input's elapsed time (a demo's sentences carry today's clock)."""
    t = np.asarray(rec.time, float)
    if len(t) and t[0] > 1e8:
        return lambda x: x
    start = rec.meta.get("utc_start")
    if start:
        try:
            base = datetime.fromisoformat(str(start).replace("Z", "+00:00")).timestamp()
            return lambda x: base + x
        except ValueError:
            pass
    base = time.time() - (float(t[0]) if len(t) else 0.0)
    return lambda x: base + x
