"""Cost of the streamed CSV's final header (formats.csv.CsvWriter): metadata known only at the end (a streamed
run's warnings and validation) replace the first chunk's in the header, and the rows are copied once behind it.

Run: python benchmarks/stream_header.py [ROWS]   (default 2 000 000 rows of 9-axis data, written in 500 000-row
chunks; prints the time to write them without final metadata, with them (kernel copy: os.copy_file_range), and with
them by 16 MiB blocks (no kernel copy), and the file size)
"""

from __future__ import annotations

import os
import sys
import tempfile
import time

import numpy as np

from formats import Recording
from formats.csv import CsvWriter


def _write(path: str, chunks: list[Recording], final: dict | None) -> float:
    t0 = time.perf_counter()
    with CsvWriter(path) as w:
        for c in chunks:
            w.write(c)
        if final:
            w.set_final_meta(final)
    return time.perf_counter() - t0


def main(rows: int = 2_000_000) -> None:
    rng = np.random.default_rng(1)
    step = 500_000
    chunks = []
    for r0 in range(0, rows, step):
        n = min(step, rows - r0)
        t = (r0 + np.arange(n)) / 200.0
        chunks.append(
            Recording(
                t,
                {k: rng.normal(size=(n, 3)) for k in ("gyro", "accel", "mag")},
                meta={"warnings": ["first chunk"], "source": "benchmark"},
            )
        )
    final = {"warnings": [f"warning {i}" for i in range(5)], "validation": {"rows_read": rows, "rows_kept": rows}}
    copy_range = getattr(os, "copy_file_range", None)
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "s.csv")
        best: dict[str, float] = {}
        for _ in range(3):
            for name, meta, kernel in (
                ("no final metadata", None, True),
                ("final header, kernel copy", final, True),
                ("final header, block copy", final, False),
            ):
                if not kernel and copy_range is not None:
                    del os.copy_file_range
                try:
                    best[name] = min(best.get(name, np.inf), _write(p, chunks, meta))
                finally:
                    if copy_range is not None:
                        os.copy_file_range = copy_range
                size = os.path.getsize(p)
                os.unlink(p)
    print(f"{rows} rows, {size / 1e6:.0f} MB (best of 3):")
    base = best["no final metadata"]
    for name, s in best.items():
        extra = "" if name == "no final metadata" else f"  (+{s - base:.2f} s, +{100 * (s - base) / base:.0f} %)"
        print(f"  {name:28s} {s:6.2f} s{extra}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 2_000_000)
