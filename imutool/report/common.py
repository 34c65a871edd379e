"""Pieces shared by the evidence reports: tolerances, item status, hashes, identification, editions, plateaus.

Status vocabulary (never a pass without data that supports one):
``pass`` / ``fail`` (criterion evaluated on enough data), ``insufficient data`` (some data, too little to decide),
``not tested`` (no data for the item). Report-level ``overall``: ``fail`` if any item fails, ``pass`` only if every
required item passed, otherwise ``incomplete``.
"""

from __future__ import annotations

import hashlib
import os
import re
import subprocess
from datetime import datetime, timezone
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from formats import Recording
from formats.errors import ImutoolError
from imutool import __version__

PASS, FAIL, INSUFFICIENT, NOT_TESTED = "pass", "fail", "insufficient data", "not tested"
STATUSES = (PASS, FAIL, INSUFFICIENT, NOT_TESTED)

SCOPE = (
    "This report is test evidence produced by imutool from recorded data. It is NOT a type approval: type "
    "approval (e.g. MED wheelmark, recognised-organisation or flag acceptance) is granted by the "
    "Administration or a recognised organisation. Criteria whose source could not be confirmed are listed "
    "with their confidence tag (legend of the standards excerpts shipped with imutool, "
    "imutool/report/standards.md: A verbatim, B secondary quote, C partial, R recalled and not confirmed, "
    "I imutool's inference)."
)
STANDARDS_FILE = "imutool/report/standards.md (shipped with imutool)"

CRITERION = "max"  # max: every sample/cycle within tolerance | p95: 95 % bound (MSC.1/Circ.1575)
ALIGN = "none"  # none: common clock, latency counts as error | xcorr: remove the measured constant lag
MAX_LAG_S = 5.0  # s, ± lag searched by the cross-correlation

CONFIDENCE = {
    "A": "seen verbatim",
    "B": "secondary source quoting the text",
    "C": "partial (titles / TOC only)",
    "R": "recalled, NOT confirmed",
    "I": "imutool inference, not a requirement",
}


def check_tolerance(name: str, floor: float, pct: float, unit: str) -> None:
    """Refuse a tolerance that cannot be met or means nothing: floor > 0 and 0 < pct < 100."""
    if not (np.isfinite(floor) and floor > 0):
        raise ImutoolError(
            f"{name} tolerance floor must be > 0 {unit} (got {floor:g}): a zero or negative "
            "tolerance cannot be met by any instrument"
        )
    if not (np.isfinite(pct) and 0 < pct < 100):
        raise ImutoolError(f"{name} tolerance must be between 0 and 100 % of reading (got {pct:g} %)")


def standards_cited(ids: list[str]) -> list[dict[str, str]]:
    """The rows of the shipped standards excerpts (imutool/report/standards.md) with these ids: id, requirement,
    value, source, confidence — so a report quotes what it applies, with its confidence tag."""
    text = resources.files("imutool.report").joinpath("standards.md").read_text(encoding="utf-8")
    rows: dict[str, dict[str, str]] = {}
    for line in text.splitlines():
        if not line.startswith("| P"):
            continue
        c = [x.strip().replace("\\|", "|").replace("**", "") for x in re.split(r"(?<!\\)\|", line.strip()[1:-1])]
        if len(c) >= 5:
            rows[c[0]] = {
                "id": c[0],
                "requirement": c[1].replace("*", ""),
                "value": c[2],
                "source": c[3],
                "confidence": c[4],
            }
    return [rows[i] for i in ids if i in rows]


def tol_angle(reading_deg: np.ndarray | float, floor_deg: float = 1.0, pct: float = 5.0) -> np.ndarray:
    """MSC.363(92) angle tolerance max(floor, pct % of |reading|) (deg; standards.md P3, conf. B)."""
    return np.maximum(floor_deg, pct / 100.0 * np.abs(np.asarray(reading_deg, float)))


def tol_period(reading_s: np.ndarray | float, floor_s: float = 1.0, pct: float = 5.0) -> np.ndarray:
    """MSC.363(92) roll-period tolerance max(floor, pct % of reading) (s; standards.md P4, conf. B)."""
    return np.maximum(floor_s, pct / 100.0 * np.abs(np.asarray(reading_s, float)))


def judge(err: np.ndarray, tol: np.ndarray | float, criterion: str = "max", n_min: int = 1) -> tuple[str, dict]:
    """Status of an error series against a tolerance series.

    criterion ``max``: every |error| ≤ tolerance. ``p95``: the 95th percentile of |error|/tolerance ≤ 1 (the
    95 % bound of MSC.1/Circ.1575, standards.md P12). Fewer than n_min finite samples → insufficient data.
    Returns (status, {worst_ratio, p95_ratio, n_exceed}).
    """
    e = np.asarray(err, float)
    tl = np.broadcast_to(np.asarray(tol, float), e.shape)
    ok = np.isfinite(e) & np.isfinite(tl)
    n = int(ok.sum())
    if n == 0:
        return NOT_TESTED, {"worst_ratio": None, "p95_ratio": None, "n_exceed": 0}
    r = np.abs(e[ok]) / tl[ok]
    info = {
        "worst_ratio": float(r.max()),
        "p95_ratio": float(np.percentile(r, 95)),
        "n_exceed": int(np.count_nonzero(r > 1.0)),
    }
    if n < n_min:
        return INSUFFICIENT, info
    value = info["worst_ratio"] if criterion == "max" else info["p95_ratio"]
    return (PASS if value <= 1.0 else FAIL), info


def stats(err: np.ndarray) -> dict[str, Any]:
    """N, max |error|, RMS, 95th percentile |error|, mean (bias), std — JSON-safe (None for NaN)."""
    from imutool.metrics import error_stats

    s = error_stats(np.asarray(err, float))
    return {k: clean(v) for k, v in s.items() if k in ("n", "max_abs", "rmse", "p95_abs", "mean", "std")}


def clean(v: Any) -> Any:
    """JSON-safe value: numpy → python, NaN/inf → None, recursively."""
    if isinstance(v, dict):
        return {str(k): clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [clean(x) for x in v]
    if isinstance(v, np.ndarray):
        return clean(v.tolist())
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if np.isfinite(f) else None
    if isinstance(v, np.bool_):
        return bool(v)
    if isinstance(v, (str, int, bool)) or v is None:
        return v
    return str(v)


def item(
    id_: str,
    clause: str,
    title: str,
    status: str,
    reason: str,
    criterion: str | None = None,
    stats_: dict | None = None,
    rows: list | None = None,
    extra: dict | None = None,
) -> dict[str, Any]:
    """One item of an evidence report (JSON-clean): id, clause, title, status (:data:`STATUSES`), the reason for
    it, the criterion, its statistics, its table rows and any ``extra`` fields."""
    return clean(
        {
            "id": id_,
            "clause": clause,
            "title": title,
            "status": status,
            "reason": reason,
            "criterion": criterion,
            "stats": stats_ or {},
            "rows": rows or [],
            **(extra or {}),
        }
    )


def sha256_of(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def tool_identity() -> dict[str, Any]:
    """imutool version and git commit (if the package sits in a git checkout)."""
    git = None
    try:
        root = Path(__file__).resolve().parents[2]
        out = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5)
        if out.returncode == 0:
            git = out.stdout.strip()
            dirty = subprocess.run(
                ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                capture_output=True,
                text=True,
                timeout=5,
            )
            if dirty.returncode == 0 and dirty.stdout.strip():
                git += " (modified)"
    except (OSError, subprocess.SubprocessError):
        git = None
    return {"name": "imutool", "version": __version__, "git": git}


def now_utc() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def own_samples(rec: Recording, channel: str) -> Recording:
    """The recording a report evaluates for ``channel``: on a many-clock log (several sentence types, topics or
    ``--with`` files: :class:`formats.Recording`), the stream that carries it, on its own rows only (another
    stream's row is not a missing sample of it); the file's streams are kept in ``meta["file_streams"]``
    (:meth:`formats.Recording.stream_summary`) for the inputs record. A single-clock recording is returned as
    it is."""
    if not rec.multi_clock or channel not in rec.channels:
        return rec
    out = rec.stream(channel)
    out.meta["file_streams"] = rec.stream_summary()
    out.meta["file_rows"] = len(rec)
    return out


def channel_on(rec: Recording, name: str, t: np.ndarray) -> np.ndarray | None:
    """Channel ``name`` of ``rec`` (its stored unit) at the times ``t`` (s): the values themselves where ``t``
    are its own sample times, else interpolated linearly from its own samples (:func:`imutool.metrics.interp_to`:
    NaN outside them and across a gap). None when ``rec`` has no such channel."""
    from imutool.metrics import interp_to

    if name not in rec.channels:
        return None
    ts, v = rec.series(name)
    v = np.asarray(v, float)
    if ts.shape == t.shape and np.array_equal(ts, t):
        return v
    return interp_to(t, ts, v)


def input_record(path: str | None, rec: Any, channel: str | None, kind: str) -> dict[str, Any]:
    """Identification of one input: path, sha256, size, rows, rate, duration, channel used, how it was loaded
    (``loading``: the time and header options given, where its times came from, the files merged onto it; from
    ``rec.meta["loading"]``, :func:`imutool.loading.how_loaded`), metadata. For a stream of a many-clock log
    (:func:`own_samples`): ``rows``, ``rate_hz`` and ``duration_s`` are the stream's own samples, ``stream``
    names it and ``streams`` lists every stream of the file (samples, rate, duration)."""
    if path is None:
        return {"path": None, "sha256": None, "kind": kind, "rows": int(len(rec)) if rec is not None else 0}
    if rec is None:
        return clean({"path": os.fspath(path), "sha256": sha256_of(path), "bytes": os.path.getsize(path), "kind": kind})
    meta = {k: v for k, v in rec.meta.items() if k not in ("validation", "loading", "file_streams", "file_rows")}
    many = (
        {"stream": rec.meta.get("stream"), "streams": rec.meta["file_streams"], "file_rows": rec.meta.get("file_rows")}
        if rec.meta.get("file_streams")
        else {}
    )
    return clean(
        {
            "path": os.fspath(path),
            "sha256": sha256_of(path),
            "bytes": os.path.getsize(path),
            "kind": kind,
            "rows": int(len(rec)),
            "rate_hz": float(rec.rate_hz) if len(rec) > 1 else None,
            "duration_s": float(rec.duration),
            "channel": channel,
            **many,
            "meta": meta,
            "validation": rec.meta.get("validation"),
            **({"loading": rec.meta["loading"]} if rec.meta.get("loading") else {}),
        }
    )


def plateaus(
    t: np.ndarray, x: np.ndarray, band: float, min_s: float, settle_s: float = 2.0, window_s: float = 2.0
) -> list[tuple[float, float]]:
    """Stationary stretches of x: runs where the range of x over ±window_s/2 stays ≤ band, lasting ≥ min_s.

    Returns [(start, end)] in s, each trimmed by settle_s at the start (the table settling after a move).
    """
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    t = np.asarray(t, float)
    x = np.asarray(x, float)
    if t.size < 3:
        return []
    dt = float(np.median(np.diff(t)))
    w = max(3, int(round(window_s / dt)) | 1)
    xf = np.where(np.isfinite(x), x, np.nan)
    hi = maximum_filter1d(np.nan_to_num(xf, nan=np.inf), w, mode="nearest")
    lo = minimum_filter1d(np.nan_to_num(xf, nan=-np.inf), w, mode="nearest")
    still = (hi - lo) <= band
    out: list[tuple[float, float]] = []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        t0, t1 = t[a] + settle_s, t[b - 1]
        if t1 - t0 >= min_s:
            out.append((float(t0), float(t1)))
    return out


def overall(items: list[dict[str, Any]], required: tuple[str, ...]) -> dict[str, Any]:
    """Report verdict: ``fail`` if any item fails; ``pass`` only if every required item was tested and passed;
    otherwise ``incomplete`` with the lists of passed and not-passed (not tested / insufficient) items."""
    counts = {s: sum(1 for it in items if it["status"] == s) for s in STATUSES}
    req = {it["id"]: it["status"] for it in items if it["id"] in required}
    if counts[FAIL]:
        status = FAIL
    elif all(req.get(r) == PASS for r in required):
        status = PASS
    else:
        status = "incomplete"
    missing = [r for r in required if req.get(r) != PASS]
    passed = [it["id"] for it in items if it["status"] == PASS]
    failed = [it["id"] for it in items if it["status"] == FAIL]
    untested = [r for r in required if req.get(r) in (NOT_TESTED, INSUFFICIENT, None)]
    if status == PASS:
        headline = f"PASS: all {len(required)} required items tested and passed"
    elif status == FAIL:
        headline = f"FAIL: {', '.join(failed)}"
    else:
        headline = f"INCOMPLETE: passed: {', '.join(passed) or 'none'}; not tested: {', '.join(untested)}"
    return {
        "status": status,
        "headline": headline,
        "counts": counts,
        "required_items": list(required),
        "required_not_passed": missing,
        "passed": passed,
        "failed": failed,
        "not_tested": untested,
        "exit_status": 0 if status == PASS else 1,
        "rule": "fail if any item fails; pass only if every required item was tested and passed; otherwise "
        "incomplete. Exit status 0 pass, 1 fail or incomplete, 2 usage error",
    }


def set_clock(ev: dict[str, Any], plots: dict[str, Any], ref: Any) -> None:
    """State the reference's clock in the evidence (``conventions.clock``; :class:`imutool.clock.Clock`): every
    row time gets an ISO ``*_utc`` beside its seconds when the recording has a date; the PDF prints those times
    as UTC clock time, else as seconds from the start. ``plots['clock']`` is the same clock."""
    from imutool.clock import Clock, stamp_times

    clock = Clock.of(ref)
    ev.setdefault("conventions", {})["clock"] = clock.as_json()
    stamp_times(ev.get("items"), clock)
    plots["clock"] = clock
