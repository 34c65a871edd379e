"""Regenerate every file in sample_data/ from the simulator (deterministic): python sample_data/make_sample_data.py"""

from pathlib import Path

from imutool.sim.programmes import write_sample_data

if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    write_sample_data(str(here))
    print(f"wrote sample data to {here}")
