"""Regenerate every file in sample_data/ from the simulator (deterministic): python sample_data/make_sample_data.py"""

from pathlib import Path

import formats
from formats import Recording
from imutool.sim import simulate
from imutool.sim.programmes import write_sample_data

SHIP_KEEP = ("gyro", "accel", "mag", "ref_roll", "ref_pitch")


def write_ship_imu(folder: Path) -> Path:
    """ship_imu.csv: a raw 9-axis IMU on a rolling ship (±15°, 10 s), 5 minutes at 10 Hz, with the true roll and
    pitch (ref_*) — the input of the README's `imutool live --replay` example."""
    rec = simulate("ship-roll", seed=11, duration=300.0, rate_hz=10.0)
    out = Recording(rec.time, meta={k: v for k, v in rec.meta.items() if not isinstance(v, (list, dict))})
    for name in SHIP_KEEP:
        out.add(name, rec[name], rec.units.get(name))
    path = folder / "ship_imu.csv"
    formats.write(out, path)
    return path


if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    write_sample_data(str(here))
    write_ship_imu(here)
    print(f"wrote sample data to {here}")
