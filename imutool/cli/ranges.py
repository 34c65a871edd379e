"""The declared range of every numeric option of every command, applied when a command is loaded.

One table instead of ranges scattered over the command modules: each entry is ``(min, max, min_open, max_open)``
(``None`` = unbounded) for a parameter name, optionally qualified by the command path (``"calibrate mag
field_ut"`` wins over ``"field_ut"``). Every float option refuses NaN and ±inf (:class:`FiniteFloat`); an int
option gets :class:`click.IntRange`. ``tests/test_hostile.py`` checks that every numeric option has an entry, so
a new option without a declared range fails the tests. Cross-option rules (start before end) stay in the commands.

Every option bounded below at zero or more (a rate, a duration, a window, a noise, a count) is also bounded above,
at :data:`HUGE` unless its entry says less: a value of 1e300 is a typing error, and squared (a variance) or
multiplied by a rate (an array size) it would overflow or ask for terabytes.
"""

from __future__ import annotations

import click

from imutool.cli.common import FiniteFloat

Bound = tuple[float | None, float | None, bool, bool]

HUGE = 1e9  # the largest value of an option bounded below at ≥ 0 (s, Hz, m/s², counts ...) unless declared less

POS: Bound = (0, None, True, False)  # > 0: rates, durations, noises, cut-offs, sizes
NONNEG: Bound = (0, None, False, False)  # ≥ 0: gates and thresholds where 0 means "off"
ANY: Bound = (None, None, False, False)  # any finite value: times, offsets, priors
FRACTION: Bound = (0, 1, False, False)
ANGLE180: Bound = (-180, 180, False, False)
COUNT1: Bound = (1, None, False, False)

RANGES: dict[str, Bound] = {
    # times and windows (seconds on the recording clock; any finite value, start < end checked by the command)
    "start": ANY,
    "end": ANY,
    "t_start": ANY,
    "t_end": ANY,
    "calibrate accel-bias at": NONNEG,  # s from the recording's start where the bias is taken (None: the last row)
    "time_offset": ANY,
    "with_offsets": ANY,  # --with-offset: a --with file's clock offset (s)
    "ref_with_offsets": ANY,  # --ref-with-offset: the same for a --ref-with file of the reference
    # sizes and counts
    "chunk_rows": COUNT1,
    "header_rows": (1, 1000, False, False),
    "ref_header_rows": (1, 1000, False, False),
    "update_every": (0, 1_000_000, False, False),
    "per_decade": (1, 1000, False, False),
    "grid_bands": (2, 90, False, False),
    "max_points": (2, None, False, False),
    "dpi": (10, 2400, False, False),
    "min_cycles": COUNT1,
    "min_steps_per_side": COUNT1,
    "min_headings": (2, None, False, False),
    "min_poses": COUNT1,
    "harmonics": (1, 20, False, False),
    "seed": (0, 2**32 - 1, False, False),
    "baud": (50, 10_000_000, False, False),
    "unit": (0, 247, False, False),
    "mag_gain": (0, 8, False, False),
    # rates, durations, cut-offs (zero is meaningless)
    "rate_hz": (0, 100_000, True, False),
    "input_rate_hz": (0, 100_000, True, False),  # --rate of a CSV without a time column
    "ref_rate_hz": (0, 100_000, True, False),  # --ref-rate: the same for a reference file
    "nmea_rate": (0, 100_000, True, False),
    "cutoff": POS,
    "delayed_cutoff": POS,
    "cutoff_ratio": (0, 1, True, True),
    "fmin": POS,
    "fmax": POS,
    "bandwidth": POS,
    "window_s": POS,
    "height_window_s": POS,  # heave from a GNSS height: the detrending window (main had no entry)
    "hop_s": POS,
    "min_window_s": POS,
    "window_g_s": POS,
    "window_a_s": POS,
    "centre_window_s": POS,
    "max_period_s": POS,
    "duration": POS,
    "live speed": (0, 10_000, False, False),  # replay speed (× real time; 0: as fast as it goes)
    "live aux_baud": (50, 10_000_000, False, False),
    "live rotate_s": (1, None, False, False),  # s between new recording files
    "live settle_s": (0, 86_400, False, False),  # s of start-up with status V
    "replug_every": POS,
    "start_delay": NONNEG,
    "align_window": POS,
    "align_guard": NONNEG,
    "min_rest_s": NONNEG,
    "min_duration_s": NONNEG,
    "step_min_s": POS,
    "drift_min_s": POS,
    "max_lag_s": (0, 3600, False, False),  # a constant lag search of ± an hour; more is a unit error
    "max_lag": (0, 3600, False, False),
    "stream_mb": NONNEG,
    # noises and sigmas (a zero noise makes a filter singular)
    "gyro_noise": POS,
    "accel_noise": POS,
    "mag_noise": POS,
    "meas_noise": POS,
    "residual_noise": POS,
    "zupt_sigma": POS,
    "height_sigma": POS,
    "zaru_sigma": POS,
    "sigma_a": POS,
    "sigma_g": POS,
    "noise": POS,
    "rate_rw": NONNEG,
    "bias_rw": NONNEG,
    "gyro_scale_noise": NONNEG,
    "comp_q": NONNEG,
    "comp_r": POS,
    # gates, thresholds, gains (0 = off where the help says so)
    "accel_noise_gain": NONNEG,
    "accel_lp_tau": NONNEG,
    "accel_gate": NONNEG,
    "accel_nis_gate": NONNEG,
    "accel_adapt": NONNEG,
    "mag_norm_gate": NONNEG,
    "mag_dip_gate": (0, 90, False, False),
    "rest_time": NONNEG,
    "rest_gyro": NONNEG,
    "rest_accel": NONNEG,
    "gap_factor": (1, None, True, False),
    "gamma": POS,
    "b_g": POS,
    "b_a": POS,
    "gyro_std_deg": POS,
    "accel_std": POS,
    "tilt_gain": NONNEG,
    "hysteresis_deg": NONNEG,
    "hysteresis_frac": FRACTION,  # roll: auto hysteresis = this × the roll's RMS
    "hysteresis_min_deg": NONNEG,
    "smooth_frac": (0, 1, False, True),  # roll: detection smoothing, a fraction of the spectral peak period
    "disagree_frac": POS,  # roll: spread of the three period estimates that warns
    "refine_frac": FRACTION,
    "step_band_deg": POS,
    "turn_min_dps": POS,
    "min_temp_range": NONNEG,
    "min_speed": NONNEG,
    "min_coverage": FRACTION,
    "corrupt": FRACTION,
    # tolerances of the reports (a negative tolerance cannot be met)
    "angle_floor": NONNEG,
    "angle_pct": (0, 100, False, False),
    "period_floor": NONNEG,
    "period_pct": (0, 100, False, False),
    "static_limit": NONNEG,
    # angles
    "variation": ANGLE180,
    "variation_deg": ANGLE180,
    "deviation_deg": ANGLE180,
    "correction_deg": ANGLE180,
    "heading_deg": (-360, 360, False, False),
    "min_span": (0, 360, True, False),
    "turns_deg": POS,
    "latitude": (-90, 90, False, False),
    # physical quantities
    "field_ut": (0, 10_000, True, False),
    "horizontal_field": (0, 10_000, True, False),
    "bz_prior": ANY,
    "a33_prior": POS,
    "gravity": (9.7, 9.9, False, False),
    "height": (-11_000, 100_000, False, False),
    # deviation card, heave NMEA, roll events
    "max_deviation": POS,
    "nmea_baud": (50, 10_000_000, False, False),
    "threshold_deg": POS,
    "merge_gap_s": NONNEG,
    "hour_s": POS,
    "tuning_tol": POS,
    "min_growth": NONNEG,
    "min_amplitude_deg": NONNEG,
    "min_lock": FRACTION,
    "settle_fraction": (0, 1, True, False),  # heave: settled while heave_std ≤ this × the significant heave
    # order of a Butterworth filter (higher orders are numerically useless at sensor rates)
    "order": (1, 8, False, False),
    "heave order": (3, 8, False, False),
}


def _range_type(param: click.Parameter, bound: Bound) -> click.ParamType:
    lo, hi, lo_open, hi_open = bound
    if isinstance(param.type, click.types.IntParamType):
        return click.IntRange(
            None if lo is None else int(lo), None if hi is None else int(hi), min_open=lo_open, max_open=hi_open
        )
    return FiniteFloat(lo, hi, min_open=lo_open, max_open=hi_open)


def _cap(param: click.Parameter) -> None:
    """An option bounded below at ≥ 0 and not above gets the upper bound :data:`HUGE`."""
    t = param.type
    if isinstance(t, (click.IntRange, click.FloatRange)) and t.max is None and t.min is not None and t.min >= 0:
        t.max = int(HUGE) if isinstance(t, click.IntRange) else HUGE
        t.max_open = False


def is_numeric(param: click.Parameter) -> bool:
    return isinstance(param.type, (click.types.IntParamType, click.types.FloatParamType))


def declared(param: click.Parameter, path: str) -> bool:
    """True when a numeric option has a range: in the table, or a bounded IntRange/FiniteFloat of its own."""
    t = param.type
    own = isinstance(t, (click.IntRange, FiniteFloat)) and (t.min is not None or t.max is not None)
    return own or bound_for(path, param.name or "") is not None


def bound_for(path: str, name: str) -> Bound | None:
    """The declared range of option ``name`` of command ``path`` (e.g. 'heave', 'calibrate mag')."""
    words = path.split()
    for i in range(len(words)):
        key = " ".join(words[i:] + [name])
        if key in RANGES:
            return RANGES[key]
    return RANGES.get(name)


def apply_ranges(cmd: click.Command, path: str | None = None) -> click.Command:
    """Give every numeric option of ``cmd`` (and its sub-commands) its declared range; floats refuse NaN/inf."""
    path = path or cmd.name or ""
    if getattr(cmd, "_imutool_ranges", False):
        return cmd
    for p in cmd.params:
        if not is_numeric(p):
            continue
        if isinstance(p.type, (FiniteFloat, click.IntRange)):
            pass  # declared by the command itself
        elif isinstance(p.type, click.FloatRange):  # declared, but click's FloatRange lets NaN through
            t = p.type
            p.type = FiniteFloat(t.min, t.max, min_open=t.min_open, max_open=t.max_open, clamp=t.clamp)
        else:
            bound = bound_for(path, p.name or "")
            if bound is not None:
                p.type = _range_type(p, bound)
            elif isinstance(p.type, click.types.FloatParamType):
                p.type = FiniteFloat()
        _cap(p)
    if isinstance(cmd, click.Group):
        for name, sub in cmd.commands.items():
            apply_ranges(sub, f"{path} {name}")
    cmd._imutool_ranges = True  # type: ignore[attr-defined]
    return cmd
