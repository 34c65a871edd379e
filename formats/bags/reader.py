"""Read IMU and magnetometer topics of any bag into one Recording (FRD body / NED world, SI, mag µT).

The bag is opened through the one protocol (:func:`formats.bags.backends.open_bag`), payloads are decoded by
:mod:`formats.bags.decode` and converted by :mod:`formats.bags.rep103`. ``docs/bags.md`` describes it for users.

* ``MagneticField`` is in tesla; imutool uses µT. ``Vector3Stamped`` has no unit: ``vector3_mag_unit`` (default T).
* ``covariance[0] == -1`` means "this quantity is not provided" (ROS convention): the channel is NaN for those
  messages. An all-zero covariance means "unknown" and gives no covariance channel.
* Covariance channels: a diagonal covariance becomes a one-sigma channel in the canonical unit — ``gyro_std``
  (rad/s), ``accel_std`` (m/s²), ``mag_std`` (µT) as (N, 3), and ``roll_std``, ``pitch_std``, ``heading_std``
  (deg) for the orientation. If any off-diagonal term is non-zero on a topic, the full matrix is kept instead as
  ``gyro_cov`` / ``accel_cov`` / ``mag_cov`` / ``q_cov`` (N, 9), row major, columns ``*_cov_xx .. *_cov_zz``, in
  SI² units ((rad/s)², (m/s²)², µT², rad²), already rotated to FRD.
* Time: ``stamp="header"`` (the message header stamp, default) or ``"record"`` (the bag's record/receive time).
  Stamps are integer nanoseconds; ``time`` is float64 seconds ``sec + nsec·1e-9`` (at Unix-epoch magnitudes a
  float64 resolves ≈ 0.24 µs; within 1 ns for times below ~4e6 s).
* With an IMU and a magnetometer topic, the magnetometer is interpolated onto the IMU clock
  (:func:`formats.recording.merge`; only the common time span is kept).
* An orientation of four zeros is not an orientation (drivers without one leave it so, without the covariance
  flag): such messages get NaN in ``q``, and a topic whose every orientation is zero gets no ``q`` (a note says so).
* The units of the fields as read are ``meta['bag']['units']``. ``columns``/``profile`` (as for a foreign CSV,
  :mod:`formats.columns`, naming the bag's columns ``gyro_x`` … ``mag_z``) state another unit or a scale for a
  field whose driver did not follow ROS: ``--columns 'mag_x=mag_x:uT,mag_y=mag_y:uT,mag_z=mag_z:uT'``. Names stay
  (axes are the mounting's business); recorded as ``column_mapping``.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from ..errors import ImutoolError
from ..recording import Recording, join_streams, merge
from ..units import CHANNEL_QUANTITY, factor_to_si
from .backends import open_bag
from .decode import Decoded, decode, decode_slow, ns_to_seconds, pick_stamps, std_md5
from .gnss import GNSS_TYPES, gnss_recording
from .protocol import IMU, KIND, MAG, VEC3, BagReader, Topic
from .rep103 import AXES, COV_SIGN, FLIP, READ_Q, READ_VECTOR, STD_NAMES, ros_to_frd_quat

COV_UNITS = {"gyro": "rad^2/s^2", "accel": "m^2/s^4", "mag": "uT^2", "q": "rad^2"}
IMU_UNITS = {"gyro": "rad/s", "accel": "m/s^2"}  # sensor_msgs/Imu's fields (REP-103 units)


def list_topics(path: str | os.PathLike) -> list[dict[str, Any]]:
    """Topics of a bag: [{'topic', 'type', 'count', 'kind'}] (kind: imu, mag, vec3 or None)."""
    with open_bag(path) as bag:
        return [
            {"topic": t.name, "type": t.msgtype, "count": t.count, "kind": KIND.get(t.msgtype)}
            for t in bag.topics().values()
        ]


def read_bag(
    path: str | os.PathLike,
    topic: str | None = None,
    stamp: str = "header",
    vector3_mag_unit: str = "T",
    fast: bool = True,
    columns: str | None = None,
    profile: str | None = None,
) -> Recording:
    """Read IMU (+ magnetometer) messages from a ROS1 .bag or a ROS2 bag (folder, .db3 or .mcap).

    topic: None (auto: the only Imu topic and the only magnetometer topic; several → ImutoolError listing
    them) or 'IMU_TOPIC[,MAG_TOPIC]'. stamp: 'header' (message stamp) or 'record' (bag record time).
    vector3_mag_unit: unit of a Vector3Stamped magnetometer (T, gauss, uT, nT...). fast=False forces rosbags
    per-message deserialisation (reference path). Output: FRD body / NED world, SI (mag µT), see the module doc.
    With an IMU and a magnetometer topic the magnetometer is interpolated onto the IMU clock
    (formats.recording.merge; only the common time span is kept). columns/profile: unit and scale overrides of
    the bag's fields (see the module doc).
    """
    path = os.fspath(path)
    if stamp not in ("header", "record"):
        raise ImutoolError(f"unknown stamp choice {stamp!r} (header, record)")
    vscale = factor_to_si(vector3_mag_unit, "magnetic")  # a bad unit is reported before the bag is opened
    with open_bag(path) as bag:
        rec = _recording(bag, path, topic, stamp, vscale, fast, vector3_mag_unit)
    if columns or profile:
        rec = apply_columns(rec, columns, profile, path)
    return rec


def apply_columns(rec: Recording, columns: str | None, profile: str | None, path: str) -> Recording:
    """The bag's recording with the units and scales of ``columns`` ('gyro_x=gyro_x:deg/s,...', the CSV syntax)
    or of a TOML ``profile``'s [columns] applied to its fields (and their *_std / *_cov channels); the mapping is
    recorded as ``column_mapping``. A field named to another name is refused: axes are --mounting's."""
    from ..columns import load_profile, mapping_from_profile, parse_mapping_option

    heads = [c for ch in ("gyro", "accel", "mag") if ch in rec.channels for c in rec.columns[ch]]
    if columns:
        mapping = parse_mapping_option(columns, heads)
    else:
        mapping = mapping_from_profile(load_profile(str(profile)), heads, str(profile))
    units = rec.meta["bag"]["units"]
    out = rec.copy()
    done = []
    for c in mapping.columns:
        if c.inferred:
            continue
        if c.target != c.source:
            raise ImutoolError(
                f"--columns {c.source}={c.target}: a bag's fields keep their names; give their unit and scale "
                f"({c.source}={c.source}:UNIT*SCALE), and the axes with --mounting",
                path=path,
            )
        ch = c.source.split("_")[0]
        q = CHANNEL_QUANTITY[ch]
        unit = c.unit or units[ch]
        try:
            f = factor_to_si(unit, q) * c.scale / factor_to_si(units[ch], q)
        except ImutoolError as e:
            raise ImutoolError(f"--columns {c.source}: {e}", path=path) from None
        j = rec.columns[ch].index(c.source)
        out.channels[ch][:, j] *= f
        if f"{ch}_std" in out.channels:
            out.channels[f"{ch}_std"][:, j] *= abs(f)
        if f"{ch}_cov" in out.channels:  # row-major 3×3: row j and column j
            out.channels[f"{ch}_cov"][:, 3 * j : 3 * j + 3] *= f
            out.channels[f"{ch}_cov"][:, j::3] *= f
        done.append(f"{c.source}->{c.target}[{unit}{'' if c.scale == 1 else f'x{c.scale:g}'}]")
    if done:
        out.meta["column_mapping"] = "; ".join(done)
        out.meta["column_mapping_origin"] = mapping.origin
    return out


def recording_of(
    bag: BagReader,
    path: str | os.PathLike,
    topic: str | None = None,
    stamp: str = "header",
    vector3_mag_unit: str = "T",
    fast: bool = True,
) -> Recording:
    """The Recording of an already open bag (any back-end): what :func:`read_bag` returns for that bag.

    path names the bag in errors and metadata, and is what the fast=False reference path re-opens with rosbags.
    Other arguments as :func:`read_bag`.
    """
    if stamp not in ("header", "record"):
        raise ImutoolError(f"unknown stamp choice {stamp!r} (header, record)")
    vscale = factor_to_si(vector3_mag_unit, "magnetic")
    return _recording(bag, os.fspath(path), topic, stamp, vscale, fast, vector3_mag_unit)


def _recording(
    bag: BagReader, path: str, topic: str | None, stamp: str, vscale: float, fast: bool, vunit: str = "T"
) -> Recording:
    """read_bag's work on an open bag; vscale: Vector3Stamped magnetometer unit ``vunit`` → µT."""
    topics = bag.topics()
    if bag.truncated and not any(t.count for t in topics.values()):
        raise ImutoolError("bag is truncated: no complete chunk of messages to read", path=path)
    imu_t, mag_t, gnss, notes = _select(topics, topic, path)
    recs: list[Recording] = []
    info: dict[str, Any] = {}
    frame_ids: list[str] = []
    for t in (imu_t, mag_t):
        if t is None:
            continue
        kind = KIND[t.msgtype]
        nonstd = bag.format == "ros1" and t.md5 and t.md5 != std_md5(t.msgtype)
        if not fast or nonstd:
            if bag.format == "ros1" and bag.truncated:
                raise ImutoolError("truncated bag: only the fast reader can recover it", path=path)
            dec = decode_slow(path, t.name, kind)
        else:
            dec = decode(bag.raw(t), kind, t.msgtype)
        if len(dec.stamp_ns) == 0:
            raise ImutoolError(f"topic {t.name} has no readable messages", path=path)
        r = to_recording(dec, kind, stamp, t.name, path, vscale if kind == "vec3" else 1e6)
        info[kind if kind == "imu" else "mag"] = {
            "topic": t.name,
            "type": t.msgtype,
            "messages": int(len(dec.stamp_ns)),
            "frame_id": dec.frame_ids[0] if len(dec.frame_ids) == 1 else dec.frame_ids,
            "undecodable_skipped": dec.bad,
            "decoded_by_rosbags": dec.fallback,
        }
        frame_ids += dec.frame_ids
        recs.append(r)
    conv = [c for r in recs for c in r.meta.pop("_conv", [])]
    notes += [n for r in recs for n in r.meta.pop("_notes", [])]
    if len(recs) == 2:
        n_imu = len(recs[0])
        rec = merge(recs, clock=recs[0])
        if len(rec) < n_imu:
            notes.append(f"{n_imu - len(rec)} IMU messages outside the magnetometer's time span dropped")
        conv.append("magnetometer interpolated onto the IMU clock")
    elif recs:
        rec = recs[0]
    if gnss:  # each GNSS topic a stream of its own, on its own rows: never resampled
        parts = [gnss_recording(bag, t, stamp, path) for t in gnss]
        for t, (_, gi) in zip(gnss, parts, strict=True):
            info[t.name] = gi
            conv.append(gi.pop("conversion"))
        names = [t.name for t in gnss]
        if recs:
            rec = join_streams([rec] + [r for r, _ in parts], [(imu_t or mag_t).name] + names)  # type: ignore[union-attr]
        else:
            rec = join_streams([r for r, _ in parts], names) if len(parts) > 1 else parts[0][0]
    read = {t.name for t in (imu_t, mag_t, *gnss) if t is not None}
    not_read = [
        {"topic": t.name, "type": t.msgtype, "messages": t.count} for t in topics.values() if t.name not in read
    ]
    streams, stream_rows = rec.meta.get("streams"), rec.stream_rows
    rec.meta = {
        "source": path,
        "sensor": "ROS bag",
        "frame": "body FRD / world NED (converted from ROS REP-103 FLU/ENU)",
        "bag": {
            "format": bag.format,
            "stamp": stamp,
            "topics": info,
            "frame_id": sorted(set(frame_ids)),
            "conversions": conv,
            "units": {
                **{k: u for k, u in IMU_UNITS.items() if k in rec.channels},
                **({"mag": "T" if mag_t.msgtype == MAG else vunit} if mag_t is not None and "mag" in rec else {}),
            },
            "truncated": bool(bag.truncated),
            "notes": notes + list(bag.notes),
        },
    }
    if streams:
        rec.meta["streams"] = streams
        rec.stream_rows = stream_rows
    if not_read:
        rec.meta["bag"]["topics_not_read"] = not_read
    if bag.truncated:
        rec.meta["bag"]["partial_read"] = (
            f"truncated bag: {sum(v['messages'] for v in info.values())} messages recovered from complete chunks"
        )
    return rec


def _cov_channels(rec: Recording, cov: np.ndarray, absent: np.ndarray, name: str, scale: float) -> str | None:
    """Add the covariance of a quantity (FLU, ROS units) as *_std or *_cov channels; returns what was added."""
    present = ~absent
    anyabsent = bool(absent.any())
    cp = cov[present] if anyabsent else cov
    if cp.shape[0] == 0 or not np.any(cp != 0):
        return None
    if np.any(cp[:, [1, 2, 3, 5, 6, 7]] != 0):
        c = cov * (COV_SIGN * scale)
        c[absent] = np.nan
        rec.add(f"{name}_cov", c, COV_UNITS[name], columns=[f"{name}_cov_{a}" for a in AXES])
        return f"{name}_cov"
    var = cov[:, [0, 4, 8]] * scale
    var[absent] = np.nan
    with np.errstate(invalid="ignore"):
        std = np.sqrt(var)
    if name == "q":
        for j, nm in enumerate(STD_NAMES):
            rec.add(nm, np.degrees(std[:, j]), "deg")
        return "roll_std,pitch_std,heading_std"
    rec.add(f"{name}_std", std)
    return f"{name}_std"


def to_recording(dec: Decoded, kind: str, stamp: str, topic: str, path: str, mag_unit_scale: float) -> Recording:
    rec = Recording(ns_to_seconds(pick_stamps(dec.stamp_ns, dec.rec_ns, stamp, topic, path)))
    f = dec.floats
    conv: list[str] = []
    notes: list[str] = []
    if kind == "imu":
        q_abs = f[:, 4] == -1
        g_abs = f[:, 16] == -1
        a_abs = f[:, 28] == -1
        zero_q = np.all(f[:, 0:4] == 0, axis=1)  # not an orientation: a driver that has none
        if zero_q.all() and not q_abs.all():
            notes.append(f"{topic}: every orientation is [0, 0, 0, 0] (not filled by the driver): not read")
        elif not q_abs.all():
            q = ros_to_frd_quat(f[:, 0:4])
            q[q_abs | zero_q] = np.nan
            rec.add("q", q)
            conv.append(READ_Q)
            if (zero_q & ~q_abs).any():
                n0 = int((zero_q & ~q_abs).sum())
                notes.append(f"{topic}: {n0} orientation(s) of [0, 0, 0, 0] read as missing")
        if not g_abs.all():
            g = f[:, 13:16] * FLIP
            g[g_abs] = np.nan
            rec.add("gyro", g)
            conv.append(READ_VECTOR.format("angular_velocity"))
        if not a_abs.all():
            a = f[:, 25:28] * FLIP
            a[a_abs] = np.nan
            rec.add("accel", a)
            conv.append(READ_VECTOR.format("linear_acceleration"))
        for name, sl, absent in (("gyro", slice(16, 25), g_abs), ("accel", slice(28, 37), a_abs)):
            if name in rec:
                _cov_channels(rec, f[:, sl], absent, name, 1.0)
        if "q" in rec:
            _cov_channels(rec, f[:, 4:13], q_abs, "q", 1.0)
        if len(rec.channels) == 0:
            raise ImutoolError(f"{topic}: every Imu field is marked absent (covariance[0] = -1)", path=path)
    else:
        absent = f[:, 3] == -1 if kind == "mag" else np.zeros(len(f), bool)
        m = f[:, 0:3] * FLIP * mag_unit_scale
        m[absent] = np.nan
        rec.add("mag", m)
        what = "magnetic_field" if kind == "mag" else "vector"
        conv.append(READ_VECTOR.format(what) + f", ×{mag_unit_scale:g} → µT")
        if kind == "mag":
            _cov_channels(rec, f[:, 3:12], absent, "mag", mag_unit_scale**2)
    rec.meta["_conv"] = conv
    rec.meta["_notes"] = notes
    return rec


def _select(
    topics: dict[str, Topic], topic: str | None, path: str
) -> tuple[Topic | None, Topic | None, list[Topic], list[str]]:
    """(Imu topic, magnetometer topic, GNSS topics named in ``topic``, notes); see :func:`read_bag`."""

    def listing() -> str:
        return "; ".join(f"{t.name} ({t.msgtype}, {t.count} msgs)" for t in topics.values()) or "none"

    notes: list[str] = []
    wanted = [s.strip() for s in topic.split(",") if s.strip()] if topic else []
    imu_t: Topic | None = None
    mag_t: Topic | None = None
    gnss: list[Topic] = []
    for w in wanted:
        if w not in topics:
            raise ImutoolError(f"topic {w!r} not in bag; topics: {listing()}", path=path)
        t = topics[w]
        kind = KIND.get(t.msgtype)
        if t.msgtype in GNSS_TYPES:
            if t not in gnss:
                gnss.append(t)
            continue
        if kind is None:
            raise ImutoolError(
                f"topic {w} has type {t.msgtype}; imutool reads sensor_msgs/Imu, "
                "sensor_msgs/MagneticField, geometry_msgs/Vector3Stamped and (named in --topic) "
                "sensor_msgs/NavSatFix, geometry_msgs/TwistStamped, geometry_msgs/TwistWithCovarianceStamped",
                path=path,
            )
        if kind == "imu":
            if imu_t is not None:
                raise ImutoolError(f"two Imu topics named ({imu_t.name}, {w}); name one", path=path)
            imu_t = t
        else:
            if mag_t is not None:
                raise ImutoolError(f"two magnetometer topics named ({mag_t.name}, {w}); name one", path=path)
            mag_t = t
    imus = [t for t in topics.values() if t.msgtype == IMU and t.count > 0]
    mags = [
        t
        for t in topics.values()
        if t.count > 0 and (t.msgtype == MAG or (t.msgtype == VEC3 and "mag" in t.name.lower()))
    ]
    for kind_name, cands, chosen in (("Imu", imus, imu_t), ("magnetometer", mags, mag_t)):
        if chosen is not None:
            continue
        if len(cands) > 1:
            if not wanted:
                raise ImutoolError(
                    f"{len(cands)} {kind_name} topics; choose with --topic IMU[,MAG]. Topics: {listing()}", path=path
                )
            notes.append(f"{kind_name} topic not chosen among " + ", ".join(t.name for t in cands) + "; not read")
        elif len(cands) == 1:
            if kind_name == "Imu":
                imu_t = cands[0]
            else:
                mag_t = cands[0]
    if imu_t is None and mag_t is None and not gnss:
        raise ImutoolError(
            "no sensor_msgs/Imu, sensor_msgs/MagneticField or magnetometer Vector3Stamped "
            f"topic with messages; topics: {listing()}",
            path=path,
        )
    return imu_t, mag_t, gnss, notes
