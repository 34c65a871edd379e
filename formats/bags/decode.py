"""Message decoders: Imu, MagneticField and Vector3Stamped payloads → stamps, frame ids and float64 blocks.

The fast path reads the fixed layout with numpy (strided views, or a numba byte gather for irregular spacing):
ROS1 serialisation (``seq, sec, nsec, frame_id`` then the float64s) and little-endian CDR (4-byte encapsulation,
``sec, nsec, frame_id`` with NUL, padding to 8, then the float64s). Anything else (big-endian CDR, a length that
does not fit the layout) goes message by message through rosbags' ``deserialize``; :func:`decode_slow` is the
reference path that uses rosbags for everything (and for ROS1 types with a non-standard definition).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from formats.jit.decorators import njit

from ..errors import ImutoolError
from ..jit import cache as kernel_cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from .protocol import RawMessages

# float64s after the header: Imu orientation(4) + cov(9) + angular_velocity(3) + cov(9) + linear_acceleration(3)
# + cov(9); MagneticField field(3) + cov(9); Vector3Stamped vector(3)
NFLOAT = {"imu": 37, "mag": 12, "vec3": 3}


@njit(cache=True)
def u32(b, p):  # pragma: no cover - numba
    """Little-endian uint32 at byte p of a uint8 array (as int64); shared by the container scanners."""
    return np.int64(b[p]) | (np.int64(b[p + 1]) << 8) | (np.int64(b[p + 2]) << 16) | (np.int64(b[p + 3]) << 24)


@njit(cache=True)
def _gather(buf, starts, width):  # pragma: no cover - numba
    """Copy ``width`` bytes from each start into one contiguous (n*width,) uint8 array."""
    n = starts.shape[0]
    out = np.empty(n * width, np.uint8)
    for i in range(n):
        s = starts[i]
        o = i * width
        for j in range(width):
            out[o + j] = buf[s + j]
    return out


def take(buf: np.ndarray, starts: np.ndarray, dtype: str, ncols: int) -> np.ndarray:
    """(n, ncols) values of ``dtype`` read at each byte offset in ``starts`` (contiguous copy).

    Runs of equally spaced starts (the usual case: equal-length messages back to back) are copied through
    strided numpy views; heavily irregular spacing uses the numba byte gather.
    """
    n = starts.shape[0]
    item = np.dtype(dtype).itemsize
    if n == 0:
        return np.empty((0, ncols), dtype)
    if n > 2:
        d = np.diff(starts)
        cp = np.flatnonzero(d[1:] != d[:-1]) + 1
        if cp.size < max(8, n // 256) and np.all(d > 0):
            out = np.empty((n, ncols), dtype)
            bounds = np.concatenate([[0], cp, [n - 1]])
            for p, q in zip(bounds[:-1], bounds[1:], strict=True):
                view = np.ndarray(
                    (q - p + 1, ncols), dtype, buffer=buf, offset=int(starts[p]), strides=(int(d[p]), item)
                )
                out[p : q + 1] = view
            return out
    return _gather(buf, starts, item * ncols).view(dtype).reshape(n, ncols)


_TYPESTORES: dict[str, Any] = {}


def typestore(fmt: str) -> Any:
    """rosbags' type store for 'ros1' (Noetic) or 'cdr' (Humble), built once (rosbags imported lazily: it is
    only needed off the fast path and for writing)."""
    if fmt not in _TYPESTORES:
        from rosbags.typesys import Stores, get_typestore

        _TYPESTORES[fmt] = get_typestore(Stores.ROS1_NOETIC if fmt == "ros1" else Stores.ROS2_HUMBLE)
    return _TYPESTORES[fmt]


def std_md5(msgtype: str) -> str:
    """md5 of the standard ROS1 definition of a message type."""
    return typestore("ros1").generate_msgdef(msgtype)[1]


@dataclass
class Decoded:
    """One topic decoded: header stamps and record times (int64 ns), the float64 block (n, NFLOAT[kind]) in ROS
    frames and units, the distinct frame ids, messages that could not be decoded (bad, dropped) and messages
    decoded by rosbags instead of the fast path (fallback)."""

    stamp_ns: np.ndarray
    rec_ns: np.ndarray
    floats: np.ndarray
    frame_ids: list[str]
    bad: int = 0
    fallback: int = 0


def ns_to_seconds(ns: np.ndarray) -> np.ndarray:
    """int64 ns → float64 s (sec + nsec·1e-9: exact to 1 ns below ~4e6 s)."""
    ns = np.asarray(ns, np.int64)
    sec = ns // 1_000_000_000
    return sec.astype(np.float64) + (ns - sec * 1_000_000_000).astype(np.float64) * 1e-9


def pick_stamps(stamp_ns: np.ndarray, rec_ns: np.ndarray, stamp: str, topic: str, path: str) -> np.ndarray:
    """The time of each message (int64 ns): the header stamp (``stamp='header'``) or the bag's record time
    (``'record'``). Header stamps of zero on more than the first message are a driver that never filled them in:
    ImutoolError suggesting ``--stamp record`` (one zero at the start is a legitimate t = 0 of simulated data)."""
    if stamp == "header":
        zero = stamp_ns == 0
        if zero.sum() > 1 or (zero.any() and len(zero) == 1) or (zero.any() and not zero[0]):
            raise ImutoolError(
                f"{int(zero.sum())} of {len(zero)} messages on {topic} have a zero header stamp; "
                "use --stamp record (the bag's record time) instead",
                path=path,
            )
        return stamp_ns
    if stamp == "record":
        return rec_ns
    raise ImutoolError(f"unknown stamp choice {stamp!r} (header, record)")


def floats_of_msg(m: Any, kind: str) -> list[float]:
    """The float64 block of one message deserialised by rosbags, in the fixed-layout order."""
    if kind == "imu":
        o = m.orientation
        return (
            [o.x, o.y, o.z, o.w]
            + list(m.orientation_covariance)
            + [m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z]
            + list(m.angular_velocity_covariance)
            + [m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
            + list(m.linear_acceleration_covariance)
        )
    if kind == "mag":
        v = m.magnetic_field
        return [v.x, v.y, v.z] + list(m.magnetic_field_covariance)
    v = m.vector
    return [v.x, v.y, v.z]


def decode(raw: RawMessages, kind: str, msgtype: str) -> Decoded:
    """Decode fixed-layout payloads with numpy; irregular ones through rosbags deserialisation."""
    n = raw.offs.shape[0]
    nf = NFLOAT[kind]
    buf, offs, lens = raw.buf, raw.offs, raw.lens
    ok = lens >= 16
    hdr = np.zeros((n, 4), np.uint32)
    if ok.any():
        hdr[ok] = take(buf, offs[ok], "<u4", 4)
    flen = hdr[:, 3].astype(np.int64)
    if raw.fmt == "ros1":
        sec = hdr[:, 1].astype(np.int64)
        fstart = 16 + flen
        expected = fstart + 8 * nf
        ok &= lens == expected
    else:
        enc = hdr[:, 0] & 0xFFFF  # bytes 0,1 (little-endian view): b'\x00\x01' = CDR little endian
        sec = hdr[:, 1].view(np.int32).astype(np.int64)
        fstart = 4 + ((12 + flen + 7) // 8) * 8
        expected = fstart + 8 * nf
        ok &= (enc == 0x0100) & (flen >= 1) & (lens >= expected) & (lens <= expected + 7)
    nsec = hdr[:, 2].astype(np.int64)
    stamp = sec * 1_000_000_000 + nsec
    good = np.flatnonzero(ok)
    if good.size == n:
        floats = take(buf, offs + fstart, "<f8", nf)
    else:
        floats = np.full((n, nf), np.nan)
        if good.size:
            floats[good] = take(buf, offs[good] + fstart[good], "<f8", nf)
    frame_ids = _frame_ids(raw, good, flen)
    # fallback for anything irregular
    badidx = np.flatnonzero(~ok)
    nbad = 0
    keep = np.ones(n, bool)
    if badidx.size:
        ts = typestore(raw.fmt)
        for i in badidx:
            data = buf[offs[i] : offs[i] + lens[i]].tobytes()
            try:
                m = ts.deserialize_ros1(data, msgtype) if raw.fmt == "ros1" else ts.deserialize_cdr(data, msgtype)
                floats[i] = floats_of_msg(m, kind)
                stamp[i] = int(m.header.stamp.sec) * 1_000_000_000 + int(m.header.stamp.nanosec)
                frame_ids.add(m.header.frame_id)
            except Exception:
                keep[i] = False
                nbad += 1
    dec = Decoded(stamp, raw.rec_ns, floats, sorted(frame_ids), bad=nbad, fallback=int(badidx.size) - nbad)
    if nbad:
        dec.stamp_ns, dec.rec_ns, dec.floats = stamp[keep], raw.rec_ns[keep], floats[keep]
    return dec


def _frame_ids(raw: RawMessages, good: np.ndarray, flen: np.ndarray) -> set[str]:
    """Distinct header frame ids of the well-formed messages: one check per distinct length (at most 20 each)."""
    frame_ids: set[str] = set()
    for L in np.unique(flen[good]):
        sel = good[flen[good] == L]
        width = int(L) - (0 if raw.fmt == "ros1" else 1)
        if width <= 0:
            frame_ids.add("")
            continue
        rows = take(raw.buf, raw.offs[sel] + 16, "u1", width)
        uniq = rows[:1] if (rows == rows[0]).all() else np.unique(rows, axis=0)
        for u in uniq[:20]:
            frame_ids.add(u.tobytes().decode("utf-8", "replace"))
    return frame_ids


def decode_slow(bag_path: str, topic: str, kind: str) -> Decoded:
    """Reference path: rosbags AnyReader + per-message deserialise (also used for non-standard definitions)."""
    from rosbags.highlevel import AnyReader

    try:
        with AnyReader([Path(bag_path)]) as r:
            cons = [c for c in r.connections if c.topic == topic]
            st, rt, fl, fr = [], [], [], set()
            for c, t, data in r.messages(connections=cons):
                m = r.deserialize(data, c.msgtype)
                st.append(int(m.header.stamp.sec) * 1_000_000_000 + int(m.header.stamp.nanosec))
                rt.append(t)
                fl.append(floats_of_msg(m, kind))
                fr.add(m.header.frame_id)
    except Exception as exc:
        raise ImutoolError(f"cannot read {topic}: {exc}", path=bag_path) from None
    return Decoded(
        np.array(st, np.int64), np.array(rt, np.int64), np.array(fl, float).reshape(-1, NFLOAT[kind]), sorted(fr)
    )
