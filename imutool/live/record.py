"""Recording while live, through capture's durable sink (:mod:`imutool.capture.sink`): the raw samples and the
estimates in rotating imutool CSVs (``raw_<UTC>.csv``, ``estimate_<UTC>.csv``) and an events log, in ``DIR``.

Rows are appended as whole lines and flushed per block (a SIGKILL loses no completed row: the kernel keeps what
was written); fsync at most every second. The estimate files are what ``imutool report inclinometer`` takes as the
device under test (``roll`` deg + starboard down, with a ``time`` column on the input's clock). A full disk stops
the recording, not the outputs: :attr:`Recorder.stopped` says why and the engine logs it.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from formats.errors import ImutoolError
from imutool.capture.sink import CaptureCsv, EventLog, utc_stamp

RAW_COLUMNS = ["time", "gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z", "mag_x", "mag_y", "mag_z"]
EST_COLUMNS = ["time", "roll", "pitch", "heading", "roll_std", "pitch_std", "heave", "status_a"]


class Recorder:
    """Raw samples and estimates to rotating CSVs in ``folder``; never raises after it started."""

    def __init__(self, folder: str | os.PathLike, meta: dict[str, Any], rotate_s: float | None = 3600.0) -> None:
        self.folder = Path(folder)
        stamp = utc_stamp()
        self.stopped: str | None = None
        self.rows = 0
        try:
            self.raw = CaptureCsv(
                self.folder / f"raw_{stamp}.csv",
                RAW_COLUMNS,
                {**meta, "content": "raw samples (SI: rad/s, m/s^2, uT), sensor frame, before calibration"},
                rotate_s=rotate_s,
            )
            self.est = CaptureCsv(
                self.folder / f"estimate_{stamp}.csv",
                EST_COLUMNS,
                {
                    **meta,
                    "content": "imutool live estimates: roll/pitch/heading deg (roll + starboard down), "
                    "heave m + up, status_a 1 while the outputs' status is A",
                },
                rotate_s=rotate_s,
            )
            self.events = EventLog(self.folder / "live_events.jsonl")
        except OSError as e:
            raise ImutoolError(f"cannot record: {e.strerror}", path=str(folder)) from None

    def write_raw(self, raw: np.ndarray) -> str | None:
        """Append raw rows (rows × RAW_COLUMNS); returns why the recording stopped, once."""
        return self._write(self.raw, raw)

    def write_estimates(self, est: np.ndarray) -> str | None:
        """Append estimate rows (rows × EST_COLUMNS); returns why the recording stopped, once."""
        why = self._write(self.est, est)
        if why is None and not self.stopped:
            self.rows += len(est)
        return why

    def _write(self, sink: CaptureCsv, rows: np.ndarray) -> str | None:
        if self.stopped:
            return None
        try:
            sink.write_rows(rows)
        except ImutoolError as e:  # DiskFull and any other write error: the outputs go on
            self.stopped = str(e)
            return self.stopped
        return None

    def event(self, name: str, **fields: Any) -> None:
        if self.stopped:
            return
        try:
            self.events.add(name, **fields)
        except ImutoolError as e:
            self.stopped = str(e)

    @property
    def files(self) -> list[str]:
        return self.raw.file.files + self.est.file.files

    def close(self, summary: dict[str, Any]) -> None:
        flat = {k: v for k, v in summary.items() if not isinstance(v, (list, dict))}
        for f in (self.raw, self.est):
            try:
                f.close(flat)
            except (ImutoolError, OSError):
                pass
        try:
            self.events.close()
        except (ImutoolError, OSError):
            pass
