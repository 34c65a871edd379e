"""What every raw-IMU serial protocol decoder gives: :class:`ImuSamples` (SI, imutool's frame) and its counters.

A decoder is incremental: ``feed(data: bytes) -> ImuSamples`` keeps whatever partial frame is left at the end
of ``data`` and completes it from the next read, so a frame split across reads at any byte decodes the same.
Each sample carries ``end`` — the offset, in that ``data``, of the byte that completed it — so the caller can
time it by the bytes that followed it (at the baud rate) from the host's arrival time of the read.

Units and frame (imutool's, ``DESIGN.md``): gyro rad/s, accel m/s² as *specific force* (what an accelerometer
measures: +g upward at rest, so a unit at rest level reads accel_z = −9.81 in body FRD), mag µT, body axes FRD
(x forward, y starboard, z down); the vendor's own attitude, when it sends one, as roll/pitch/yaw in degrees in
imutool's sense (roll + starboard down, pitch + bow up, yaw clockwise seen from above).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ImuSamples:
    """Decoded samples, in arrival order: ``end`` (N,) int byte offset in the fed data of each sample's last
    byte + 1; gyro, accel (N,3) rad/s, m/s² (FRD); mag (N,3) µT or None (NaN rows where a sample had none);
    ``attitude`` (N,3) vendor roll, pitch, yaw deg (imutool's signs) or None; ``temp`` (N,) °C or None;
    ``t_device`` (N,) s of the device's own clock or None."""

    end: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    mag: np.ndarray | None = None
    attitude: np.ndarray | None = None
    temp: np.ndarray | None = None
    t_device: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.end)


@dataclass
class DecoderStats:
    """Counts since the decoder was made: ``frames`` good frames; ``samples`` samples given; ``bad_checksum``
    frames whose checksum/CRC failed; ``malformed`` frames with the right check but unusable content;
    ``garbage_bytes`` bytes skipped that belonged to no good frame; ``resyncs`` times the decoder lost the
    frame boundary and searched for the next start; ``other`` good frames of kinds it does not use;
    ``incomplete`` cycles dropped because a needed part was missing."""

    frames: int = 0
    samples: int = 0
    bad_checksum: int = 0
    malformed: int = 0
    garbage_bytes: int = 0
    resyncs: int = 0
    other: int = 0
    incomplete: int = 0
    extra: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, int]:
        d = {k: int(v) for k, v in self.__dict__.items() if k != "extra"}
        d.update(self.extra)
        return d


class SampleRows:
    """Collects rows of one feed and turns them into :class:`ImuSamples` (NaN where a part is missing)."""

    def __init__(self) -> None:
        self.rows: list[tuple] = []

    def add(self, end: int, gyro, accel, mag=None, att=None, temp=None, t_dev=None) -> None:
        self.rows.append((end, gyro, accel, mag, att, temp, t_dev))

    def samples(self) -> ImuSamples:
        n = len(self.rows)
        if not n:
            z = np.empty((0, 3))
            return ImuSamples(np.empty(0, dtype=np.int64), z, z.copy())
        nan3 = (np.nan, np.nan, np.nan)

        def col(i: int, width: int) -> np.ndarray | None:
            vals = [r[i] for r in self.rows]
            if all(v is None for v in vals):
                return None
            fill = nan3 if width == 3 else np.nan
            return np.array([fill if v is None else v for v in vals], dtype=float)

        return ImuSamples(
            np.array([r[0] for r in self.rows], dtype=np.int64),
            np.array([r[1] for r in self.rows], dtype=float),
            np.array([r[2] for r in self.rows], dtype=float),
            col(3, 3),
            col(4, 3),
            col(5, 1),
            col(6, 1),
        )
