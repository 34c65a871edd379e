"""The filter's kernels for a cold first run, compiled two at a time (:mod:`formats.kernel_warm`).

A cold ``imutool filter`` compiles the CSV parser, then the EKF kernel (most of the time: its sections and helpers
are compiled into it, with its flags), then the gyro check's kernel and the CSV writer's (and, with ``--smooth``,
the RTS pass and the zero-phase low-pass). :data:`AFTER_THE_EKF`, ``CSV_WRITER`` (for a CSV output) and
:data:`SMOOTH_KERNELS` list those later kernels with the argument types they are called with, so that a second
process compiles them while the command compiles the EKF. The EKF kernel is the probe (not cached yet = a cold run).

Only kernels called from Python belong here: a helper compiled on its own would not get the flags its caller
passes down (numba inherits ``fastmath``, ``error_model``, ``_nrt`` and ``forceinline``) and numba's cache does not
key on flags. A kernel added to the command, or a changed argument list, must be listed here with its types
(signature syntax: ``float64[:, ::1]`` a 2-D C array): ``tests/test_kernel_warm.py`` records a real cold compile
and names what is missing or different."""

from __future__ import annotations

import subprocess

from formats.kernel_warm import CSV_WRITER, Entry, warm_in_background
from imutool.attitude.kernel import ekf_kernel

_A = "float64[::1]"  # 1-D C array
_M = "float64[:, ::1]"  # 2-D C array
_F = "float64"

AFTER_THE_EKF: tuple[Entry, ...] = (
    (
        "imutool.gyro_check",
        "pair_discrepancy_kernel",
        ", ".join([_A, _M, _M, _M, _F, _F, _M, _F, "int64", _A, _A]),
    ),
)

SMOOTH_KERNELS: tuple[Entry, ...] = (
    (
        "imutool.attitude.rts",
        "rts_kernel",
        ", ".join([_A, _M, _M, _M, "float64[:, :, ::1]"] + [_F] * 7 + [_M, _M, "float64[:, :, ::1]"]),
    ),
    ("imutool.attitude.smoother", "zero_phase_lp_kernel", ", ".join([_A, _M, _M, _M] + [_F] * 3 + [_M])),
)


def warm_filter_kernels(smooth: bool = False, csv_output: bool = False) -> subprocess.Popen | None:
    """On a cold cache, compile the kernels the filter needs after the EKF in a second process (see the top):
    the gyro check's, the CSV writer's with a CSV output, the smoother's with ``smooth``."""
    later = AFTER_THE_EKF + ((CSV_WRITER,) if csv_output else ()) + (SMOOTH_KERNELS if smooth else ())
    return warm_in_background(ekf_kernel, later)
