"""ROS bags (ROS1 ``.bag``, ROS2 sqlite3 ``.db3`` and MCAP) ↔ Recording, with REP-103 → FRD/NED at the boundary.

Read: ``sensor_msgs/Imu``, ``sensor_msgs/MagneticField`` and (legacy magnetometer) ``geometry_msgs/Vector3Stamped``.
Write: ``sensor_msgs/Imu`` (+ ``sensor_msgs/MagneticField`` when the recording has ``mag``). ``docs/bags.md`` is
the user's description (channels, frames, covariances, stamps, speed, limits).

The parts, one concept each:

* ``protocol`` — the one reader protocol (:class:`BagReader`: a context manager listing topics, handing out a
  topic's payloads in bulk or lazily one message at a time) and the message types read.
* ``backends`` — :func:`open_bag`: which back-end reads a path.
* ``ros1``, ``ros2_sqlite3``, ``ros2_mcap`` — the fast back-ends (container scanned by small numba kernels);
  ``ros2_rosbags`` — everything else through rosbags' own reader.
* ``decode`` — message payloads → stamps and float64 blocks (numpy on the fixed layout; rosbags as fallback).
* ``rep103`` — the frame conversion ROS FLU/ENU ↔ imutool FRD/NED.
* ``reader`` — :func:`read_bag`, :func:`list_topics` (topic choice, stamps, channels, merge).
* ``writer`` — :func:`write_bag`.

Units: SI inside, mag µT (ROS MagneticField is tesla); time float64 s from integer-ns stamps.
"""

from __future__ import annotations

from .backends import open_bag
from .protocol import IMU, MAG, VEC3, BagReader, RawMessages, Topic
from .reader import list_topics, read_bag, recording_of
from .rep103 import frd_to_ros_quat, ros_to_frd_quat
from .writer import write_bag

__all__ = [
    "IMU",
    "MAG",
    "VEC3",
    "BagReader",
    "RawMessages",
    "Topic",
    "frd_to_ros_quat",
    "list_topics",
    "open_bag",
    "read_bag",
    "recording_of",
    "ros_to_frd_quat",
    "write_bag",
]
