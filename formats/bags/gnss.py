"""GNSS topics of a bag: ``sensor_msgs/NavSatFix`` (position) and ``geometry_msgs/TwistStamped`` /
``TwistWithCovarianceStamped`` (velocity), each read as a stream of its own (never resampled onto the IMU clock).

These topics are few messages per second, so each message goes through rosbags' ``deserialize``.

* NavSatFix → ``lat``, ``lon`` (deg, WGS 84), ``gnss_height`` (m above the WGS 84 ellipsoid, as the message
  says), ``gnss_fix_status`` (the message's -1 no fix, 0 fix, 1 SBAS, 2 GBAS); a message with status -1 has NaN
  position. When ``position_covariance_type`` is not 0 (unknown), the diagonal of the ENU covariance (m²) gives
  ``gnss_lat_std`` (north), ``gnss_lon_std`` (east) and ``gnss_height_std`` (up), one sigma in m.
* Twist → ``vel_n``, ``vel_e``, ``vel_d`` (m/s, NED): the linear velocity is taken in an ENU world frame (the
  GNSS drivers' convention, e.g. nmea_navsat_driver's ``vel``): ``vel_n = y``, ``vel_e = x``, ``vel_d = -z``
  (REP-103 ENU → NED, :mod:`formats.bags.rep103`). The angular part is not read.

``nav_msgs/Odometry`` is not read: its twist is in the body (child) frame, not a GNSS velocity.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ImutoolError
from ..recording import Recording
from .decode import ns_to_seconds, pick_stamps, typestore
from .protocol import BagReader, Topic
from .rep103 import READ_TWIST

NAVSAT = "sensor_msgs/msg/NavSatFix"
TWIST = "geometry_msgs/msg/TwistStamped"
TWIST_COV = "geometry_msgs/msg/TwistWithCovarianceStamped"
GNSS_TYPES = {NAVSAT: "fix", TWIST: "vel", TWIST_COV: "vel"}


def _stamp_ns(m: Any) -> int:
    return int(m.header.stamp.sec) * 1_000_000_000 + int(m.header.stamp.nanosec)


def gnss_recording(bag: BagReader, topic: Topic, stamp: str, path: str) -> tuple[Recording, dict[str, Any]]:
    """The Recording of one NavSatFix or Twist topic (module doc) and its ``meta['bag']['topics']`` entry."""
    kind = GNSS_TYPES[topic.msgtype]
    ts = typestore(topic.fmt)
    de = ts.deserialize_ros1 if topic.fmt == "ros1" else ts.deserialize_cdr
    st: list[int] = []
    rt: list[int] = []
    vals: list[list[float]] = []
    frames: set[str] = set()
    bad = 0
    for rec_ns, data in bag.messages(topic):
        try:
            m = de(bytes(data), topic.msgtype)
        except Exception:
            bad += 1
            continue
        st.append(_stamp_ns(m))
        rt.append(int(rec_ns))
        frames.add(m.header.frame_id)
        if kind == "fix":
            c = m.position_covariance
            vals.append(
                [m.latitude, m.longitude, m.altitude, m.status.status, m.position_covariance_type, c[0], c[4], c[8]]
            )
        else:
            v = m.twist.twist.linear if topic.msgtype == TWIST_COV else m.twist.linear
            vals.append([v.x, v.y, v.z])
    if not st:
        raise ImutoolError(f"topic {topic.name} has no readable messages", path=path)
    t_ns = pick_stamps(np.array(st, np.int64), np.array(rt, np.int64), stamp, topic.name, path)
    order = np.argsort(t_ns, kind="stable")
    a = np.array(vals, float)[order]
    rec = Recording(ns_to_seconds(t_ns[order]))
    if kind == "fix":
        nofix = a[:, 3] < 0
        pos = a[:, 0:3].copy()
        pos[nofix] = np.nan
        rec.add("lat", pos[:, 0], "deg")
        rec.add("lon", pos[:, 1], "deg")
        rec.add("gnss_height", pos[:, 2], "m")
        rec.add("gnss_fix_status", a[:, 3], "1")
        known = a[:, 4] > 0
        if known.any():
            with np.errstate(invalid="ignore"):
                sd = np.where(known[:, None], np.sqrt(a[:, 5:8]), np.nan)
            for j, name in enumerate(("gnss_lon_std", "gnss_lat_std", "gnss_height_std")):  # ENU diagonal
                rec.add(name, sd[:, j], "m")
        conv = f"{topic.name}: NavSatFix latitude/longitude (deg), altitude (m, WGS 84 ellipsoid); status -1 → NaN"
    else:
        rec.add("vel_n", a[:, 1], "m/s")
        rec.add("vel_e", a[:, 0], "m/s")
        rec.add("vel_d", -a[:, 2], "m/s")
        conv = f"{topic.name}: {READ_TWIST}"
    info = {
        "topic": topic.name,
        "type": topic.msgtype,
        "messages": len(st),
        "frame_id": sorted(frames)[0] if len(frames) == 1 else sorted(frames),
        "undecodable_skipped": bad,
        "channels": list(rec.channels),
        "conversion": conv,
    }
    return rec, info
