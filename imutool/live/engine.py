"""The live loop: samples in, the inclinometer's outputs out, never waiting on an output.

For each block a source gives: calibration and mounting (as ``filter`` applies them), the saturation check, the
EKF step (:class:`imutool.attitude.EkfStepper`, the same object the streamed ``filter`` uses), real-time heave,
roll statistics and peak-hold, the status, the sentences due in the block (each at the row where it falls due, on
the input's clock), the hub's snapshots and the recording. Outputs take bytes through their own bounded queues.

Start-up: the first ``settle_s`` of samples are held while the motion model is decided on them (when it is
``auto``; given, only ``min_start_s`` are held to fix the sample interval), then the filter runs over them and on.
The status is V ("settling") until ``settle_s`` has passed and the filter's roll/pitch σ is within bounds.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from formats import Recording
from formats.frames import quat_to_matrix
from formats.saturation import FLOORS, clipped
from imutool.attitude import EkfParams, EkfStepper, mag_interval, nominal_dt
from imutool.attitude.motion import choose_motion, params_for_motion
from imutool.attitude.selfcheck import SampleFlag, has_flag

from .checks import LiveChecks
from .heave import LiveHeave
from .hub import LiveHub, LiveSnapshot
from .outputs import Output
from .record import Recorder
from .rollstats import LiveRoll
from .sentences import SentenceScheduler
from .sources import AuxNmea, SampleBlock, Source
from .status import LiveStatus

CLIP_TAIL = 8  # samples before a block taken into its saturation check (a range limit held 3 samples is a limit)
HUB_RATE_HZ = 10.0  # snapshots per second of input time handed to the hub
PEAK_SAVE_S = 10.0  # s of input between writes of the peak-hold state file


@dataclass
class EngineOptions:
    """What the engine needs besides its source and outputs (units: s, m, deg)."""

    params: EkfParams = field(default_factory=EkfParams)
    lever_arm: np.ndarray | None = None
    antenna_arm: np.ndarray | None = None
    settle_s: float = 60.0
    min_start_s: float = 1.0
    duration_s: float | None = None
    roll_window_s: float = 120.0
    heave: bool = True
    heave_settle_s: float = 120.0
    stale_s: float = 1.0
    rates: dict[str, float] = field(default_factory=lambda: {"HRM": 1.0})
    talker: str = "II"
    peak_state: str | None = None
    calibration: Any = None  # calibration.Calibration or None
    mount: Any = None  # formats.parse_mounting(...) result or None
    heading_ref: str = "magnetic"  # a magnetometer's heading; 'true' whenever a gyrocompass heading is the input
    utc_of: Callable[[float], float] | None = None  # input time (s) → UTC epoch (s); None: it is UTC already


class LiveEngine:
    """One run of ``imutool live`` over a source (see the module docstring)."""

    def __init__(
        self,
        source: Source,
        opts: EngineOptions,
        outputs: list[Output],
        hub: LiveHub,
        log: Callable[[str], None],
        aux: AuxNmea | None = None,
        recorder: Recorder | None = None,
    ) -> None:
        self.src, self.opts, self.outputs, self.hub, self.log = source, opts, outputs, hub, log
        self.aux, self.recorder = aux, recorder
        self.status = LiveStatus(opts.settle_s, log, stale_s=opts.stale_s)
        self.sched = SentenceScheduler(opts.rates, opts.talker)
        self.roll = LiveRoll(opts.roll_window_s, state_path=opts.peak_state)
        self.stepper: EkfStepper | None = None
        self.heave: LiveHeave | None = None
        self.checks: LiveChecks | None = None
        self.motion: Any = None
        self.held: list[SampleBlock] = []
        self.t_first: float | None = None
        self.t_last = -np.inf
        self.samples = 0
        self.out_of_order = 0
        self.saturated_samples = 0
        self.inconsistent_samples = 0
        self.resets: list[str] = []
        self._hub_next = -np.inf
        self._last_arrival = time.monotonic()
        self._tail_acc = np.empty((0, 3))
        self._tail_gyr = np.empty((0, 3))
        self._last_snap: LiveSnapshot | None = None
        self._pending: list[bytes] = []
        self._saved_at = -np.inf
        self.heading_known = False
        self.heading_ref = opts.heading_ref
        self._silent_base = 0.0
        self.stop_reason = ""

    # -------------------------------------------------------------------------------------------------- the loop
    def run(self, should_stop: Callable[[], str]) -> dict[str, Any]:
        """Run until ``should_stop()`` returns a reason, the source ends or the duration is reached."""
        while True:
            reason = should_stop()
            if reason:
                self.stop_reason = reason
                break
            for who, utc in self.hub.take_resets():
                self.reset_peak(who, utc)
            if self.aux is not None:
                self.aux.poll()
            blk = self.src.read(0.05)
            if blk is None or not len(blk):
                if self.src.finished:
                    self.stop_reason = "end of input"
                    break
                self._silence()
                continue
            self._last_arrival = time.monotonic()
            end = self.feed(blk)
            self._flush()
            if end:
                self.stop_reason = f"duration {self.opts.duration_s:g} s reached"
                break
        if self.held:  # a source that ended inside the start-up span: filter what was held
            self._start()
        self._flush()
        self.roll.save()
        return self.summary()

    def reset_peak(self, who: str, utc: float) -> None:
        """Reset the peak-hold (at host UTC ``utc`` s), log it and record it."""
        self.roll.reset(utc)
        self.resets.append(self.roll.reset_iso or "")
        self.log(f"peak-hold reset by {who} at {self.roll.reset_iso}")
        if self.recorder is not None:
            self.recorder.event("peak_hold_reset", by=who, utc=self.roll.reset_iso)

    def _silence(self) -> None:
        """No sample: after ``stale_s`` the status goes V and the sentences go on (V) on the host's clock."""
        quiet = time.monotonic() - self._last_arrival
        self.status.silence(quiet)
        if quiet <= self.opts.stale_s:
            return
        if self._last_snap is None:  # nothing ever arrived: V with empty values, on the host's clock
            nan = float("nan")
            self.status.update()
            now = time.time()
            self._last_snap = LiveSnapshot(now, now, nan, nan, None, self.heading_ref, None, None, None, None, None,
                                           self.roll.peak_port, self.roll.peak_stbd, self.roll.reset_iso, "V",
                                           self.status.cause, False)  # fmt: skip
            self._silent_base = now - quiet
        if not np.isfinite(self.t_last):
            t = self._silent_base + quiet
            names = self.sched.due(t)
            if names:
                s = replace(self._last_snap, utc=t, t=t, status="V", cause=self.status.cause)
                self._emit(self.sched.lines(s, names))
                self._flush()
                self.hub.publish(s)
            return
        self.status.update()
        t = self.t_last + quiet
        names = self.sched.due(t)
        if names:
            s = replace(self._last_snap, utc=self._utc(t), t=t, status="V", cause=self.status.cause)
            self._emit(self.sched.lines(s, names))
            self._flush()
            self.hub.publish(s)

    def feed(self, blk: SampleBlock) -> bool:
        """Take a block; True when the duration is reached."""
        keep = blk.t > np.maximum.accumulate(np.concatenate([[self.t_last], blk.t[:-1]]))
        if not keep.all():  # a time that does not increase (a replug, a clock step of the sensor): dropped
            self.out_of_order += int((~keep).sum())
            blk = _select(blk, keep)
            if not len(blk):
                return False
        end = False
        if self.t_first is None:
            self.t_first = float(blk.t[0])
        if self.opts.duration_s is not None and blk.t[-1] - self.t_first >= self.opts.duration_s:
            blk = _select(blk, blk.t - self.t_first < self.opts.duration_s)
            end = True
        if len(blk):
            self.t_last = float(blk.t[-1])
            if self.recorder is not None:  # the samples as they came, before calibration and mounting
                n = len(blk)
                mag = blk.mag if blk.mag is not None else np.full((n, 3), np.nan)
                self._recorded(self.recorder.write_raw(np.column_stack([blk.t, blk.gyro, blk.accel, mag])))
            blk = self._prepare(blk)
            if self.stepper is None:
                self.held.append(blk)
                span = self.t_last - float(self.held[0].t[0])
                need = self.opts.settle_s if self.opts.params.motion == "auto" else self.opts.min_start_s
                if span >= need:
                    self._start()
                else:
                    self._settling_output(blk)
            else:
                self._process(blk)
        return end

    # ----------------------------------------------------------------------------------------------- the steps
    def _prepare(self, blk: SampleBlock) -> SampleBlock:
        """Calibration and mounting, as ``filter`` applies them to a file."""
        if self.opts.calibration is None and self.opts.mount is None:
            return blk
        rec = Recording(blk.t, {"gyro": blk.gyro, "accel": blk.accel})
        rec.units.update(gyro="rad/s", accel="m/s^2")
        if blk.mag is not None:
            rec.add("mag", blk.mag, "uT")
        if self.opts.calibration is not None:
            rec = self.opts.calibration.apply(rec)
        if self.opts.mount is not None:
            rec = rec.mounted(*self.opts.mount)
        return SampleBlock(blk.t, rec["gyro"], rec["accel"], rec.channels.get("mag"), blk.extra)

    def _start(self) -> None:
        """Decide the motion model on the held samples, set the filter up once, and run it over them."""
        held = _concat(self.held)
        self.held = []
        params = self.opts.params
        self.motion = choose_motion(params, held.t, held.gyro)
        run_params = params_for_motion(params, self.motion)
        dt = nominal_dt(held.t)
        has_heading = "heading_true" in held.extra or (self.aux is not None)
        self.heading_known = bool(has_heading or (held.mag is not None and params.mag_mode != "off"))
        self.heading_ref = "true" if has_heading else self.opts.heading_ref
        self.stepper = EkfStepper(
            run_params,
            dt_nominal=dt,
            dt_mag=mag_interval(held.t, held.mag) if held.mag is not None and not has_heading else None,
            lever_arm=self.opts.lever_arm,
            antenna_arm=self.opts.antenna_arm,
            heading_held=bool(has_heading or held.mag is not None),
            keep_force=True,  # the gyro-scale check's input
        )
        self.checks = LiveChecks(dt, run_params.gap_factor, run_params.gravity)
        if self.opts.heave:
            self.heave = LiveHeave(1.0 / dt, settle_s=self.opts.heave_settle_s)
        how = f"decided on the first {held.t[-1] - held.t[0]:.0f} s" if params.motion == "auto" else "given"
        self.log(
            f"filter started: motion {self.motion.kind} ({how}), {1.0 / dt:.1f} Hz, settling {self.opts.settle_s:g} s"
        )
        self._process(held)

    def _inputs(self, blk: SampleBlock) -> tuple[Any, ...]:
        """(mag, sog, cog, heading_deg, vel) for the stepper from the block's own columns or the second port."""
        ex = dict(blk.extra)
        if self.aux is not None:
            n = len(blk)
            for k, v in self.aux.latest(time.monotonic()).items():
                ex[k] = np.full(n, v)
            for k in ("sog", "cog", "heading_true"):
                if k not in ex and k in self.aux.values:
                    ex[k] = np.full(n, np.nan)  # known source, value too old
        heading = ex.get("heading_true")
        sog, cog = ex.get("sog"), ex.get("cog")
        vel = None
        if sog is not None and cog is not None:
            c = np.radians(cog)
            vel = np.stack([sog * np.cos(c), sog * np.sin(c)], axis=1)
        elif "vel_n" in ex and "vel_e" in ex:
            vel = np.stack([ex["vel_n"], ex["vel_e"]], axis=1)
        return blk.mag, sog, cog, heading, vel

    def _process(self, blk: SampleBlock) -> None:
        assert self.stepper is not None
        n = len(blk)
        # saturation: the capture's rule on this block with the last samples before it (a flat top spans blocks)
        clip_a, clip_g = self._clipping(blk)
        accel = blk.accel
        if clip_a.any():
            accel = np.array(accel, dtype=np.float64)
            accel[clip_a] = np.nan
        mag, sog, cog, heading, vel = self._inputs(blk)
        res = self.stepper.step(blk.t, blk.gyro, accel, mag, sog, cog, heading_deg=heading, velocity_ne=vel)
        R = quat_to_matrix(res.q)
        roll, pitch, hdg = (np.degrees(a) for a in _euler_of_matrix(R))
        std = np.degrees(res.std)
        incons = has_flag(res.flags, SampleFlag.INCONSISTENT)
        # rate of turn: the bias-corrected body rate about the world vertical (deg/min, + clockwise seen from above)
        w_ned = np.einsum("nij,nj->ni", R, blk.gyro - res.bias)
        rot = np.degrees(w_ned[:, 2]) * 60.0
        heave = self.heave.add(blk.t, R, blk.accel) if self.heave is not None else None
        sat = _rows_any(clip_a) | _rows_any(clip_g)
        assert self.checks is not None
        self.checks.add(blk.t, blk.gyro, accel, res.bias, res.force)
        self.status.check_causes = self.checks.causes(float(blk.t[-1]))
        self.samples += n
        self.saturated_samples += int(sat.sum())
        self.inconsistent_samples += int(incons.sum())
        # the rows where something falls due: each segment up to such a row is taken before its output
        due_rows = self._due_rows(blk.t)
        start = 0
        for i, names in due_rows + [(n - 1, [])]:
            if i < start:
                continue
            seg = slice(start, i + 1)
            self.roll.add(blk.t[seg], roll[seg])
            tilt_std = float(max(std[i, 0], std[i, 1]))
            self.status.samples(float(blk.t[i]), bool(sat[seg].any()), bool(incons[seg].any()), tilt_std)
            status = self.status.update()
            start = i + 1
            if not names:
                continue
            if "HRM" in names:
                self.roll.refresh()  # a cycle completed in this block is in this HRM
                if blk.t[i] - self._saved_at >= PEAK_SAVE_S:  # the peak-hold survives a restart
                    self._saved_at = float(blk.t[i])
                    self.roll.save()
            snap = self._snapshot(
                float(blk.t[i]), roll[i], pitch[i], hdg[i], rot[i], None if heave is None else heave[i], status
            )
            sentences = [s for s in names if s != "_HUB"]
            if sentences:
                self._emit(self.sched.lines(snap, sentences, {"std_deg": (std[i, 0], std[i, 1], std[i, 2])}))
            if "_HUB" in names:
                self.hub.publish(snap)
            self._last_snap = snap
        if self.recorder is not None:
            self._record(blk, roll, pitch, hdg, std, heave)

    def _clipping(self, blk: SampleBlock) -> tuple[np.ndarray, np.ndarray]:
        """(accel, gyro) clipped masks of the block: capture's rule (:func:`formats.saturation.clipped`) on the
        block with the last samples before it (a flat top spans blocks); skipped while every value lies within the
        floors below which no sensor's range ends."""
        out = []
        for name, x, tail in (("accel", blk.accel, "_tail_acc"), ("gyro", blk.gyro, "_tail_gyr")):
            n = len(x)
            w = np.concatenate([getattr(self, tail), x])
            setattr(self, tail, w[-CLIP_TAIL:])
            if not (np.abs(w) >= FLOORS[name]).any():  # (NaN compares False: nanmax's answer, a tenth the cost)
                out.append(np.zeros(x.shape, bool))
            else:
                out.append(clipped(w, name).mask[-n:])
        return out[0], out[1]

    def _due_rows(self, t: np.ndarray) -> list[tuple[int, list[str]]]:
        """[(row, [names due at it])] in row order; '_HUB' for the hub's snapshots."""
        rows: dict[int, list[str]] = {}
        t_end = float(t[-1])
        for name, hz in list(self.sched.rates.items()) + [("_HUB", HUB_RATE_HZ)]:
            nxt = self.sched._next.get(name) if name != "_HUB" else self._hub_next
            while nxt is None or nxt - 1e-9 <= t_end:
                i = 0 if nxt is None else int(np.searchsorted(t, nxt - 1e-9, side="left"))
                i = min(i, len(t) - 1)
                rows.setdefault(i, []).append(name)
                period = 1.0 / hz
                nxt = nxt + period if nxt is not None and t[i] - nxt < period else float(t[i]) + period
            if name == "_HUB":
                self._hub_next = nxt
            else:
                self.sched._next[name] = nxt
        return sorted(rows.items())

    def _snapshot(
        self, t: float, roll: float, pitch: float, hdg: float, rot: float, heave: float | None, status: str
    ) -> LiveSnapshot:
        has_heading = self.heading_known
        heave_ok = self.heave is not None and self.heave.settled
        r = self.roll
        return LiveSnapshot(
            utc=self._utc(t),
            t=t,
            roll_deg=float(roll),
            pitch_deg=float(pitch),
            heading_deg=float(hdg) % 360.0 if has_heading else None,
            heading_ref=self.heading_ref,
            rot_deg_min=float(rot),
            heave_m=float(heave) if heave is not None and heave_ok else None,
            roll_amp_port_deg=r.amp_port,
            roll_amp_stbd_deg=r.amp_stbd,
            roll_period_s=r.period,
            peak_port_deg=r.peak_port,
            peak_stbd_deg=r.peak_stbd,
            peak_reset_utc=r.reset_iso,
            status=status,
            cause=self.status.cause,
            settled=self.status.settled,
        )

    def _utc(self, t: float) -> float:
        return self.opts.utc_of(t) if self.opts.utc_of is not None else t

    def _settling_output(self, blk: SampleBlock) -> None:
        """While the start-up span is held: V sentences with empty values, each at the row where it falls due."""
        nan = float("nan")
        for i, names in self._due_rows(blk.t):
            t = float(blk.t[i])
            self.status.samples(t, False, False, np.inf)
            status = self.status.update()
            snap = LiveSnapshot(self._utc(t), t, nan, nan, None, self.heading_ref, None, None, None, None, None,
                                self.roll.peak_port, self.roll.peak_stbd, self.roll.reset_iso, status,
                                self.status.cause, False)  # fmt: skip
            sentences = [s for s in names if s != "_HUB"]
            if sentences:
                self._emit(self.sched.lines(snap, sentences))
            if "_HUB" in names:
                self.hub.publish(snap)
        self.status.samples(float(blk.t[-1]), False, False, np.inf)

    def _emit(self, data: bytes) -> None:
        """Queue sentences; they go to the outputs at the end of the block (:meth:`_flush`), one hand-over each."""
        if data:
            self._pending.append(data)

    def _flush(self) -> None:
        if self._pending:
            data = b"".join(self._pending)
            self._pending.clear()
            for out in self.outputs:
                out.send(data)

    def _record(self, blk: SampleBlock, roll, pitch, hdg, std, heave) -> None:
        n = len(blk)
        status_a = 1.0 if self.status.status == "A" else 0.0
        hv = heave if heave is not None and self.heave is not None and self.heave.settled else np.full(n, np.nan)
        est = np.column_stack([blk.t, roll, pitch, hdg % 360.0, std[:, 0], std[:, 1], hv, np.full(n, status_a)])
        assert self.recorder is not None
        self._recorded(self.recorder.write_estimates(est))

    def _recorded(self, why: str | None) -> None:
        if why:
            self.log(f"recording stopped: {why} (the outputs go on)")

    def summary(self) -> dict[str, Any]:
        span = 0.0 if self.t_first is None else max(0.0, self.t_last - self.t_first)
        out: dict[str, Any] = {
            "stop_reason": self.stop_reason,
            "source": self.src.description,
            "samples": self.samples,
            "input_span_s": round(span, 3),
            "motion": None if self.motion is None else self.motion.summary(),
            "status": self.status.status,
            "status_changes": self.status.changes,
            "settled": self.status.settled,
            "sentences": dict(self.sched.counts),
            "outputs": [o.stats() for o in self.outputs],
            "saturated_samples": self.saturated_samples,
            "inconsistent_samples": self.inconsistent_samples,
            "out_of_order_samples": self.out_of_order,
            "source_stats": dict(self.src.stats),
            "peak_hold_resets": self.resets,
        }
        if self.checks is not None:
            out["self_checks"] = self.checks.summary()
        if self.stepper is not None:
            out["filter"] = {k: v for k, v in self.stepper.counters().items()}
        if self.recorder is not None:
            out["recording"] = {"rows": self.recorder.rows, "files": self.recorder.files,
                                "stopped": self.recorder.stopped}  # fmt: skip
        return out


def _euler_of_matrix(R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ZYX Euler angles (rad; heading in [0, 2π)) from the rotation matrices of :func:`quat_to_matrix`: the same
    products and sums as :func:`formats.frames.quat_to_euler` on the quaternions (bit for bit), without computing
    them twice."""
    roll = np.arctan2(R[:, 2, 1], R[:, 2, 2])
    pitch = np.arcsin(np.clip(-R[:, 2, 0], -1.0, 1.0))
    heading = np.mod(np.arctan2(R[:, 1, 0], R[:, 0, 0]), 2 * np.pi)
    return roll, pitch, heading


def _rows_any(mask: np.ndarray) -> np.ndarray:
    return mask.any(axis=1) if mask.ndim == 2 else mask


def _select(blk: SampleBlock, keep: np.ndarray) -> SampleBlock:
    return SampleBlock(blk.t[keep], blk.gyro[keep], blk.accel[keep], None if blk.mag is None else blk.mag[keep],
                       {k: v[keep] for k, v in blk.extra.items()})  # fmt: skip


def _concat(blocks: list[SampleBlock]) -> SampleBlock:
    if len(blocks) == 1:
        return blocks[0]
    mags = [b.mag for b in blocks]
    mag = None if any(m is None for m in mags) else np.concatenate(mags)
    keys = set.intersection(*(set(b.extra) for b in blocks))
    return SampleBlock(
        np.concatenate([b.t for b in blocks]),
        np.concatenate([b.gyro for b in blocks]),
        np.concatenate([b.accel for b in blocks]),
        mag,
        {k: np.concatenate([b.extra[k] for b in blocks]) for k in keys},
    )
