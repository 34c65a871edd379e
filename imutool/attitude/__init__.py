"""The attitude filter: a quaternion EKF with gyro-bias states, its RTS and zero-lag smoothers, and self-checks.

One concept per module (docs/architecture.md, "The attitude package"):

- :mod:`~imutool.attitude.param_table` — :data:`PARAMS`: every tuning constant in one table (default, unit, range,
  meaning, how it enters the kernel); :mod:`~imutool.attitude.params` — :class:`EkfParams` (made from it),
  :class:`EkfCoefficients` (derived once per run from the parameters and the sample interval), the versioned TOML
  and its :data:`MIGRATIONS`.
- :mod:`~imutool.attitude.layout` — the state vector's slots (``S_*``), the parameter vector's (``P_*``) and the
  per-sample flag bits (``F_*``).
- :mod:`~imutool.attitude.kernel` — the per-sample loop (numba; the filter's equations are in its docstring): one
  call per section in a written order — :mod:`~imutool.attitude.predict` (gyro), :mod:`~imutool.attitude.accel`
  (noise level, gate, quasi-inertial low-pass, update), :mod:`~imutool.attitude.rest`,
  :mod:`~imutool.attitude.compensation` (lever arm, GNSS turn, velocity aiding), :mod:`~imutool.attitude.magnetic`
  (gates, new field, update), :mod:`~imutool.attitude.heading_input` (a gyrocompass), then the outputs and the
  per-sample self-check; the algebra in :mod:`~imutool.attitude.covariance` and :mod:`~imutool.attitude.updates`,
  the low-passes in :mod:`~imutool.attitude.lowpass`, the shared :mod:`imutool.quaternion` steps.
- :mod:`~imutool.attitude.run` — :func:`run_ekf` over arrays (initial state, chunks, :class:`AttitudeResult`).
- :mod:`~imutool.attitude.rts`, :mod:`~imutool.attitude.smoother` — the RTS pass and the zero-lag smoother.
- :mod:`~imutool.attitude.selfcheck` — :class:`SelfCheck`, the one accumulator of the self-check reports
  (inconsistency, heading, new field, tilt, GNSS, heading source and lag, gyro scale) for the memory and streamed
  runs, :func:`output_metadata`, and the per-sample flags by name (:class:`SampleFlag`).
- :mod:`~imutool.attitude.motion` — ship or hand-held, told from the gyro (the low-pass's delay);
  :mod:`~imutool.attitude.lever_estimate` — a ship's lever arm from its motion when none is given.
- :mod:`~imutool.attitude.recording` — :func:`ekf_recording`: the filter over a Recording, output channels.

Frames and units: body FRD, world NED, q = [w, x, y, z] body→NED; gyro rad/s, accel m/s², mag µT, time s.
"""

from imutool.attitude.layout import (
    F_ACC_REJ,
    F_ACC_USED,
    F_HDG_USED,
    F_INCONSISTENT,
    F_MAG_NEW,
    F_MAG_REJ,
    F_MAG_USED,
    F_REST,
    STATE_SIZE,
)
from imutool.attitude.param_table import PARAMS, Param, ToKernel, params_markdown
from imutool.attitude.params import (
    MIGRATIONS,
    PARAM_DOC,
    PARAMS_VERSION,
    EkfCoefficients,
    EkfParams,
    Migration,
    ParamsFile,
    params_from_options,
    read_params_file,
)
from imutool.attitude.recording import (
    OUTPUT_DECIMALS,
    available_memory,
    carry_labels,
    check_smoother_memory,
    ekf_recording,
    quat_error_metrics,
    result_recording,
)
from imutool.attitude.rts import rts_smooth
from imutool.attitude.run import AttitudeResult, EkfStepper, euler_std, initial_state, mag_interval, nominal_dt, run_ekf
from imutool.attitude.selfcheck import (
    FlagSpans,
    SampleFlag,
    SelfCheck,
    SelfCheckReport,
    gnss_heading_check,
    heading_check,
    heading_source_report,
    inconsistency_report,
    new_field_check,
    output_metadata,
    self_check,
    tilt_check,
)
from imutool.attitude.smoother import zero_lag_smooth

__all__ = [
    "F_ACC_REJ",
    "F_ACC_USED",
    "F_HDG_USED",
    "F_INCONSISTENT",
    "F_MAG_NEW",
    "F_MAG_REJ",
    "F_MAG_USED",
    "F_REST",
    "MIGRATIONS",
    "OUTPUT_DECIMALS",
    "PARAMS",
    "PARAMS_VERSION",
    "PARAM_DOC",
    "STATE_SIZE",
    "AttitudeResult",
    "EkfCoefficients",
    "EkfParams",
    "FlagSpans",
    "Migration",
    "Param",
    "ParamsFile",
    "SampleFlag",
    "SelfCheck",
    "SelfCheckReport",
    "ToKernel",
    "available_memory",
    "carry_labels",
    "check_smoother_memory",
    "ekf_recording",
    "euler_std",
    "gnss_heading_check",
    "heading_check",
    "heading_source_report",
    "inconsistency_report",
    "initial_state",
    "mag_interval",
    "new_field_check",
    "nominal_dt",
    "output_metadata",
    "params_from_options",
    "params_markdown",
    "quat_error_metrics",
    "read_params_file",
    "result_recording",
    "rts_smooth",
    "run_ekf",
    "EkfStepper",
    "self_check",
    "tilt_check",
    "zero_lag_smooth",
]
