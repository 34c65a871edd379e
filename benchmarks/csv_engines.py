"""imutool's CSV dialect read and written by the hand-written compiled engine, polars and pyarrow.csv (issue 52).

Each (engine, operation) runs in its own process (wall time of the operation alone, peak RSS of the process),
interleaved in ``--repeat`` rounds so the machine's load falls on every engine alike. The file is what imutool
writes for a 9-channel 200 Hz recording (``# imutool-csv: 1``, metadata lines with JSON, ``# units:``, header,
exact shortest round-trip doubles). Reading ends with the channels as float64 NumPy arrays (what a Recording
holds); writing starts from them. Write cases: ``input`` (17-digit doubles, exact) and ``estimate`` (the
filter's output: 22 columns at 6/9/0 fixed decimals). Each write is checked for an exact round trip of its values.

Imports and the first load of the compiled kernels are outside the timed part (wall and CPU of all threads); the
peak RSS is the whole process's (Python, numpy, numba and the library imported: ~180–200 MB before any work).
``CSV_ENGINES_CHECK=1``: each child also checks its result (written values read back bit-exactly; polars' and
pyarrow's read values bit-identical to imutool's).

Usage::

    python benchmarks/csv_engines.py                 # 2 M rows, 3 rounds
    python benchmarks/csv_engines.py --rows 500000 --repeat 1
    CSV_ENGINES_CHECK=1 python benchmarks/csv_engines.py --rows 100000 --repeat 1
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# -- the child: one (engine, operation) ---------------------------------------------------------------------
CHILD = r"""
import os, sys, time
import numpy as np
sys.path.insert(0, sys.argv[1])
engine, op, path, rows = sys.argv[2], sys.argv[3], sys.argv[4], int(sys.argv[5])
import formats
from formats.csv import read_header, read_csv, iter_csv, write_csv, header_text

DECIMALS = {"roll": 6, "pitch": 6, "heading": 6, "q": 9, "gyro_bias": 9, "roll_std": 6, "pitch_std": 6,
            "heading_std": 6, "accel_rejected": 0, "mag_rejected": 0, "rest": 0, "inconsistent": 0,
            "heading_inconsistent": 0}  # what the filter writes (imutool.attitude.recording.OUTPUT_DECIMALS)

def recording(kind):
    # input: time + gyro/accel/mag as 17-digit doubles; estimate: the filter's output columns + ref_*
    rng = np.random.default_rng(1)
    rec = formats.Recording(np.arange(rows) / 200.0)
    if kind == "input":
        for g, s in (("gyro", 0.1), ("accel", 9.8), ("mag", 40.0)):
            rec.add(g, rng.standard_normal((rows, 3)) * s)
    else:
        for n in ("roll", "pitch", "heading"):
            rec.add(n, rng.standard_normal(rows) * 30)
        rec.add("q", rng.standard_normal((rows, 4)) * 0.5)
        rec.add("gyro_bias", rng.standard_normal((rows, 3)) * 0.5)
        for n in ("roll_std", "pitch_std", "heading_std"):
            rec.add(n, np.abs(rng.standard_normal(rows)), "deg")
        for n in ("accel_rejected", "mag_rejected", "rest", "inconsistent", "heading_inconsistent"):
            rec.add(n, (rng.random(rows) < 0.1).astype(float), "1")
        for n in ("ref_roll", "ref_pitch", "ref_heading"):
            rec.add(n, rng.standard_normal(rows) * 30)
        rec.meta["csv_decimals"] = dict(DECIMALS)
    rec.meta["sensor"] = "benchmark"
    rec.meta["filter"] = {"a": 1, "b": [1, 2]}
    return rec

def flat(rec):
    # (column names, 1-D float64 columns) of a recording, as the CSV lists them
    cols = [rec.time] + [np.ascontiguousarray(a[:, k]) if a.ndim == 2 else a for a in rec.channels.values()
                         for k in range(a.shape[1] if a.ndim == 2 else 1)]
    return rec.column_names(), cols

def decimals_of(name, dec):
    # the fixed decimals of a CSV column under csv_decimals (None: exact)
    key = "q" if name in ("qw", "qx", "qy", "qz") else ("gyro_bias" if name.startswith("gyro_bias") else name)
    return dec.get(key)

# imports and the compiled kernels' first load are outside the timed part (what is timed is the engine itself)
ti = time.perf_counter()
if "polars" in engine:
    import polars as pl
elif "pyarrow" in engine:
    import pyarrow as pa, pyarrow.csv as pc
else:
    from formats.csv import format_array
    tiny = os.path.join(os.path.dirname(path), f"warm_{os.getpid()}.csv")
    with open(tiny, "w") as f:
        f.write("time,a\n0,1.5\n")
    read_csv(tiny)
    format_array(np.ones((1, 2)), decimals=np.array([3, -1]))
    os.unlink(tiny)
print(f"import {time.perf_counter() - ti:.3f}")
if op == "read":
    hdr = read_header(path)
    t0, c0 = time.perf_counter(), time.process_time()
    if engine == "imutool":
        rec = read_csv(path)
        n = len(rec)
    elif engine == "imutool-stream":
        n = sum(len(c) for c in iter_csv(path, chunk_rows=500_000))
    elif engine == "polars":
        df = pl.read_csv(path, has_header=False, skip_lines=hdr.data_line - 1, comment_prefix="#",
                         schema={c: pl.Float64 for c in hdr.names})
        arrs = {}
        for c in hdr.names:
            arrs[c] = df.get_column(c).fill_null(np.nan).to_numpy(writable=True)
        n = df.height
        del df
    elif engine == "polars-batched":
        lf = pl.scan_csv(path, has_header=False, skip_lines=hdr.data_line - 1, comment_prefix="#",
                         schema={c: pl.Float64 for c in hdr.names})
        n = 0
        for b in lf.collect_batches(chunk_size=500_000):
            arrs = [b.get_column(c).fill_null(np.nan).to_numpy() for c in hdr.names]
            n += b.height
    elif engine == "pyarrow":
        ro = pc.ReadOptions(skip_rows=hdr.data_line - 1, column_names=hdr.names)
        co = pc.ConvertOptions(column_types={c: pa.float64() for c in hdr.names})
        tab = pc.read_csv(path, read_options=ro, convert_options=co)
        arrs = {c: tab.column(c).to_numpy() for c in hdr.names}
        n = tab.num_rows
    elif engine == "pyarrow-stream":
        ro = pc.ReadOptions(skip_rows=hdr.data_line - 1, column_names=hdr.names, block_size=16 << 20)
        co = pc.ConvertOptions(column_types={c: pa.float64() for c in hdr.names})
        n = 0
        for b in pc.open_csv(path, read_options=ro, convert_options=co):
            arrs = [b.column(i).to_numpy(zero_copy_only=False) for i in range(b.num_columns)]
            n += b.num_rows
    dt, dc = time.perf_counter() - t0, time.process_time() - c0
    assert n == rows, (engine, n, rows)
    print(f"{dt:.3f} {dc:.3f}")
    if os.environ.get("CSV_ENGINES_CHECK") and engine in ("polars", "pyarrow"):  # the same doubles, bit for bit
        ref = dict(zip(*flat(read_csv(path)), strict=True))
        assert all(np.array_equal(arrs[c].view(np.uint64), ref[c].view(np.uint64)) for c in hdr.names), engine
else:
    kind = op.split("-")[1]
    rec = recording(kind)
    out = path
    t0, c0 = time.perf_counter(), time.process_time()
    if engine == "imutool":
        write_csv(rec, out)
    else:  # the header by imutool; the rows by the library, fixed decimals by its own rounding, NaN empty
        names, cols = flat(rec)
        dec = rec.meta.get("csv_decimals", {})
        with open(out, "wb") as f:
            f.write(header_text(rec).encode())
            if engine == "polars":
                df = pl.DataFrame(dict(zip(names, cols)))
                rounded = [pl.col(n).round(d) for n in names if (d := decimals_of(n, dec)) is not None]
                if rounded:
                    df = df.with_columns(rounded)
                df.with_columns(pl.all().fill_nan(None)).write_csv(f, include_header=False, null_value="")
            else:
                import pyarrow.compute as pcc
                cols = [a if (d := decimals_of(n, dec)) is None else pcc.round(a, d) for n, a in zip(names, cols)]
                tab = pa.table(dict(zip(names, cols)))
                pc.write_csv(tab, f, write_options=pc.WriteOptions(include_header=False, quoting_style="none"))
    dt, dc = time.perf_counter() - t0, time.process_time() - c0
    print(f"{dt:.3f} {dc:.3f}")
    if os.environ.get("CSV_ENGINES_CHECK"):  # exact round trip of the values (outside the RSS figures)
        back = read_csv(out)
        ch = "gyro" if kind == "input" else "ref_roll"
        assert np.array_equal(back[ch], rec[ch]) and np.array_equal(back.time, rec.time), engine
    os.unlink(out)
"""

READS = ("imutool", "imutool-stream", "polars", "polars-batched", "pyarrow", "pyarrow-stream")
WRITES = (
    ("imutool", "write-input"),
    ("polars", "write-input"),
    ("pyarrow", "write-input"),
    ("imutool", "write-estimate"),
    ("polars", "write-estimate"),
    ("pyarrow", "write-estimate"),
)


def run_rss(engine: str, op: str, path: str, rows: int) -> tuple[float, float, float]:
    """(wall and CPU seconds of the operation, all threads; peak RSS MB of its process, from os.wait4)."""
    p = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(ROOT), engine, op, path, str(rows)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    _, status, ru = os.wait4(p.pid, 0)
    out, err = p.stdout.read(), p.stderr.read()
    if status:
        raise SystemExit(f"{engine} {op} failed:\n{err.decode()[-2000:]}")
    wall, cpu = (float(v) for v in out.decode().splitlines()[1].split())
    return wall, cpu, ru.ru_maxrss / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=2_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--dir", default="/tmp/imutool_csv_engines")
    ap.add_argument("--only", choices=("read", "write"))
    a = ap.parse_args()
    os.makedirs(a.dir, exist_ok=True)
    src = os.path.join(a.dir, f"input_{a.rows}.csv")
    if not os.path.exists(src):
        sys.path.insert(0, str(ROOT))
        import numpy as np

        import formats

        rng = np.random.default_rng(0)
        rec = formats.Recording(np.arange(a.rows) / 200.0)
        for g, s in (("gyro", 0.1), ("accel", 9.8), ("mag", 40.0)):
            rec.add(g, rng.standard_normal((a.rows, 3)) * s)
        rec.meta.update({"sensor": "benchmark", "rate_hz": 200.0, "mounting": [0, 0, 0]})
        formats.write(rec, src)
    cases = [(e, "read", src) for e in READS] if a.only != "write" else []
    if a.only != "read":
        cases += [(e, op, os.path.join(a.dir, f"out_{e}.csv")) for e, op in WRITES]
    res: dict[tuple[str, str], list[tuple[float, float, float]]] = {}
    for r in range(a.repeat):
        for e, op, p in cases:
            res.setdefault((e, op), []).append(run_rss(e, op, p, a.rows))
        print(f"round {r + 1} done (load {os.getloadavg()[0]:.1f})", file=sys.stderr)
    print(f"{a.rows} rows, {a.repeat} rounds, load now {os.getloadavg()[0]:.1f}")
    print(f"{'operation':<16}{'engine':<16}{'best s':>8}{'median s':>10}{'median CPU s':>14}{'peak RSS MB':>13}")
    for (e, op), v in res.items():
        ts = sorted(x[0] for x in v)
        cpu = sorted(x[1] for x in v)[len(v) // 2]
        print(f"{op:<16}{e:<16}{ts[0]:>8.2f}{ts[len(ts) // 2]:>10.2f}{cpu:>14.2f}{max(x[2] for x in v):>13.0f}")


if __name__ == "__main__":
    main()
