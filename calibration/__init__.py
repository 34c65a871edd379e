"""imutool calibration: magnetometer hard/soft iron, deviation card, gyro/accel bias and scale, Allan noise,
and the calibration file (TOML) applied by every command that reads sensor data. Knows nothing of the CLI.

Magnetometer model, once for all: m_true = A (m_meas − b) (b hard iron µT, A symmetric soft iron).
"""

from .deviation import DeviationCard, fit_deviation
from .file import Calibration, load_calibration, update_calibration
from .magnetometer import MagFit, calibrate_sphere

__all__ = [
    "Calibration",
    "DeviationCard",
    "MagFit",
    "calibrate_sphere",
    "fit_deviation",
    "load_calibration",
    "update_calibration",
]
