"""Former home of the ROS bag reader/writer, kept so ``from formats.rosbag import read_bag`` keeps working.

The code lives in the package :mod:`formats.bags` (one reader protocol, a back-end per storage, the decoders, the
REP-103 conversion, the writer); import from there.
"""

from __future__ import annotations

from .bags import IMU, MAG, VEC3, frd_to_ros_quat, list_topics, read_bag, ros_to_frd_quat, write_bag

__all__ = ["IMU", "MAG", "VEC3", "frd_to_ros_quat", "list_topics", "read_bag", "ros_to_frd_quat", "write_bag"]
