"""Estimate vs truth: the one route behind ``imutool evaluate`` (and a Python user).

:func:`evaluate` compares an estimate recording with a reference (``ref_*`` truth columns; the estimate itself
by default): per angle RMSE, max, p95, MAE, lag and SNR (deg; heading errors wrapped to ±180°), quaternion
errors with the BROAD metrics (total, heading, inclination), heave (positive up, with the three "5 cm or 5 %"
readings) or position; optionally an error plot. Nothing is printed.
"""

from __future__ import annotations

import importlib
import os
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.errors import ImutoolError
from formats.frames import wrap_deg180

CHANNELS = ("angles", "quaternion", "heave", "position")


def load_for_evaluation(path: str | os.PathLike) -> Recording:
    """Read ``path`` and put it in time order (duplicates dropped, backwards time sorted)."""
    path = os.fspath(path)
    rec = formats.read(path)
    rec, _ = rec.validated(duplicates="drop", backwards="sort", source=path)
    return rec


def evaluate(
    estimate: str | os.PathLike | Recording,
    reference: str | os.PathLike | Recording | None = None,
    *,
    channel: str | None = None,
    max_lag_s: float = 0.0,
    plot: str | os.PathLike | None = None,
) -> dict[str, Any]:
    """Compare ``estimate`` with ``reference`` (paths or Recordings; default: the estimate's own ``ref_*``).

    channel: ``angles`` (roll/pitch/heading vs ref_roll/ref_pitch/ref_heading, deg), ``quaternion`` (q vs
    ref_q), ``heave`` or ``position``; default angles plus quaternion when both have one. ``max_lag_s``: search a
    constant lag up to ± this many seconds. ``plot``: error plot (.png/.pdf). Returns the summary dict.
    """
    if channel is not None and channel not in CHANNELS:
        raise ImutoolError(f"evaluate channel {channel!r}: expected one of {', '.join(CHANNELS)}")
    est_path = _name(estimate)
    est = estimate if isinstance(estimate, Recording) else load_for_evaluation(estimate)
    if reference is None:
        ref, ref_path = est, None
    else:
        ref = reference if isinstance(reference, Recording) else load_for_evaluation(reference)
        ref_path = _name(reference)
        check_overlap(est, ref, est_path, ref_path)
    summary: dict[str, Any] = {"estimate": est_path, "reference": ref_path or est_path}
    if channel == "heave":
        signs = {
            "estimate": str(est.meta.get("heave_positive", "up")),
            "reference": str(ref.meta.get("heave_positive", "up")),
        }
        same = ref is est
        est = heave_up(est)
        ref = est if same else heave_up(ref)
        summary["heave"] = _external("imutool.heave", "evaluate_heave", "heave")(est, ref, max_lag_s)
        summary["heave"]["compared"] = (
            f"positive up (files: estimate {signs['estimate']}, reference {signs['reference']})"
        )
        heave_readings(est, ref, summary["heave"])
    elif channel == "position":
        summary["position"] = _external("imutool.ins", "evaluate_position", "position")(est, ref)
    else:
        if channel in (None, "angles"):
            ang = evaluate_angles(est, ref, max_lag_s)
            if ang:
                summary["angles"] = ang
            elif channel == "angles":
                raise ImutoolError(
                    "no angle to compare: need roll/pitch/heading in EST and ref_roll/ref_pitch/"
                    "ref_heading in the reference"
                )
        if channel == "quaternion" or (channel is None and "q" in est.channels and "ref_q" in ref.channels):
            summary["quaternion"] = evaluate_quaternion_rec(est, ref)
        if len(summary) == 2:
            raise ImutoolError("nothing to compare: no matching estimate/ref_* channels", path=est_path)
    if plot:
        plot_errors(est, ref, os.fspath(plot))
        summary["plot"] = os.fspath(plot)
    return summary


def check_overlap(est: Recording, ref: Recording, est_path: str, ref_path: str) -> None:
    """A reference that can be compared with the estimate: two rows or more, and a time span that overlaps
    the estimate's by more than one sample interval (an ImutoolError naming the reference otherwise)."""
    if len(ref) < 2:
        raise ImutoolError(f"the reference has {len(ref)} row(s): nothing to compare with", path=ref_path)
    if len(est) < 2:
        raise ImutoolError(f"the estimate has {len(est)} row(s): nothing to compare", path=est_path)
    start = max(float(est.time[0]), float(ref.time[0]))
    end = min(float(est.time[-1]), float(ref.time[-1]))
    if not end > start:
        raise ImutoolError(
            f"the reference ({ref.time[0]:.6g} … {ref.time[-1]:.6g} s) does not overlap the estimate "
            f"{os.path.basename(est_path)} ({est.time[0]:.6g} … {est.time[-1]:.6g} s) in time: same clock?",
            path=ref_path,
        )


def _name(x: str | os.PathLike | Recording) -> str:
    return str(x.meta.get("source", "<recording>")) if isinstance(x, Recording) else os.fspath(x)


def evaluate_angles(est: Recording, ref: Recording, max_lag_s: float) -> dict[str, Any]:
    """Roll/pitch/heading of ``est`` vs ref_roll/ref_pitch/ref_heading of ``ref`` (deg; SNR against the raw
    accelerometer/magnetometer angles of ``ref`` when it has the sensor channels)."""
    from imutool.metrics import evaluate_angle, interp_to

    raw = _raw_angles(ref)
    out: dict[str, Any] = {}
    for name in ("roll", "pitch", "heading"):
        if name not in est.channels or f"ref_{name}" not in ref.channels:
            continue
        r = raw.get(name)
        if r is not None:
            r = interp_to(est.time, ref.time, r) if name != "heading" else _interp_wrapped(est.time, ref.time, r)
        st = evaluate_angle(
            est.time, est[name], ref.time, ref[f"ref_{name}"], wrap=name == "heading", max_lag_s=max_lag_s, raw=r
        )
        out[name] = {k: (round(v, 5) if isinstance(v, float) else v) for k, v in st.items()}
    return out


def _interp_wrapped(t, ts, a):
    from imutool.metrics import interp_to, unwrap_deg

    return interp_to(t, ts, unwrap_deg(a)) % 360.0


def evaluate_quaternion_rec(est: Recording, ref: Recording) -> dict[str, Any]:
    """q of ``est`` vs ref_q of ``ref`` (interpolated onto the estimate's times): BROAD total, heading and
    inclination errors (deg), over the ``movement`` rows when a movement label is there."""
    from imutool.metrics import evaluate_quaternion, interp_to

    if "q" not in est.channels:
        raise ImutoolError("the estimate has no quaternion (qw..qz)")
    if "ref_q" not in ref.channels:
        raise ImutoolError("the reference has no ref_qw..ref_qz columns")
    qr = ref["ref_q"]
    if ref is not est and (len(ref) != len(est) or not np.array_equal(ref.time, est.time)):
        qr = interp_to(est.time, ref.time, qr)
        qr = qr / np.linalg.norm(qr, axis=1, keepdims=True)
    mask = None
    for src in (est, ref):
        if "movement" in src.channels:
            mv = src["movement"] if src is est else np.round(interp_to(est.time, ref.time, ref["movement"]))
            mask = np.nan_to_num(mv) > 0
            break
    out = evaluate_quaternion(est["q"], qr, mask)
    out["rows"] = "movement rows" if mask is not None else "all rows"
    return out


def _raw_angles(ref) -> dict[str, np.ndarray]:
    """Unfiltered angles (deg) from the reference file's sensor channels (accel tilt, tilt-compensated mag)."""
    if "accel" not in ref.channels:
        return {}
    from imutool.baseline import accel_tilt, tilt_compensated_heading

    roll, pitch = accel_tilt(ref["accel"])
    out = {"roll": np.degrees(roll), "pitch": np.degrees(pitch)}
    if "mag" in ref.channels:
        out["heading"] = np.degrees(tilt_compensated_heading(ref["mag"], roll, pitch))
    return out


def _external(module: str, func: str, what: str):
    try:
        mod = importlib.import_module(module)
        return getattr(mod, func)
    except (ImportError, AttributeError):
        raise ImutoolError(f"{what} evaluation is not available in this build ({module}:{func} missing)") from None


_HEAVE_COLUMNS = ("heave", "heave_delayed", "heave_rate", "heave_rate_delayed", "ref_heave", "ref_heave_rate")


def heave_up(rec: Recording) -> Recording:
    """The recording with every heave column positive up (metadata ``heave_positive: down`` → negated copy)."""
    if str(rec.meta.get("heave_positive", "up")).lower() != "down":
        return rec
    out = rec.copy()
    for name in _HEAVE_COLUMNS:
        if name in out.channels:
            out.add(name, -out[name], out.units.get(name))
    out.meta["heave_positive"] = "up"
    return out


def heave_readings(est: Recording, ref: Recording, out: dict[str, Any]) -> None:
    """Add the three "5 cm or 5 %" readings (imutool.metrics.heave_accuracy) to each evaluated heave channel."""
    from imutool.metrics import heave_accuracy

    rname = next(
        (n for n in ("ref_heave", "heave") if n in ref.channels and (ref is not est or n == "ref_heave")), None
    )
    if rname is None:
        return
    for ch, flag in (("heave", "settled"), ("heave_delayed", "settled_delayed")):
        if isinstance(out.get(ch), dict) and ch in est.channels:
            mask = np.asarray(est[flag]) > 0.5 if flag in est.channels else None
            out[ch]["readings"] = heave_accuracy(
                est.time, est[ch], ref.time, ref[rname], lag_s=float(out[ch].get("lag_s", 0.0)), mask=mask
            )


def plot_errors(est: Recording, ref: Recording, path: str) -> None:
    """Estimate and reference per angle, and the error with the filter's ±2σ band, into ``path`` (.png/.pdf)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from formats.atomic import atomic_path
    from imutool.metrics import interp_to, unwrap_deg

    names = [n for n in ("roll", "pitch", "heading") if n in est.channels and f"ref_{n}" in ref.channels]
    if not names:
        raise ImutoolError("nothing to plot: no roll/pitch/heading with ref_* columns")
    fig, axes = plt.subplots(len(names), 2, figsize=(12, 2.8 * len(names)), squeeze=False)
    for i, n in enumerate(names):
        wrap = n == "heading"
        r = interp_to(est.time, ref.time, unwrap_deg(ref[f"ref_{n}"]) if wrap else ref[f"ref_{n}"])
        e = est[n] - r
        if wrap:
            e = wrap_deg180(e)
            r = r % 360
        axes[i, 0].plot(est.time, r, "k-", lw=1, label="reference")
        axes[i, 0].plot(est.time, est[n], "C0-", lw=0.8, label="estimate")
        axes[i, 0].set_ylabel(f"{n} (deg)")
        axes[i, 0].legend(loc="upper right", fontsize=8)
        axes[i, 1].plot(est.time, e, "C3-", lw=0.8)
        if f"{n}_std" in est.channels:
            s = est[f"{n}_std"]
            axes[i, 1].fill_between(est.time, -2 * s, 2 * s, color="0.8", label="±2σ (filter)")
            axes[i, 1].legend(loc="upper right", fontsize=8)
        axes[i, 1].set_ylabel(f"{n} error (deg)")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=path.rsplit(".", 1)[-1].lower() if "." in path else "png", dpi=100)
    plt.close(fig)
