"""Write a Recording as sensor_msgs/Imu (+ sensor_msgs/MagneticField) to a ROS1 ``.bag`` or a ROS2 bag.

Payloads are serialised with numpy on the fixed layout (ROS1 or little-endian CDR; the tests check the bytes
against rosbags' serialisers), converted back to REP-103 (:mod:`formats.bags.rep103`) and written one message at a
time through rosbags' writers, atomically (temporary name, renamed at the end).
"""

from __future__ import annotations

import os
import re
import shutil
import sqlite3
import struct
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import atomic_path
from ..errors import ImutoolError
from ..frames import euler_to_quat
from ..recording import Recording
from .decode import typestore
from .protocol import IMU, MAG
from .rep103 import AXES, COV_SIGN, FLIP, STD_NAMES, WRITE_COV, WRITE_EULER, WRITE_Q, WRITE_VECTOR, frd_to_ros_quat


def _seconds_to_sec_nsec(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float64 seconds → (sec, nsec) integers, rounding to the nearest ns without losing float precision."""
    t = np.asarray(t, np.float64)
    sec = np.floor(t)
    nsec = np.rint((t - sec) * 1e9).astype(np.int64)
    sec = sec.astype(np.int64)
    carry = nsec >= 1_000_000_000
    sec[carry] += 1
    nsec[carry] -= 1_000_000_000
    return sec, nsec


def _cov_from(rec: Recording, name: str, unit_scale: float) -> np.ndarray | None:
    """(N, 9) covariance in FRD (SI² imutool units) from *_cov, 9 scalar columns, or *_std; None if absent."""
    n = len(rec)
    cn = f"{name}_cov"
    if cn in rec and rec[cn].shape[1:] == (9,):
        c = rec[cn].astype(float)
    elif all(f"{cn}_{a}" in rec for a in AXES):
        c = np.stack([rec[f"{cn}_{a}"] for a in AXES], axis=1).astype(float)
    elif name == "q" and all(s in rec for s in STD_NAMES):
        c = np.zeros((n, 9))
        for j, s in enumerate(STD_NAMES):
            c[:, 4 * j] = np.radians(rec.get(s, "deg")) ** 2
        return c
    elif name != "q" and f"{name}_std" in rec and rec[f"{name}_std"].shape[1:] == (3,):
        unit = {"gyro": "rad/s", "accel": "m/s^2", "mag": "uT"}[name]
        s = rec.get(f"{name}_std", unit) if rec.units.get(f"{name}_std") else rec[f"{name}_std"]
        c = np.zeros((n, 9))
        c[:, [0, 4, 8]] = s**2
        return c
    else:
        return None
    return c


def _cov_names(rec: Recording, name: str) -> list[str]:
    cn = f"{name}_cov"
    out = [cn] + [f"{cn}_{a}" for a in AXES]
    out += list(STD_NAMES) if name == "q" else [f"{name}_std"]
    return [x for x in out if x in rec]


def _imu_payloads(rec: Recording, fmt: str, frame_id: str) -> tuple[np.ndarray, list[str]]:
    """Serialise Imu messages with numpy (fixed layout); returns (bytes as (n, size) uint8, used channels)."""
    floats, used = imu_floats(rec)
    return serialise(rec.time, floats, fmt, frame_id), used


def imu_floats(rec: Recording) -> tuple[np.ndarray, list[str]]:
    """The 37 float64s of each row's Imu message (REP-103) and the channels used.

    A row without a value is "no data" as sensor_msgs/Imu says: its covariance[0] is -1 and the field is zeros
    (an orientation of a quaternion with a NaN component, a gyro or accel row whose every axis is NaN). No NaN
    goes into an orientation or a flagged field; a NaN covariance entry is written 0 (unknown).
    """
    n = len(rec)
    used: list[str] = []
    floats = np.zeros((n, 37))
    q = None
    if "q" in rec and rec["q"].shape[1:] == (4,):
        q = rec["q"]
        used.append("q")
    elif all(k in rec for k in ("roll", "pitch", "heading")):
        q = euler_to_quat(rec.get("roll", "rad"), rec.get("pitch", "rad"), rec.get("heading", "rad"))
        used += ["roll", "pitch", "heading"]
    if q is not None:
        q_abs = ~np.all(np.isfinite(q), axis=1)
        floats[:, 0:4] = frd_to_ros_quat(np.where(q_abs[:, None], [1.0, 0.0, 0.0, 0.0], q))
        c = _cov_from(rec, "q", 1.0)
        if c is not None:
            floats[:, 4:13] = np.nan_to_num(c * COV_SIGN, nan=0.0)
            used += _cov_names(rec, "q")
    else:
        q_abs = np.ones(n, bool)
    floats[q_abs, 0:13] = 0.0  # "no data": a zero quaternion, covariance[0] = -1
    floats[q_abs, 4] = -1.0
    for name, vs, cs in (("gyro", 13, 16), ("accel", 25, 28)):
        absent = np.ones(n, bool)
        if name in rec and rec[name].shape[1:] == (3,):
            unit = "rad/s" if name == "gyro" else "m/s^2"
            v = rec.in_unit(name, unit)
            absent = np.all(np.isnan(v), axis=1)
            floats[:, vs : vs + 3] = v * FLIP
            used.append(name)
            c = _cov_from(rec, name, 1.0)
            if c is not None:
                floats[:, cs : cs + 9] = np.nan_to_num(c * COV_SIGN, nan=0.0)
                used += _cov_names(rec, name)
        floats[absent, vs : cs + 9] = 0.0
        floats[absent, cs] = -1.0
    return floats, used


def _mag_payloads(rec: Recording, fmt: str, frame_id: str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """MagneticField messages of the rows with a value (a row whose every axis is NaN is no sample)."""
    m = rec.get("mag", "uT") if rec.units.get("mag") else rec["mag"]
    keep = ~np.all(np.isnan(m), axis=1)
    floats = np.zeros((len(rec), 12))
    floats[:, 0:3] = m * FLIP * 1e-6
    used = ["mag"]
    c = _cov_from(rec, "mag", 1.0)
    if c is not None:
        floats[:, 3:12] = np.nan_to_num(c * COV_SIGN * 1e-12, nan=0.0)
        used += _cov_names(rec, "mag")
    return serialise(rec.time[keep], floats[keep], fmt, frame_id), keep, used


def serialise(t: np.ndarray, floats: np.ndarray, fmt: str, frame_id: str) -> np.ndarray:
    """Messages as rows of a (n, size) uint8 array: header (stamp, frame_id) + float64 block."""
    n, nf = floats.shape
    sec, nsec = _seconds_to_sec_nsec(t)
    fid = frame_id.encode("utf-8")
    if fmt == "ros1":
        L = len(fid)
        fstart = 16 + L
        size = fstart + 8 * nf
        out = np.zeros((n, size), np.uint8)
        out[:, 0:4] = np.arange(n, dtype="<u4").view(np.uint8).reshape(n, 4)
        if np.any(sec < 0) or np.any(sec > 0xFFFFFFFF):
            raise ImutoolError("time is outside the ROS1 stamp range (0 .. 2^32 s)")
        out[:, 4:8] = sec.astype("<u4").view(np.uint8).reshape(n, 4)
    else:
        L = len(fid) + 1
        fstart = 4 + ((12 + L + 7) // 8) * 8
        size = fstart + 8 * nf
        out = np.zeros((n, size), np.uint8)
        out[:, 1] = 1  # CDR little endian
        if np.any(sec < -(2**31)) or np.any(sec >= 2**31):
            raise ImutoolError("time is outside the ROS2 stamp range (int32 seconds)")
        out[:, 4:8] = sec.astype("<i4").view(np.uint8).reshape(n, 4)
    out[:, 8:12] = nsec.astype("<u4").view(np.uint8).reshape(n, 4)
    out[:, 12:16] = np.frombuffer(struct.pack("<I", L), np.uint8)
    if fid:
        out[:, 16 : 16 + len(fid)] = np.frombuffer(fid, np.uint8)
    out[:, fstart:] = np.ascontiguousarray(floats, dtype="<f8").view(np.uint8).reshape(n, 8 * nf)
    return out


def _stamps_ns(t: np.ndarray) -> np.ndarray:
    sec, nsec = _seconds_to_sec_nsec(t)
    return sec * 1_000_000_000 + nsec


_TOPIC = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")


def check_topic_name(name: object, what: str = "topic") -> str:
    """A concrete ROS topic name (ROS 2 naming rules, which ROS 1 accepts too): tokens of letters, digits and
    underscores separated by single slashes, none starting with a digit, no repeated underscore, no trailing
    slash, no substitution (``~``, ``{}``) since a bag stores the resolved name. Returns it; else ImutoolError."""
    if not isinstance(name, str) or not _TOPIC.fullmatch(name) or "__" in name:
        raise ImutoolError(
            f"{what} {name!r} is not a valid ROS topic name (letters, digits, '_' in tokens separated by single "
            "'/', a token not starting with a digit, no '__', no trailing '/'; e.g. /imu/data)"
        )
    return name


def write_bag(
    rec: Recording,
    path: str | os.PathLike,
    topic: str = "/imu/data",
    mag_topic: str = "/imu/mag",
    frame_id: str | None = None,
    storage: str | None = None,
    compression: str | None = None,
) -> dict[str, Any]:
    """Write a Recording as sensor_msgs/Imu (+ MagneticField) to a ROS1 .bag or a ROS2 bag.

    path: ``*.bag`` ROS1; ``*.db3`` / ``*.mcap`` a single ROS2 storage file; any other name a ROS2 bag folder
    (storage ``sqlite3`` unless ``storage='mcap'``). FRD/NED → FLU/ENU (inverse of :func:`read_bag`); mag µT → T.
    Orientation from ``q`` (or roll/pitch/heading), its covariance from ``q_cov`` or roll/pitch/heading_std.
    compression: ROS1 chunk compression 'bz2' or 'lz4'. Atomic. Returns a summary with the channels written
    and those that an Imu/MagneticField message cannot carry (``channels_not_written``).
    """
    from rosbags.rosbag1 import Writer as Writer1  # lazy: rosbags is imported only when a bag is written
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    path = os.fspath(path)
    p = Path(path)
    ext = p.suffix.lower()
    ros1 = ext == ".bag"
    try:
        check_topic_name(topic, "IMU topic")
        check_topic_name(mag_topic, "magnetometer topic")
    except ImutoolError as e:
        raise ImutoolError(str(e), path=path) from None
    if len(rec) == 0:
        raise ImutoolError("nothing to write: the recording has no rows", path=path)
    has_imu = any(k in rec for k in ("gyro", "accel", "q")) or all(k in rec for k in ("roll", "pitch", "heading"))
    has_mag = "mag" in rec and rec["mag"].shape[1:] == (3,)
    if not has_imu and not has_mag:
        raise ImutoolError(
            "nothing to write as Imu/MagneticField: needs gyro, accel, q/roll,pitch,heading or mag; "
            f"has {', '.join(rec.channels) or 'none'}",
            path=path,
        )
    if len(rec) > 1 and np.any(np.diff(rec.time) < 0):
        raise ImutoolError("time goes backwards; validate the recording first (--backwards sort)", path=path)
    fid = frame_id or _meta_frame_id(rec) or "imu_link"
    fmt = "ros1" if ros1 else "cdr"
    if ext in (".db3", ".mcap"):
        storage = ext[1:].replace("db3", "sqlite3")
    elif storage is None:
        storage = "sqlite3"
    if storage not in ("sqlite3", "mcap"):
        raise ImutoolError(f"unknown ROS2 storage {storage!r} (sqlite3, mcap)")
    used: list[str] = []
    msgs: list[tuple[str, str, np.ndarray, np.ndarray]] = []
    topic_streams: dict[str, str | None] = {}
    notes: list[str] = []
    if has_imu:
        groups, notes = imu_topics(rec, topic)
        for name, stream, sub in groups:
            pay, u = _imu_payloads(sub, fmt, fid)
            used += [c for c in u if c not in used]
            msgs.append((name, IMU, pay, _stamps_ns(sub.time)))
            topic_streams[name] = stream
    if has_mag:
        sub = rec if not rec.multi_clock else rec.select(rec.own_rows("mag"))
        pay, keep, u = _mag_payloads(sub, fmt, fid)
        used += u
        msgs.append((mag_topic, MAG, pay, _stamps_ns(sub.time[keep])))
        topic_streams[mag_topic] = rec.stream_of("mag")
    not_written = [k for k in rec.channels if k not in used]
    ts = typestore("ros1" if ros1 else "cdr")
    try:
        if ros1:
            with atomic_path(path) as tmp:
                os.unlink(tmp)
                w = Writer1(tmp)
                if compression:
                    if compression not in ("bz2", "lz4"):
                        raise ImutoolError(f"unknown ROS1 compression {compression!r} (bz2, lz4)")
                    w.set_compression(Writer1.CompressionFormat[compression.upper()])
                with w:
                    _write_all(w, msgs, ts)
        elif ext in (".db3", ".mcap"):
            with atomic_path(path) as tmp:
                os.unlink(tmp)
                d = Path(tempfile.mkdtemp(prefix=".imutool-bag.", dir=p.parent if str(p.parent) else "."))
                try:
                    folder = d / p.stem
                    plugin = StoragePlugin.MCAP if ext == ".mcap" else StoragePlugin.SQLITE3
                    with Writer2(folder, version=9, storage_plugin=plugin) as w:
                        _write_all(w, msgs, ts)
                    inner = next(folder.glob("*" + ext))
                    os.replace(inner, tmp)
                finally:
                    shutil.rmtree(d, ignore_errors=True)
        else:
            with atomic_path(path, is_dir=True) as tmp:
                plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
                inner_name = p.name or "bag"
                with Writer2(tmp, version=9, storage_plugin=plugin) as w:
                    _write_all(w, msgs, ts)
                _rename_storage(tmp, inner_name)
    except ImutoolError:
        raise
    except OSError as exc:
        raise ImutoolError(f"cannot write bag: {exc}", path=path) from None
    except sqlite3.Error as exc:  # rosbag2's sqlite3 storage: "database or disk is full", "disk I/O error"
        raise ImutoolError(f"cannot write bag: {exc} (disk full?)", path=path) from None
    return {
        "format": "ros1" if ros1 else f"ros2-{storage}",
        "messages": {t: int(len(pay)) for t, _, pay, _ in msgs},
        "frame_id": fid,
        "channels_written": used,
        "channels_not_written": not_written,
        "conversions": _out_conversions(used),
        **({"streams": topic_streams} if rec.multi_clock else {}),
        **({"notes": notes} if notes else {}),
    }


def _token(stream: str) -> str:
    """A stream's name as one ROS topic token ('HDT+PASHR' → 'hdt_pashr')."""
    tok = re.sub(r"[^A-Za-z0-9]+", "_", stream).strip("_").lower() or "stream"
    return "s" + tok if tok[0].isdigit() else tok


def imu_topics(rec: Recording, topic: str = "/imu/data") -> tuple[list[tuple[str, str | None, Recording]], list[str]]:
    """The Imu topics of a recording: [(topic name, stream or None, recording of that topic's rows)] and notes.

    A single-clock recording is one topic on every row. A many-clock one (:class:`formats.recording.Recording`)
    gets one topic per stream that carries an Imu field (orientation — ``q``, or ``roll``, ``pitch`` and
    ``heading`` on the rows where all three are sampled —, ``gyro``, ``accel``), on that stream's own rows only:
    ``topic`` when one stream carries them all, else ``topic/<stream>`` each. Samples of roll/pitch/heading on
    rows where the other two have none cannot make an orientation: the notes count them.
    """
    fields: list[tuple[list[str], np.ndarray, str | None]] = []  # (channels, rows, stream)
    if "q" in rec and rec["q"].shape[1:] == (4,):
        fields.append((["q", *_cov_names(rec, "q")], rec.own_rows("q"), rec.stream_of("q")))
    elif all(k in rec for k in ("roll", "pitch", "heading")):
        rpy = ("roll", "pitch", "heading")
        rows = rec.own_rows("roll") & rec.own_rows("pitch") & rec.own_rows("heading")
        fields.append(([*rpy, *_cov_names(rec, "q")], rows, rec.stream_of("roll")))
    for name in ("gyro", "accel"):
        if name in rec and rec[name].shape[1:] == (3,):
            fields.append(([name, *_cov_names(rec, name)], rec.own_rows(name), rec.stream_of(name)))
    if not rec.multi_clock:
        return [(topic, None, rec)], []
    notes: list[str] = []
    if "q" not in rec and fields and fields[0][0][0] == "roll":
        for c in ("roll", "pitch", "heading"):
            v = rec[c]
            lost = int((rec.own_rows(c) & ~fields[0][1] & np.isfinite(v)).sum())
            if lost:
                notes.append(
                    f"{c}: {lost} samples ({rec.stream_of(c)}) on rows without the other two of roll/pitch/heading "
                    "not written (an Imu orientation needs all three)"
                )
    groups: dict[bytes, tuple[list[str], np.ndarray, str | None]] = {}
    for chans, rows, stream in fields:
        key = np.packbits(rows).tobytes()
        if key in groups:
            groups[key][0].extend(chans)
        else:
            groups[key] = (list(chans), rows, stream)
    out = []
    for chans, rows, stream in groups.values():
        sub = rec.select(rows)
        for c in list(sub.channels):
            if c not in chans:
                sub.remove(c)
        sub.stream_rows = {}
        sub.meta.pop("streams", None)
        name = topic if len(groups) == 1 else f"{topic.rstrip('/')}/{_token(stream or 'rows')}"
        out.append((name, stream, sub))
    return out, notes


def _out_conversions(used: list[str]) -> list[str]:
    conv = [WRITE_VECTOR.format(k) for k in ("gyro", "accel", "mag") if k in used]
    if "mag" in used:
        conv.append("mag µT → T")
    if "q" in used:
        conv.append(WRITE_Q)
    elif "roll" in used:
        conv.append(WRITE_EULER)
    if any(k.endswith(("_std", "_cov")) or "_cov_" in k for k in used):
        conv.append(WRITE_COV)
    return conv


def _rename_storage(folder: Path, name: str) -> None:
    """rosbags names the storage file after the (temporary) folder; give it the final bag name."""
    meta = folder / "metadata.yaml"
    for f in folder.iterdir():
        if f.suffix in (".db3", ".mcap") and f.stem != name:
            new = f.with_name(name + f.suffix)
            os.replace(f, new)
            text = meta.read_text()
            text = re.sub(re.escape(f.name), new.name, text)
            meta.write_text(text)


def _meta_frame_id(rec: Recording) -> str | None:
    b = rec.meta.get("bag")
    if isinstance(b, dict):
        f = b.get("frame_id")
        if isinstance(f, list) and len(f) == 1:
            return str(f[0])
        if isinstance(f, str):
            return f
    return None


def _write_all(w: Any, msgs: list[tuple[str, str, np.ndarray, np.ndarray]], ts: Any) -> None:
    for topic, msgtype, pay, stamps in msgs:
        conn = w.add_connection(topic, msgtype, typestore=ts)
        flat = pay.tobytes()
        size = pay.shape[1]
        write = w.write
        for i, t in enumerate(stamps.tolist()):
            write(conn, t, flat[i * size : (i + 1) * size])
