"""The frame of a reference (truth) recording: declared, converted to body FRD → NED, and checked.

A reference orientation (``ref_q``, ``ref_roll/ref_pitch/ref_heading``) is compared with an estimate only when
both describe the same body in the same world. Motion-capture systems and ROS tools give a z-up world (ENU, or the
capture volume's own axes), and their body axes are the marker set's or the sensor's, not the vessel's:

- ``ref_frame`` (``evaluate --ref-frame``) names the reference's **world**: ``ned`` (as imutool), ``enu`` (x east,
  y north, z up) or ``zup`` (z up, x the capture volume's horizontal axis, y to its left; heading then counts from
  that x axis: ``--align-heading``);
- ``ref_mounting`` (``--ref-mounting REMAP[;R,P,Y]``, as ``--mounting``) maps the reference's body axes into the
  estimate's body axes where they differ (e.g. ``x,-y,-z`` for a FLU marker set against an FRD estimate).

:func:`reference_to_ned` converts at load; :func:`vertical_disagreement` measures how far the reference's vertical
(gravity in its body axes) lies from the estimate's — a reference in another frame shows up as tens of degrees
(an upside-down one as ~180°) where an estimate's real tilt error is a few — and :func:`frame_warning` names the
options when it does.

Which body a ``ref_q`` of an *input* rotates from is the recording's ``meta['ref_frame']``
(:data:`formats.recording.REF_BODY_SENSOR`: the sensor's axes, turned into the body by a ``--mounting`` —
BROAD's ``sensor->NED``; anything else or absent: the body's own, which a mounting leaves untouched,
:meth:`formats.Recording.mounted`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from formats import Recording
from formats.errors import ImutoolError
from formats.frames import (
    Q_ENU_TO_NED,
    Q_FLU_TO_FRD,
    euler_to_quat,
    matrix_to_quat,
    parse_axis_remap,
    quat_conjugate,
    quat_multiply,
    quat_to_euler,
    rotation_about_axes,
)
from formats.recording import parse_mounting
from imutool.metrics import interp_to

REF_FRAMES = ("ned", "enu", "zup")
"""The worlds a reference may be declared in (``--ref-frame``)."""

WORLD_TO_NED = {
    "ned": np.array([1.0, 0.0, 0.0, 0.0]),
    "enu": Q_ENU_TO_NED,  # (e, n, u) → (n, e, d)
    "zup": Q_FLU_TO_FRD,  # (x, y left, z up) → (x, y right, z down): a rotation of 180° about x
}
"""Quaternion W of each world with v_ned = W ⊗ v_world ⊗ W*."""

VERTICAL_DISAGREEMENT_DEG = 20.0
"""Mean angle (deg) between the reference's and the estimate's vertical beyond which the two are taken to be in
different frames (a warning naming ``--ref-frame``/``--ref-mounting``): an attitude estimate off by 20° of tilt on
average is broken, a frame mistake is 90° or 180°."""

ANGLES = ("roll", "pitch", "heading")


def parse_ref_frame(value: str | None) -> str | None:
    """``--ref-frame``: None, or one of :data:`REF_FRAMES` (case-insensitive)."""
    if value is None or not str(value).strip():
        return None
    v = str(value).strip().lower()
    if v not in REF_FRAMES:
        raise ImutoolError(f"--ref-frame {value!r}: expected one of {', '.join(REF_FRAMES)}")
    return v


def reference_to_ned(
    ref: Recording,
    ref_frame: str | None = None,
    ref_mounting: str | None = None,
    prefixes: tuple[str, ...] = ("ref_",),
) -> tuple[Recording, dict[str, Any]]:
    """``ref`` with its orientation (``<prefix>q`` and ``<prefix>roll/pitch/heading`` for each of ``prefixes``:
    ``ref_`` for truth columns, ``''`` as well for a report's reference file) turned into the estimate's body FRD →
    NED: q = W ⊗ q_ref ⊗ C*, W the world's rotation into NED (:data:`WORLD_TO_NED`), C the ``ref_mounting``
    (reference body → estimate body). Angles without a quaternion are taken as ZYX Euler angles in the declared
    world and converted through one. Returns (recording, what was done: ``world``, ``mounting``, ``converted``,
    ``how``). Neither given: the reference as it is (its world taken as NED)."""
    world = parse_ref_frame(ref_frame) or "ned"
    info: dict[str, Any] = {"world": world, "mounting": ref_mounting or None}
    if world == "ned" and not ref_mounting:
        info["how"] = (
            "declared NED (--ref-frame ned)" if ref_frame else "taken as body → NED (no --ref-frame/--ref-mounting)"
        )
        return ref, info
    c = np.eye(3)
    if ref_mounting:
        remap, mis = parse_mounting(ref_mounting)
        c = rotation_about_axes(*np.radians(mis)) @ parse_axis_remap(remap)
    w, qc = WORLD_TO_NED[world], matrix_to_quat(c)
    out = ref.copy()
    converted: list[str] = []
    hows: list[str] = []
    for prefix in prefixes:
        has_q = f"{prefix}q" in ref.channels and np.shape(ref[f"{prefix}q"])[1:] == (4,)
        has_angles = all(f"{prefix}{n}" in ref.channels for n in ANGLES)
        if not has_q and not has_angles:
            continue
        if has_q:
            q = np.asarray(ref[f"{prefix}q"], float)
            hows.append(f"{prefix}q")
        else:
            q = euler_to_quat(*(np.radians(np.asarray(ref[f"{prefix}{n}"], float)) for n in ANGLES))
            hows.append(f"{prefix}roll/{prefix}pitch/{prefix}heading (ZYX Euler in that world)")
        q_ned = quat_multiply(quat_multiply(w, q), quat_conjugate(qc))
        if has_q:
            out.channels[f"{prefix}q"] = q_ned
            converted.append(f"{prefix}q")
        angles = dict(zip(ANGLES, (np.degrees(a) for a in quat_to_euler(q_ned)), strict=True))
        for n in ANGLES:
            if f"{prefix}{n}" in ref.channels:
                out.add(f"{prefix}{n}", angles[n], "deg")
                converted.append(f"{prefix}{n}")
    if not converted:
        names = " or ".join(f"{p}qw..{p}qz, or {p}roll, {p}pitch and {p}heading" for p in prefixes)
        raise ImutoolError(f"--ref-frame/--ref-mounting: the reference has no orientation to convert ({names})")
    out.meta["ref_world"] = "ned"
    info["converted"] = converted
    info["how"] = (
        f"{'; '.join(hows)} from a {world.upper()} world"
        + (f" and reference body axes mounted {ref_mounting}" if ref_mounting else "")
        + " into body FRD → NED at load"
    )
    return out, info


def _down_from_q(q: np.ndarray) -> np.ndarray:
    """The world's down (gravity) direction in body axes: the third row of R(q) (N×3)."""
    w, x, y, z = np.moveaxis(np.asarray(q, float), -1, 0)
    return np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1)


def _down_from_angles(roll_deg: np.ndarray, pitch_deg: np.ndarray) -> np.ndarray:
    r, p = np.radians(np.asarray(roll_deg, float)), np.radians(np.asarray(pitch_deg, float))
    return np.stack([-np.sin(p), np.sin(r) * np.cos(p), np.cos(r) * np.cos(p)], axis=-1)


def _down(rec: Recording, prefix: str) -> np.ndarray | None:
    q = f"{prefix}q"
    if q in rec.channels and np.shape(rec[q])[1:] == (4,):
        return _down_from_q(rec[q])
    if f"{prefix}roll" in rec.channels and f"{prefix}pitch" in rec.channels:
        return _down_from_angles(rec[f"{prefix}roll"], rec[f"{prefix}pitch"])
    return None


def vertical_disagreement(est: Recording, ref: Recording) -> float | None:
    """Mean angle (deg) between the estimate's vertical and the reference's, each as the world's down in body axes
    (from ``q`` or roll/pitch; the reference's interpolated onto the estimate's times): about the estimate's tilt
    error when both are in one frame, 180° for an upside-down reference. None when either has no attitude."""
    de, dr = _down(est, ""), _down(ref, "ref_")
    if de is None or dr is None:
        return None
    if ref is not est or est.multi_clock:  # another recording, or truth on its own rows (many clocks)
        dr = interp_to(est.time, ref.time, dr)
    dot = np.sum(de * dr, axis=1) / (np.linalg.norm(de, axis=1) * np.linalg.norm(dr, axis=1))
    dot = dot[np.isfinite(dot)]
    if dot.size == 0:
        return None
    return float(np.mean(np.degrees(np.arccos(np.clip(dot, -1.0, 1.0)))))


def frame_warning(angle_deg: float | None, declared: bool) -> str | None:
    """The warning for a mean vertical disagreement beyond :data:`VERTICAL_DISAGREEMENT_DEG` (None below it)."""
    if angle_deg is None or not angle_deg > VERTICAL_DISAGREEMENT_DEG:
        return None
    said = (
        "even with the frame given: check --ref-frame and --ref-mounting"
        if declared
        else "is the reference in another frame (a z-up motion-capture or ENU world, other body axes)? give "
        "--ref-frame ned|enu|zup and/or --ref-mounting REMAP"
    )
    return (
        f"the reference's vertical differs from the estimate's gravity direction by {angle_deg:.1f}° on average "
        f"(more than {VERTICAL_DISAGREEMENT_DEG:g}°): {said}"
    )
