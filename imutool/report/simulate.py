"""Former home of the reports' simulated test programmes, kept so ``from imutool.report.simulate import ...`` keeps
working.

The code lives in :mod:`imutool.sim.programmes` (the simulator's one home, ``imutool/sim/``); import from there.
"""

from __future__ import annotations

from imutool.sim.programmes import (
    DEFAULT_DYNAMIC,
    DEFAULT_STEPS,
    SAMPLE_HEADING_ERRORS,
    SAMPLE_INCLINOMETER_ERRORS,
    SAMPLE_LATERAL_ACCEL_MS2,
    heading_programme,
    heading_test,
    inclinometer_programme,
    inclinometer_test,
    irregular_roll,
    sea_pair,
    write_sample_data,
    write_steps_csv,
)

__all__ = [
    "DEFAULT_DYNAMIC",
    "DEFAULT_STEPS",
    "SAMPLE_HEADING_ERRORS",
    "SAMPLE_INCLINOMETER_ERRORS",
    "SAMPLE_LATERAL_ACCEL_MS2",
    "heading_programme",
    "heading_test",
    "inclinometer_programme",
    "inclinometer_test",
    "irregular_roll",
    "sea_pair",
    "write_sample_data",
    "write_steps_csv",
]
