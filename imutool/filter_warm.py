"""The filter's kernels for a cold first run, compiled two at a time (:mod:`formats.jit.warm`).

A cold ``imutool filter`` compiles the CSV parser, then the EKF kernel (most of the time), then the gyro check's
kernel and the CSV writer's (and, with ``--smooth``, the RTS pass and the zero-phase low-pass). The command starts
a second process as soon as it knows what it will run (``imutool/cli/filter.py``, before it imports the filter;
``run_filter`` for a library caller), which compiles, in this order:

1. (with a CSV output, the CSV writer's kernel first, see 2.) the EKF's sections (:data:`EKF_SECTIONS`) from the
   last to the first, while the command compiles the parser and
   then types the kernel from the first section on. Each section is cached on its own with the flags it states
   itself (:data:`imutool.attitude.layout.INLINED`), so the command loads what the second process has finished,
   as LLVM bitcode that its kernel inlines as before, and compiles the rest; the two meet in the middle, where
   each waits for a section the other is compiling instead of compiling it too (:mod:`formats.jit.claims`);
2. the kernels the command calls after the EKF: the CSV writer's (for a CSV output) before the sections, the
   others after them in the order the command calls them (:data:`AFTER_THE_EKF`, :data:`SMOOTH_KERNELS` with
   ``--smooth``). Where the two meet among the sections the command is left with the EKF kernel's own part (its
   typing and the whole loop's LLVM, ~2 s), which it compiles while the second process compiles the gyro check
   (~2 s). The command compiles a later kernel itself only after the EKF kernel, while it waits for one the second
   process is compiling (from the last it calls, :func:`formats.jit.claims.while_waiting`). Before (the later
   kernels all after the sections, and the command compiling one where it met the second process), one of them
   came before the EKF kernel's own part on the command's path while the second process had nothing left to do:
   10.3–13.2 s against 8.7–10.6 s of the second process's (2026-12-06, traced cold runs).

The sections of inputs a first run usually has not (GNSS speed or velocity, an external heading) are not compiled
into the default kernel (None arguments, ``imutool/attitude/kernel.py``); an external heading's is listed when
``--heading`` is given. The EKF kernel is the probe (not cached yet = a cold run). An entry is ``(module,
function, argument types)`` in numba's signature syntax (``float64[:, ::1]`` a 2-D C array), in the types the
command calls it with. A section or kernel added, or an argument list changed, must be listed here:
``tests/test_kernel_warm.py`` records a real cold compile and names what is missing or different. A helper that a
section calls is not listed: it compiles with its section, with its own stated flags.
"""

from __future__ import annotations

import subprocess

from formats.jit.warm import CSV_WRITER, Entry, warm_in_background

# the probe: the EKF kernel not in the cache yet = a cold run (found by its cache file's name: this module imports no
# kernel, so that the command can start the second process before it imports the filter, imutool/cli/filter.py)
EKF_KERNEL: Entry = ("imutool.attitude.kernel", "ekf_kernel", "")

_A = "float64[::1]"  # 1-D C array
_M = "float64[:, ::1]"  # 2-D C array
_F = "float64"
_B = "boolean"


def _types(*parts: str) -> str:
    return ", ".join(parts)


_STATE = (_A, _M, _A)  # st, P, prm

# the EKF loop's sections in the order the kernel calls them (imutool/attitude/kernel.py) on the default path: without
# GNSS speed, GNSS velocity or an external heading, whose sections the kernel leaves out (None arguments, pruned)
EKF_SECTIONS: tuple[Entry, ...] = (
    ("imutool.attitude.predict", "_predict", _types(*_STATE, _F, _F, _F, _F, _B)),
    ("imutool.attitude.accel", "_accel_white_noise", _types(_A, _A, _F, _F, _F, _F)),
    ("imutool.attitude.rest", "_rest", _types(*_STATE, _A, _M, *[_F] * 7, "int64")),
    ("imutool.attitude.compensation", "_lever_arm", _types(_A, _A, _A, *[_F] * 7, _B)),
    ("imutool.attitude.accel", "_accel_gate", _types(_A, _A, _M, _F, _F, _F, _F, _B)),
    ("imutool.attitude.accel", "_accel_low_pass", _types(_A, _A, _M, _F, _F, _F, _F, _B, _B)),
    ("imutool.attitude.accel", "_age_low_pass", _types(_A, _M, _F)),
    ("imutool.attitude.accel", "_accel_update", _types(*_STATE, _M, _M, _M, _M, _A, *[_F] * 6, _B, _B, _B)),
    ("imutool.attitude.magnetic", "_mag_sample", _types(*_STATE, _M, *[_F] * 7, _A)),
    ("imutool.attitude.magnetic", "_mag_update", _types(*_STATE, _M, _A, *[_F] * 5, "int64", _A)),
    ("imutool.attitude.kernel", "_outputs", _types(_A, _M, "int64", _M, _M, _M)),
    ("imutool.attitude.kernel", "_self_check", _types(_A, _A, _F, _F)),
)
# an external heading's section (--heading); GNSS speed's and velocity's are compiled by the command when it has them
HEADING_SECTION: Entry = ("imutool.attitude.heading_input", "_heading_input", _types(*_STATE, _M, _A, _F, _F))

AFTER_THE_EKF: tuple[Entry, ...] = (
    (
        "imutool.gyro_check",
        "pair_discrepancy_kernel",
        _types(_A, _M, _M, _M, _F, _F, _M, _F, "int64", _A, _A),
    ),
)

SMOOTH_KERNELS: tuple[Entry, ...] = (
    (
        "imutool.attitude.rts",
        "rts_kernel",
        _types(_A, _M, _M, _M, "float64[:, :, ::1]", *[_F] * 7, _M, _M, "float64[:, :, ::1]"),
    ),
    ("imutool.attitude.smoother", "zero_phase_lp_kernel", _types(_A, _M, _M, _M, _F, _F, _F, _M)),
)


def warm_filter_kernels(
    smooth: bool = False, csv_output: bool = False, heading: bool = False
) -> subprocess.Popen | None:
    """On a cold cache, compile in a second process the CSV writer's kernel with a CSV output, the EKF's sections
    from the last (with ``heading``, an external heading's too), then what the filter needs after the EKF in the
    order it needs it (the gyro check's, the smoother's with ``smooth``)."""
    sections = EKF_SECTIONS[:-2] + ((HEADING_SECTION,) if heading else ()) + EKF_SECTIONS[-2:]
    first = (CSV_WRITER,) if csv_output else ()
    later = AFTER_THE_EKF + (SMOOTH_KERNELS if smooth else ())
    # the command, while it waits for a kernel the second process is compiling (after its EKF kernel), compiles
    # what it needs later from the last it needs (formats.jit.claims): the two take those from opposite ends
    return warm_in_background(
        EKF_KERNEL, first + tuple(reversed(sections)) + later, splits_probe=True, meanwhile=tuple(reversed(later))
    )
