"""Roll events of a recording and of a fleet: heavy-roll episodes, hourly MSC.363 statistics, parametric roll.

Per recording (:func:`analyse`, :func:`run`), from the heel/roll angle (deg, + starboard down) and, for
parametric roll, the pitch (deg) or heave (m) that reveals the wave encounter period:

- **heavy-roll events**: |heel| ≥ ``threshold_deg``; crossings closer than ``merge_gap_s`` are one event, with
  start/end (s and UTC when known), duration, peak heel (signed, deg), side, number of crossings and the roll
  period (MSC.363(92) §3: time between successive maxima on the same side, median over the event's cycles).
- **hourly statistics**: per hour, the MSC.363(92) §3 quantities of :mod:`imutool.roll` (roll period per side,
  roll amplitude per side: mean and max), max heel to port/starboard, RMS heel, cycles, heavy-roll events begun.
- **parametric roll** (principal parametric resonance). Criterion implemented, after IMO MSC.1/Circ.1228 (roll
  period about twice the encounter period), the ABS *Guide for the Assessment of Parametric Roll Resonance in the
  Design of Container Carriers* (principal resonance at ωe ≈ 2ωφ) and the on-board detectors of Galeazzi, Blanke &
  Poulsen, *Early detection of parametric roll resonance on container ships*, IEEE TCST 21(2), 2013 (frequency
  coupling + phase synchronisation + growth). An episode is a run of roll half-cycles (:func:`imutool.roll.
  roll_cycles`) where, at the same time,

  1. *frequency condition*: |Tφ / (2·Te) − 1| ≤ ``tuning_tol`` (default 0.15) for ≥ 75 % of the cycles, Tφ the
     roll period (same-side maxima, median of the last three) and Te the dominant period of pitch (else heave)
     in a ``window_s`` window around each cycle;
  2. *growth*: the amplitude does not fall (by more than ``slack``) from one half-cycle to the next; from the
     smallest half-cycle of such a run to the first one within 5 % of its largest (the growth) there are at least
     ``min_cycles`` half-cycles and the amplitude grows by ≥ ``min_growth`` × to ≥ ``min_amplitude_deg``;
  3. *phase lock*: roll at ωe/2 is synchronised to pitch: the phase-locking value |⟨exp i(2φ_roll − φ_pitch)⟩|
     of the band-passed analytic signals over the fitted growth (below) is ≥ ``min_lock`` (default 0.7; ≈ 0.1–0.4
     for the independent responses of a linear irregular sea).

  Onset = the time where the exponential growth fitted (log-linear least squares) to the half-cycle amplitudes
  between max(1.5 × the smallest, 0.1 × the largest) and 0.5 × the largest leaves the background amplitude (median
  of the half-cycles from the smallest to the first fitted one); growth rate σ (1/s) is the fitted slope. The
  frequency condition (≥ 75 % of the cycles) and the phase lock are checked over the fitted growth.

Fleet (:func:`fleet_table`, :func:`fleet_plot`): one row per event across recordings with ship and voyage (from
metadata ``ship``/``vessel``/``voyage``, options, or the file path) and a plot of events per ship per month and
the worst roll per voyage.
"""

from __future__ import annotations

import csv
import json
import os
import re
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import numpy as np

from formats import Recording
from formats.atomic import atomic_path
from formats.errors import ImutoolError
from imutool.batch import expand_inputs
from imutool.loading import LOAD_OPTIONS, one_clock
from imutool.roll import heel_of, roll_cycles
from imutool.routes import OnInput, RouteResult, load_input

DEFAULTS: dict[str, Any] = {
    "threshold_deg": 20.0,
    "merge_gap_s": 60.0,
    "hysteresis_deg": 0.5,
    "hour_s": 3600.0,
    "tuning_tol": 0.15,
    "min_cycles": 6,
    "min_growth": 2.0,
    "min_amplitude_deg": 5.0,
    "slack": 0.15,
    "min_lock": 0.7,
    "window_s": 120.0,
}
_FS = 4.0  # Hz, resampling rate for wave-period analysis (wave motions are below 0.5 Hz)


# -- time ---------------------------------------------------------------------------------------------------
def utc_start_of(rec: Recording, override: str | None = None) -> datetime | None:
    """UTC of time 0: ``override`` (ISO 8601), metadata ``utc_start``/``start_utc``, or None (Unix-epoch times
    are recognised per sample by :func:`utc`)."""
    text = override or rec.meta.get("utc_start") or rec.meta.get("start_utc")
    if not text:
        return None
    try:
        d = datetime.fromisoformat(str(text).replace("Z", "+00:00"))
    except ValueError:
        raise ImutoolError(f"UTC start {text!r} is not ISO 8601 (e.g. 2024-01-31T12:00:00Z)") from None
    return d if d.tzinfo else d.replace(tzinfo=timezone.utc)


def utc(t: float, start: datetime | None) -> str | None:
    """ISO UTC of recording time t (s): start + t, or t itself when it looks like Unix time (> 1e9 s)."""
    if start is not None:
        return (start + timedelta(seconds=float(t))).strftime("%Y-%m-%dT%H:%M:%SZ")
    if t > 1e9:
        return datetime.fromtimestamp(float(t), tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    return None


# -- signal helpers -------------------------------------------------------------------------------------------
def _resample(t: np.ndarray, x: np.ndarray, fs: float = _FS) -> tuple[np.ndarray, np.ndarray]:
    ok = np.isfinite(x)
    if ok.sum() < 2:
        return np.zeros(0), np.zeros(0)
    tu = np.arange(t[ok][0], t[ok][-1], 1.0 / fs)
    return tu, np.interp(tu, t[ok], x[ok])


def dominant_period(x: np.ndarray, fs: float, min_s: float = 3.0, max_s: float = 40.0) -> float:
    """Period (s) of the largest peak of the Hann-windowed periodogram of x (mean removed, 8× zero padding)
    between min_s and max_s; NaN when the window is too short."""
    x = np.asarray(x, float)
    if x.size < fs * min_s * 2:
        return float("nan")
    x = (x - x.mean()) * np.hanning(x.size)
    nfft = 1 << int(np.ceil(np.log2(x.size * 8)))
    p = np.abs(np.fft.rfft(x, nfft)) ** 2
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    band = (f >= 1.0 / max_s) & (f <= 1.0 / min_s)
    if not band.any() or not np.any(p[band] > 0):
        return float("nan")
    return float(1.0 / f[band][np.argmax(p[band])])


def _phase_lock(
    tu: np.ndarray, roll: np.ndarray, pitch: np.ndarray, t0: float, t1: float, t_roll: float, t_enc: float
) -> float:
    """|mean exp(i(2·phase(roll) − phase(pitch)))| over [t0, t1], each band-passed ±30 % around its period."""
    from scipy.signal import butter, hilbert, sosfiltfilt

    def band(x: np.ndarray, period: float) -> np.ndarray:
        f0 = 1.0 / period
        lo, hi = 0.7 * f0, min(1.3 * f0, 0.45 * _FS)
        sos = butter(2, [lo, hi], btype="band", fs=_FS, output="sos")
        return sosfiltfilt(sos, x - x.mean())

    if tu.size < 64 or not (np.isfinite(t_roll) and np.isfinite(t_enc)):
        return float("nan")
    ar, ap = hilbert(band(roll, t_roll)), hilbert(band(pitch, t_enc))
    m = (tu >= t0) & (tu <= t1)
    if m.sum() < 8:
        return float("nan")
    psi = 2 * np.angle(ar[m]) - np.angle(ap[m])
    return float(np.abs(np.mean(np.exp(1j * psi))))


# -- heavy roll -----------------------------------------------------------------------------------------------
def heavy_roll_events(
    t: np.ndarray,
    heel: np.ndarray,
    cycles: Any,
    threshold_deg: float = 20.0,
    merge_gap_s: float = 60.0,
    start: datetime | None = None,
) -> list[dict[str, Any]]:
    """Episodes of |heel| ≥ threshold_deg (crossings < merge_gap_s apart merged), in time order."""
    t = np.asarray(t, float)
    x = np.asarray(heel, float)
    over = np.abs(np.where(np.isfinite(x), x, 0.0)) >= threshold_deg
    if not over.any():
        return []
    d = np.diff(np.concatenate([[False], over, [False]]).astype(np.int8))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1  # inclusive sample indices
    groups: list[list[int]] = [[0]]
    for k in range(1, starts.size):
        if t[starts[k]] - t[ends[k - 1]] < merge_gap_s:
            groups[-1].append(k)
        else:
            groups.append([k])
    out = []
    for g in groups:
        i0, i1 = int(starts[g[0]]), int(ends[g[-1]])
        seg = x[i0 : i1 + 1]
        ip = i0 + int(np.nanargmax(np.abs(seg)))
        t0, t1 = float(t[i0]), float(t[i1])
        m = (cycles.t_peak >= t0 - merge_gap_s / 2) & (cycles.t_peak <= t1 + merge_gap_s / 2)
        per = cycles.period_s[m]
        per = per[np.isfinite(per)]
        out.append(
            {
                "type": "heavy_roll",
                "t_start": t0,
                "t_end": t1,
                "duration_s": t1 - t0,
                "t_peak": float(t[ip]),
                "peak_deg": float(x[ip]),
                "side": "starboard" if x[ip] > 0 else "port",
                "crossings": len(g),
                "period_s": float(np.median(per)) if per.size else None,
                "utc_start": utc(t0, start),
                "threshold_deg": threshold_deg,
            }
        )
    return out


# -- hourly statistics ------------------------------------------------------------------------------------------
def hourly_statistics(
    t: np.ndarray,
    heel: np.ndarray,
    cycles: Any,
    events: list[dict[str, Any]],
    hour_s: float = 3600.0,
    start: datetime | None = None,
) -> list[dict[str, Any]]:
    """Per ``hour_s`` bin (aligned to the UTC hour when absolute time is known): MSC.363(92) §3 roll period and
    amplitude per side (mean, max), max heel per side, RMS heel, cycles, heavy-roll events begun in the bin."""
    t = np.asarray(t, float)
    x = np.asarray(heel, float)
    if t.size == 0:
        return []
    if start is not None:
        off = start.timestamp()
        base = np.floor((t[0] + off) / hour_s) * hour_s - off
    elif t[0] > 1e9:
        base = np.floor(t[0] / hour_s) * hour_s
    else:
        base = float(t[0])
    nb = int(np.floor((t[-1] - base) / hour_s)) + 1
    bins = np.clip(((t - base) // hour_s).astype(np.int64), 0, nb - 1)
    cbin = np.clip(((cycles.t_peak - base) // hour_s).astype(np.int64), 0, nb - 1) if len(cycles) else np.zeros(0, int)
    ev_t = np.array([e["t_start"] for e in events])
    out = []
    edges = np.searchsorted(bins, np.arange(nb + 1))
    for b in range(nb):
        a, z = int(edges[b]), int(edges[b + 1])
        if z <= a:
            continue
        xs = x[a:z]
        fin = xs[np.isfinite(xs)]
        row: dict[str, Any] = {
            "t_start": float(base + b * hour_s),
            "utc_start": utc(base + b * hour_s, start),
            "samples": int(z - a),
            "max_heel_stbd_deg": float(max(fin.max(), 0.0)) if fin.size else None,
            "max_heel_port_deg": float(max(-fin.min(), 0.0)) if fin.size else None,
            "rms_heel_deg": float(np.sqrt(np.mean(fin**2))) if fin.size else None,
        }
        sel = cbin == b
        row["cycles"] = int(sel.sum())
        for name, s in (("port", -1), ("stbd", 1)):
            m = sel & (cycles.side == s)
            per = cycles.period_s[m]
            per = per[np.isfinite(per)]
            amp = cycles.amplitude_deg[m]
            row[f"period_{name}_mean_s"] = float(per.mean()) if per.size else None
            row[f"amplitude_{name}_mean_deg"] = float(amp.mean()) if amp.size else None
            row[f"amplitude_{name}_max_deg"] = float(amp.max()) if amp.size else None
        lo, hi = base + b * hour_s, base + (b + 1) * hour_s
        row["heavy_roll_events"] = int(((ev_t >= lo) & (ev_t < hi)).sum()) if ev_t.size else 0
        out.append(row)
    return out


# -- parametric roll ---------------------------------------------------------------------------------------------
def parametric_roll(
    t: np.ndarray,
    heel: np.ndarray,
    wave: np.ndarray,
    cycles: Any,
    settings: dict[str, Any] | None = None,
    start: datetime | None = None,
) -> list[dict[str, Any]]:
    """Parametric-roll episodes (module docstring: frequency condition, growth, phase lock; onset by fit).

    t s; heel deg (+ starboard); wave: pitch (deg) or heave (m) at the encounter period; cycles from
    :func:`imutool.roll.roll_cycles` on the same heel.
    """
    s = {**DEFAULTS, **(settings or {})}
    t = np.asarray(t, float)
    n = len(cycles)
    if n < s["min_cycles"]:
        return []
    tu, ru = _resample(t, np.asarray(heel, float))
    tw, wu = _resample(t, np.asarray(wave, float))
    if tu.size < 16 or tw.size < 16:
        return []
    wu = np.interp(tu, tw, wu)
    tp, amp = cycles.t_peak, cycles.amplitude_deg
    # roll period at each half-cycle: median of the last three same-side periods
    per = cycles.period_s
    troll = np.full(n, np.nan)
    for k in range(n):
        p = per[max(0, k - 3) : k + 1]
        p = p[np.isfinite(p)]
        if p.size:
            troll[k] = np.median(p)
    half = s["window_s"] / 2
    te = np.full(n, np.nan)
    for k in range(n):
        m = (tu >= tp[k] - half) & (tu <= tp[k] + half)
        te[k] = dominant_period(wu[m], _FS)
    with np.errstate(invalid="ignore"):
        tuned = np.abs(troll / (2 * te) - 1) <= s["tuning_tol"]
    grow = np.zeros(n, bool)
    grow[1:] = amp[1:] >= amp[:-1] * (1 - s["slack"])
    episodes = []
    k = 0
    while k < n - 1:
        if not grow[k + 1]:
            k += 1
            continue
        i = k
        j = k + 1
        while j + 1 < n and grow[j + 1]:
            j += 1
        k = j
        top = float(amp[i : j + 1].max())
        m_ = i + int(np.flatnonzero(amp[i : j + 1] >= 0.95 * top)[0])  # growth ends on reaching the plateau
        i = i + int(np.argmin(amp[i : m_ + 1]))  # and begins at the smallest half-cycle before it
        if m_ - i + 1 < s["min_cycles"] or amp[m_] < s["min_amplitude_deg"] or amp[m_] < s["min_growth"] * amp[i]:
            continue
        lo, hi = max(1.5 * amp[i], 0.1 * top), 0.5 * top  # below half the plateau: saturation barely slows it
        fit = [q for q in range(i, m_ + 1) if lo <= amp[q] <= hi]
        if len(fit) < 3:
            fit = list(range(i, m_ + 1))
        f0 = fit[0]
        if np.mean(tuned[f0 : m_ + 1]) < 0.75:
            continue
        t_roll = float(np.nanmedian(troll[f0 : m_ + 1]))
        t_enc = float(np.nanmedian(te[f0 : m_ + 1]))
        lock = _phase_lock(tu, ru, wu, float(tp[f0]), float(tp[m_]), t_roll, t_enc)
        if not (lock >= s["min_lock"]):
            continue
        bg = float(np.median(amp[i:f0])) if f0 > i else float(amp[i])
        slope, icpt = np.polyfit(tp[fit], np.log(amp[fit]), 1)
        onset = (np.log(bg) - icpt) / slope if slope > 0 else float(tp[i])
        onset = float(np.clip(onset, tp[i] - t_roll, tp[f0]))
        e = m_
        while e + 1 < n and amp[e + 1] >= 0.5 * amp[m_]:
            e += 1
        pk = int(np.argmax(amp[i : e + 1])) + i
        episodes.append(
            {
                "type": "parametric_roll",
                "t_onset": onset,
                "t_start": onset,
                "t_end": float(cycles.t_end[e]),
                "duration_s": float(cycles.t_end[e] - onset),
                "t_peak": float(tp[pk]),
                "peak_deg": float(cycles.peak_deg[pk]),
                "side": "starboard" if cycles.peak_deg[pk] > 0 else "port",
                "period_s": t_roll,
                "encounter_period_s": t_enc,
                "period_ratio": t_roll / t_enc,
                "growth_rate_per_s": float(slope),
                "background_deg": bg,
                "phase_lock": lock,
                "cycles": int(e - i + 1),
                "utc_start": utc(onset, start),
            }
        )
    return episodes


# -- one recording ------------------------------------------------------------------------------------------------
def _channel(rec: Recording, name: str, unit: str) -> np.ndarray:
    return np.asarray(rec.in_unit(name, unit), float)


def identify(
    rec: Recording, path: str | None, ship: str | None = None, voyage: str | None = None, path_regex: str | None = None
) -> tuple[str, str]:
    """(ship, voyage): options, else metadata (ship/vessel/ship_name, voyage), else ``path_regex`` named groups
    ``ship``/``voyage`` on the path, else the parent folder's name and the file's stem."""
    groups: dict[str, str] = {}
    if path_regex and path:
        m = re.search(path_regex, os.fspath(path))
        if m:
            groups = {k: v for k, v in m.groupdict().items() if v}
    meta = rec.meta
    p = Path(path) if path else None
    ship = (
        ship
        or next((str(meta[k]) for k in ("ship", "vessel", "ship_name") if meta.get(k)), None)
        or groups.get("ship")
        or (p.parent.name if p is not None and p.parent.name else "unknown")
    )
    voyage = (
        voyage
        or (str(meta["voyage"]) if meta.get("voyage") else None)
        or groups.get("voyage")
        or (p.stem if p is not None else "unknown")
    )
    return ship, voyage


def analyse(
    rec: Recording,
    *,
    path: str | None = None,
    roll_channel: str | None = None,
    pitch_channel: str | None = None,
    heave_channel: str | None = None,
    utc_start: str | None = None,
    ship: str | None = None,
    voyage: str | None = None,
    path_regex: str | None = None,
    **settings: Any,
) -> dict[str, Any]:
    """Events, hourly statistics and parametric-roll episodes of one recording (a JSON-ready dict).

    roll_channel: heel/roll (deg) — default ``heel`` or ``roll``; pitch_channel (deg) default ``pitch``,
    heave_channel (m) default ``heave``: the first present gives the encounter period. settings: see DEFAULTS.
    """
    unknown = set(settings) - set(DEFAULTS)
    if unknown:
        raise ImutoolError(f"events: unknown setting(s) {', '.join(sorted(unknown))}")
    s = {**DEFAULTS, **settings}
    src = path or str(rec.meta.get("source", "recording"))
    rec = one_clock(rec, (roll_channel,) if roll_channel else ("heel", "roll"))  # many clocks: the heel's samples
    heel = heel_of(rec, src, roll_channel)
    start = utc_start_of(rec, utc_start)
    cyc = roll_cycles(rec.time, heel, hysteresis_deg=s["hysteresis_deg"])
    events = heavy_roll_events(rec.time, heel, cyc, s["threshold_deg"], s["merge_gap_s"], start)
    hourly = hourly_statistics(rec.time, heel, cyc, events, s["hour_s"], start)
    wave_name = None
    for name, unit in ((pitch_channel or "pitch", "deg"), (heave_channel or "heave", "m")):
        if name in rec.channels and rec[name].ndim == 1:
            wave_name, wave = name, _channel(rec, name, unit)
            break
    else:
        for asked in (pitch_channel, heave_channel):
            if asked:
                raise ImutoolError(f"no channel {asked!r}; has {', '.join(rec.channels)}", path=src)
    notes = [rec.meta["clock"]["note"]] if "clock" in rec.meta else []
    if wave_name is None:
        notes.append("no pitch or heave channel: parametric roll not assessed")
        para: list[dict[str, Any]] = []
    else:
        para = parametric_roll(rec.time, heel, wave, cyc, s, start)
    ship_, voyage_ = identify(rec, path, ship, voyage, path_regex)
    ip = int(np.nanargmax(np.abs(heel))) if np.isfinite(heel).any() else None
    summary = {
        "rows": len(rec),
        "duration_s": rec.duration,
        "cycles": len(cyc),
        "max_heel_deg": float(heel[ip]) if ip is not None else None,
        "max_heel_t": float(rec.time[ip]) if ip is not None else None,
        "max_heel_utc": utc(float(rec.time[ip]), start) if ip is not None else None,
        "heavy_roll_events": len(events),
        "parametric_roll_episodes": len(para),
        "first_parametric_onset_s": para[0]["t_onset"] if para else None,
    }
    return {
        "format": "imutool-events",
        "version": 1,
        "source": src,
        "ship": ship_,
        "voyage": voyage_,
        "utc_start": utc(float(rec.time[0]), start) if len(rec) else None,
        "t_start": float(rec.time[0]),
        "roll_channel": roll_channel or ("heel" if "heel" in rec.channels else "roll"),
        "wave_channel": wave_name,
        "settings": s,
        "summary": summary,
        "events": events + para,
        "hourly": hourly,
        "notes": notes,
    }


def write_table(rows: list[dict[str, Any]], path: str) -> None:
    """Rows (dicts) as CSV, columns in order of first appearance, None as an empty field (atomic)."""
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=cols or ["none"])
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if v is None else v) for k, v in r.items()})


def run(
    path: str,
    output: str | None = None,
    *,
    events_csv: str | None = None,
    hourly_csv: str | None = None,
    inputs: list[dict[str, Any]] | None = None,
    strict: bool = False,
    on_input: OnInput | None = None,
    **options: Any,
) -> dict[str, Any]:
    """Read ``path``, :func:`analyse` it and write the JSON result to ``output`` (and the tables as CSV);
    returns the result. The same route for the CLI, ``imutool batch`` and Python users. ``options``: those of
    :func:`analyse`, and the loading options every command takes (:data:`imutool.loading.LOAD_OPTIONS`:
    ``columns``, ``profile``, ``time_column``, ``with_files`` ...; the file is loaded by
    :func:`imutool.loading.load_recording`, rows out of time order sorted unless ``backwards`` says otherwise;
    ``inputs`` collects its loading report, ``strict`` makes its warnings errors, ``on_input(path, report)``)."""
    for out in (output, events_csv, hourly_csv):
        if out and os.path.abspath(out) == os.path.abspath(path):
            raise ImutoolError("output would overwrite the input", path=out)
    load = {k: options.pop(k) for k in list(options) if k in LOAD_OPTIONS}
    load = {k: v for k, v in load.items() if v is not None}
    load.setdefault("backwards", "sort")
    load.setdefault("duplicates", "drop")
    rec, _ = load_input(path, inputs if inputs is not None else [], strict=strict, on_input=on_input, **load)
    res = analyse(rec, path=path, **options)
    if output:
        with atomic_path(output) as tmp:
            tmp.write_text(json.dumps(res, indent=1, default=_json_default), encoding="utf-8")
    if events_csv:
        write_table(res["events"], events_csv)
    if hourly_csv:
        write_table(res["hourly"], hourly_csv)
    return res


def run_events(
    path: str | os.PathLike,
    output: str | os.PathLike | None = None,
    *,
    events_csv: str | os.PathLike | None = None,
    hourly_csv: str | os.PathLike | None = None,
    strict: bool = False,
    on_input: OnInput | None = None,
    **options: Any,
) -> RouteResult:
    """:func:`run` as a command route: the route behind ``imutool events detect`` and ``imutool batch 'events
    detect'``. ``options`` as :func:`analyse` (channels, ship/voyage, utc_start, path_regex, :data:`DEFAULTS`) and
    the loading options (:data:`imutool.loading.LOAD_OPTIONS`). Returns the summary (input, output, ship, voyage,
    rows, max heel, event counts...), the input's loading report and the whole result (``data``: events, hourly
    rows, notes, settings)."""
    path = os.fspath(path)
    inputs: list[dict[str, Any]] = []
    res = run(
        path,
        None if output is None else os.fspath(output),
        events_csv=None if events_csv is None else os.fspath(events_csv),
        hourly_csv=None if hourly_csv is None else os.fspath(hourly_csv),
        inputs=inputs,
        strict=strict,
        on_input=on_input,
        **options,
    )
    summary = {
        "input": path,
        "output": None if output is None else os.fspath(output),
        "ship": res["ship"],
        "voyage": res["voyage"],
        **res["summary"],
    }
    return RouteResult(summary, inputs, data=res)


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    return str(o)


# -- fleet ------------------------------------------------------------------------------------------------------
def load_results(paths: list[str]) -> list[dict[str, Any]]:
    """Per-recording results (JSON written by :func:`run`)."""
    out = []
    for p in paths:
        try:
            d = json.loads(Path(p).read_text(encoding="utf-8"))
        except (OSError, ValueError) as e:
            raise ImutoolError(f"not an events result: {e}", path=p) from None
        if d.get("format") != "imutool-events":
            raise ImutoolError("not an imutool events result (run 'imutool events detect' first)", path=p)
        out.append(d)
    return out


def fleet_table(results: list[dict[str, Any]]) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(one row per event across the fleet, one row per voyage: recordings, hours, worst roll, event counts)."""
    rows = []
    voyages: dict[tuple[str, str], dict[str, Any]] = {}
    for r in results:
        key = (r["ship"], r["voyage"])
        v = voyages.setdefault(
            key,
            {
                "ship": r["ship"],
                "voyage": r["voyage"],
                "recordings": 0,
                "hours": 0.0,
                "worst_roll_deg": None,
                "worst_roll_utc": None,
                "heavy_roll_events": 0,
                "parametric_roll_episodes": 0,
                "first_utc": r.get("utc_start"),
            },
        )
        v["recordings"] += 1
        v["hours"] += (r["summary"].get("duration_s") or 0.0) / 3600.0
        mx = r["summary"].get("max_heel_deg")
        if mx is not None and (v["worst_roll_deg"] is None or abs(mx) > abs(v["worst_roll_deg"])):
            v["worst_roll_deg"] = mx
            v["worst_roll_utc"] = r["summary"].get("max_heel_utc")
        for e in r["events"]:
            v["heavy_roll_events" if e["type"] == "heavy_roll" else "parametric_roll_episodes"] += 1
            month = (e.get("utc_start") or r.get("utc_start") or "")[:7] or "unknown"
            rows.append(
                {
                    "ship": r["ship"],
                    "voyage": r["voyage"],
                    "source": r["source"],
                    "month": month,
                    "type": e["type"],
                    "utc_start": e.get("utc_start"),
                    "t_start": e["t_start"],
                    "duration_s": e["duration_s"],
                    "peak_deg": e["peak_deg"],
                    "side": e["side"],
                    "period_s": e.get("period_s"),
                    "encounter_period_s": e.get("encounter_period_s"),
                    "growth_rate_per_s": e.get("growth_rate_per_s"),
                }
            )
    rows.sort(key=lambda x: (x["ship"], x["voyage"], x["t_start"]))
    vs = sorted(voyages.values(), key=lambda x: (x["ship"], x["voyage"]))
    for v in vs:
        v["hours"] = round(v["hours"], 4)
    return rows, vs


def fleet_plot(rows: list[dict[str, Any]], voyages: list[dict[str, Any]], path: str) -> None:
    """Two panels: events per ship per month (grouped bars; parametric roll hatched) and worst roll per voyage."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ships = sorted({v["ship"] for v in voyages})
    months = sorted({r["month"] for r in rows}) or ["none"]
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(max(7.0, 0.6 * len(voyages) + 3), 7.5), constrained_layout=True)
    width = 0.8 / max(1, len(ships))
    x = np.arange(len(months))
    for k, ship in enumerate(ships):
        for typ, hatch in (("heavy_roll", None), ("parametric_roll", "//")):
            cnt = [sum(1 for r in rows if r["ship"] == ship and r["month"] == m and r["type"] == typ) for m in months]
            bottom = (
                None
                if typ == "heavy_roll"
                else [
                    sum(1 for r in rows if r["ship"] == ship and r["month"] == m and r["type"] == "heavy_roll")
                    for m in months
                ]
            )
            a1.bar(
                x + k * width,
                cnt,
                width,
                bottom=bottom,
                color=f"C{k}",
                hatch=hatch,
                edgecolor="black" if hatch else None,
                linewidth=0.5,
                label=f"{ship}" + (" (parametric roll)" if hatch else ""),
            )
    a1.set_xticks(x + width * (len(ships) - 1) / 2, months)
    a1.set_ylabel("events")
    a1.set_title("Heavy-roll events and parametric-roll episodes per ship per month (UTC)")
    a1.legend(fontsize=8, ncols=2)
    labels = [f"{v['ship']}\n{v['voyage']}" for v in voyages]
    worst = [abs(v["worst_roll_deg"]) if v["worst_roll_deg"] is not None else 0.0 for v in voyages]
    a2.bar(np.arange(len(voyages)), worst, color=[f"C{ships.index(v['ship'])}" for v in voyages])
    a2.set_xticks(np.arange(len(voyages)), labels, fontsize=7)
    a2.set_ylabel("worst |roll| (deg)")
    a2.set_title("Worst roll per voyage")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=Path(path).suffix.lstrip(".") or "png", dpi=110)
    plt.close(fig)


def write_fleet(rows: list[dict[str, Any]], path: str) -> None:
    """The fleet event table as CSV (or Parquet by the extension)."""
    if path.lower().endswith((".parquet", ".pq")):
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            raise ImutoolError("a Parquet table needs pyarrow: pip install 'imutool[parquet]'") from None
        cols: list[str] = []
        for r in rows:
            cols += [k for k in r if k not in cols]
        with atomic_path(path) as tmp:
            pq.write_table(pa.Table.from_pylist(rows) if rows else pa.table({"ship": pa.array([], pa.string())}), tmp)
        return
    write_table(rows, path)


def run_fleet(
    sources: str | os.PathLike | list[str] | tuple[str, ...],
    output: str | os.PathLike,
    *,
    voyages_path: str | os.PathLike | None = None,
    plot_path: str | os.PathLike | None = None,
) -> RouteResult:
    """One table across many :func:`run_events` results (``sources``: JSON files, folders walked for ``*.json``,
    glob patterns): the route behind ``imutool events fleet``. Writes the fleet event table ``output`` (.csv or
    .parquet), the per-voyage table ``voyages_path`` (.csv) and the ``plot_path`` figure; ``data``: the event rows
    and the voyage rows."""
    sources = [os.fspath(sources)] if isinstance(sources, (str, os.PathLike)) else [os.fspath(p) for p in sources]
    output = os.fspath(output)
    paths = [p for p, _ in expand_inputs(sources, ("*.json",))]
    if not paths:
        raise ImutoolError("no events results given")
    rows, voyages = fleet_table(load_results(paths))
    write_fleet(rows, output)
    if voyages_path:
        write_table(voyages, os.fspath(voyages_path))
    if plot_path:
        fleet_plot(rows, voyages, os.fspath(plot_path))
    summary = {
        "results": len(paths),
        "events": len(rows),
        "ships": len({v["ship"] for v in voyages}),
        "voyages": len(voyages),
        "parametric_roll_episodes": sum(r["type"] == "parametric_roll" for r in rows),
        "output": output,
    }
    return RouteResult(summary, data={"events": rows, "voyages": voyages})
