"""The filter's kernels for a cold first run, compiled two at a time (:mod:`formats.kernel_warm`).

:data:`EKF_HELPERS` lists the EKF kernel's cached helpers in the order its type inference first reaches them, and
:data:`AFTER_THE_EKF` the kernels a cold ``imutool filter`` compiles after it (the gyro check's, the CSV writer's),
each with the argument types it is called with; :data:`SMOOTH_KERNELS` adds the RTS pass and the zero-phase
low-pass of ``--smooth``. The EKF kernel itself (the probe: not cached yet = a cold run) and the CSV parser (the
first thing the command compiles) are the command's own.

A helper added to the EKF, or a changed argument list, must be listed here with its types (signature syntax:
``float64[:, ::1]`` a 2-D C array): ``tests/test_kernel_warm.py`` records a real cold compile and names what is
missing or different.
"""

from __future__ import annotations

import subprocess

from formats.kernel_warm import Entry, warm_in_background
from imutool.attitude.kernel import ekf_kernel

_A = "float64[::1]"  # 1-D C array
_M = "float64[:, ::1]"  # 2-D C array
_F = "float64"
_COV = "imutool.attitude.covariance"
_UPD = "imutool.attitude.updates"
_KER = "imutool.attitude.kernel"

EKF_HELPERS: tuple[Entry, ...] = (
    (_COV, "_propagate_cov_q", ", ".join([_M] + [_F] * 7)),
    (_COV, "_add_rrt", f"{_M}, int64, int64, {_F}, {_F}, {_F}, {_F}"),
    (_COV, "_propagate_pending", f"{_A}, {_M}, {_A}"),
    (_UPD, "_apply_correction", f"{_A}, {_A}"),
    (_COV, "_reset_cov", f"{_M}, {_A}, {_F}, {_F}, {_F}"),
    (_KER, "_rest_update", f"{_A}, {_M}, {_A}, {_A}, {_M}"),
    (
        _KER,
        "_velocity_aiding",
        ", ".join([_A, _M, _M] + [_F] * 6 + [_A] + [_F] * 4 + ["boolean", "boolean"]),
    ),
    (_KER, "_lever_arm", ", ".join([_A, _A, _A] + [_F] * 7 + ["boolean"])),
    (_KER, "_gnss_force", ", ".join([_A, _M] + [_F] * 6 + ["boolean"] + [_F] * 3)),
    (_COV, "_vertical_forms", f"{_M}, {_F}, {_F}, {_F}"),
    (_COV, "_shear_cov", f"{_M}, {_M}, {_F}, {_M}"),
    (_UPD, "_vec_update", ", ".join([_M] + [_F] * 8 + ["boolean", _A, "boolean", _F])),
    (_COV, "_drop_vertical", ", ".join([_M] + [_F] * 6 + ["boolean", "boolean", _A])),
    (_UPD, "_reset_heading", ", ".join([_A, _M] + [_F] * 5)),
    ("imutool.attitude.magnetic", "_new_field", ", ".join([_A, _M, _A] + [_F] * 5 + ["boolean"] + [_F] * 5)),
    (_UPD, "_heading_update", ", ".join([_M] + [_F] * 5 + [_A, "boolean", _F, _F, _F])),
    (_KER, "_mag_vector_update", ", ".join([_A, _M, _A, _M, _A] + [_F] * 4)),
    (_KER, "_heading_input", ", ".join([_A, _M, _A, _M, _A, _F, _F])),
)

AFTER_THE_EKF: tuple[Entry, ...] = (
    (
        "imutool.gyro_check",
        "pair_discrepancy_kernel",
        ", ".join([_A, _M, _M, _M, _F, _F, _M, _F, "int64", _A, _A]),
    ),
    (
        "formats.csv_engine",
        "format_block",
        f"{_M}, uint64[:, ::1], int64, int64, int64, uint8[::1], int64[:, ::1], int64[::1]",
    ),
)

SMOOTH_KERNELS: tuple[Entry, ...] = (
    (_COV, "_propagate_cov", ", ".join([_M, _M, _F, _F, _F, _M, _M])),
    (
        "imutool.attitude.rts",
        "rts_kernel",
        ", ".join([_A, _M, _M, _M, "float64[:, :, ::1]"] + [_F] * 7 + [_M, _M, "float64[:, :, ::1]"]),
    ),
    ("imutool.attitude.smoother", "zero_phase_lp_kernel", ", ".join([_A, _M, _M, _M] + [_F] * 3 + [_M])),
)


def warm_filter_kernels(smooth: bool = False) -> subprocess.Popen | None:
    """On a cold cache, compile the filter's helpers in a second process while this one compiles (see the top)."""
    return warm_in_background(ekf_kernel, EKF_HELPERS, AFTER_THE_EKF + (SMOOTH_KERNELS if smooth else ()))
