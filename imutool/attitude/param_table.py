"""The EKF's tuning constants as one table, :data:`PARAMS`: name, default, unit, range, one-line meaning, and how
each enters the kernel's parameter vector (:class:`ToKernel`, the ``P_*`` slot). Made from it:
:class:`~imutool.attitude.params.EkfParams` (its fields), :data:`PARAM_DOC` (the saved TOML, ``--param``
messages), :func:`params_markdown` (docs/attitude.md) and the kernel vector
(:meth:`~imutool.attitude.params.EkfCoefficients.kernel_vector`). To add a parameter: one row here (and, if the
kernel reads it, a ``P_*`` slot in :mod:`~imutool.attitude.layout`)."""

from __future__ import annotations

import enum
from typing import Any, NamedTuple

from imutool.attitude.layout import (
    N_PARAMS,
    P_ACC_ADAPT,
    P_ACC_BIAS_DEV,
    P_ACC_GATE,
    P_ACC_HEAD,
    P_ACC_LAG,
    P_ACC_NIS,
    P_ACC_NOISE,
    P_ACC_NOISE_RISE,
    P_ACC_SOFT,
    P_ACC_TAU,
    P_ACC_VBIAS,
    P_ACC_WN_GAIN,
    P_BIAS_HOLD,
    P_BIAS_MAX,
    P_BIAS_RW,
    P_GAP_DT,
    P_GAP_RATE,
    P_GRAVITY,
    P_GYRO_NOISE,
    P_GYRO_PREV_W,
    P_GYRO_SCALE,
    P_HDG_EVERY,
    P_HDG_NOISE,
    P_HEAD_SCALE,
    P_LEVER_TAU,
    P_MAG_BIAS,
    P_MAG_BIAS_GATE,
    P_MAG_DIP_GATE,
    P_MAG_DIP_SOFT,
    P_MAG_HOLD,
    P_MAG_NEW_FIRST,
    P_MAG_NEW_RATE,
    P_MAG_NEW_TIME,
    P_MAG_NOISE,
    P_MAG_NORM_GATE,
    P_MAG_NORM_SOFT,
    P_MAG_REF_TAU,
    P_NIS_LIMIT,
    P_NIS_TAU,
    P_REJ_TIMEOUT,
    P_REST_ACC,
    P_REST_GYRO,
    P_REST_NOISE,
    P_REST_TIME,
    P_SHOCK_MAX,
    P_TILT_LIM,
    P_TILT_WIN,
)


class ToKernel(enum.Enum):
    """How a parameter enters the kernel's parameter vector (``prm[P_*]``)."""

    VALUE = "as is"
    RADIANS = "in radians (the parameter is in degrees)"
    FLAG = "as 1.0 / 0.0 (a true/false parameter)"
    DERIVED = "through EkfCoefficients (with the sample interval) or as a kernel argument"
    UNUSED = "not at all (the initial state, the smoother, the reports or the input use it)"


VALUE, RADIANS, FLAG, DERIVED, UNUSED = ToKernel


class Param(NamedTuple):
    """One row of :data:`PARAMS`: a tuning constant of the EKF."""

    name: str
    default: Any  # float, int, bool, str (a choice) or a tuple of 3 floats; its type is the field's
    unit: str  # the unit (a choice: the choices, "a|b|c"; a switch: "bool")
    range: tuple[float, float]  # lowest and highest allowed value (choices and switches: not a number range)
    to_kernel: ToKernel
    slot: int | None  # the P_* index in the kernel's parameter vector (VALUE, RADIANS, FLAG), else None
    doc: str  # one line: what it does, and what 0 means where 0 switches it off


# Every tuning constant of the EKF, in one place. The defaults were chosen on all 16 shared BROAD trials and the
# simulator, never on one file (docs/attitude.md). The order is the dataclass's (and so the order of the
# parameters in the output metadata, the saved TOML and the lists in messages).
# fmt: off
# one row per parameter: name, default, unit, (lowest, highest) allowed, how it enters the kernel, its P_* slot, and
# its meaning in one line
PARAMS: tuple[Param, ...] = (
    Param("gyro_noise", 0.001, "rad/s/√Hz", (1e-7, 1.0), VALUE, P_GYRO_NOISE,
          "gyro white-noise density: process noise of the attitude"),
    Param("gyro_scale_noise", 0.01, "1", (0.0, 1.0), VALUE, P_GYRO_SCALE,
          "rate-proportional process noise of the tilt (across the world vertical): the attitude uncertainty that "
          "gyro scale-factor and misalignment errors add while the body turns (0: off)"),
    Param("heading_scale_noise", 0.0005, "1", (0.0, 1.0), VALUE, P_HEAD_SCALE,
          "rate-proportional process noise about the world vertical only: the heading uncertainty that gyro "
          "scale-factor errors add while the body turns (gravity corrects the tilt part; 0: off)"),
    Param("bias_rw", 2e-05, "rad/s/√s", (0.0, 1.0), VALUE, P_BIAS_RW,
          "gyro bias random walk: process noise of the bias"),
    Param("accel_noise", 0.03, "rad", (1e-5, 3.0), VALUE, P_ACC_NOISE,
          "σ floor of the normalised accelerometer direction, per sample (an update of n samples uses σ²/n)"),
    Param("accel_noise_gain", 4.0, "1", (0.0, 100.0), VALUE, P_ACC_WN_GAIN,
          "σ² += (gain × learned accelerometer white-noise σ / g)²"),
    Param("accel_noise_rise_time", 300.0, "s", (0.0, 1e6), VALUE, P_ACC_NOISE_RISE,
          "the learned accelerometer white noise is a sensor property: its floor follows the 10-s mean down at once"
          " and up with this time constant, so the jerk of a spell of fast motion is not taken for sensor noise (0:"
          " the 10-s mean itself)"),
    Param("accel_lp_tau", 2.5, "s", (0.0, 100.0), VALUE, P_ACC_TAU,
          "delay of the specific force's low-pass in the quasi-inertial frame (second-order Butterworth, cut-off "
          "√2/τ rad/s; 0: raw accelerometer, as in the paper)"),
    Param("motion", "auto", "auto|ship|handheld", (0, 0), UNUSED, None,
          "the platform's motion (imutool/attitude/motion.py): ship takes ship_lp_tau as the low-pass, handheld "
          "accel_lp_tau; auto tells them apart from the gyro (a ship: rates below 30 °/s, 90 % of the motion below "
          "0.5 Hz)"),
    Param("ship_lp_tau", 5.0, "s", (0.0, 100.0), UNUSED, None,
          "the low-pass's delay on ship motion (motion ship, or auto on a ship): long against the wave band — "
          "a sway at 6 s attenuated 14×, at 10 s 5× — and short against the gyro bias's drift"),
    Param("lever_arm_estimate", True, "bool", (0, 1), UNUSED, None,
          "on ship motion with no lever arm given, the sensor's lever arm from the centre of rotation is estimated "
          "from the first ten minutes and used (imutool/attitude/lever_estimate.py; false: none, as before)"),
    Param("smoother_lp_tau", 3.0, "s", (0.0, 100.0), UNUSED, None,
          "delay of the smoother's low-pass of the specific force, run forwards and backwards (no lag: a longer τ "
          "costs it no delay; offline VQF's 3 s) (0: accel_lp_tau)"),
    Param("accel_lp_lag", True, "bool", (0, 1), FLAG, P_ACC_LAG,
          "the low-passed measurement lags a gyro-bias error by the low-pass's delay: H holds that term (false: H "
          "sees the tilt only)"),
    Param("accel_gate", 0.0, "m/s^2", (0.0, 1000.0), VALUE, P_ACC_GATE,
          "shock gate: accelerometer samples with | |a| − g | above this are skipped for at most shock_max s (0: "
          "off)"),
    Param("accel_nis_gate", 0.0, "1", (0.0, 1e6), VALUE, P_ACC_NIS,
          "skip accelerometer updates whose NIS exceeds this (0: off)"),
    Param("accel_nis_soft", False, "bool", (0, 1), FLAG, P_ACC_SOFT,
          "above accel_nis_gate inflate R by NIS/gate instead of skipping"),
    Param("accel_adapt", 0.0, "m/s^2", (0.0, 1000.0), VALUE, P_ACC_ADAPT,
          "accelerometer σ × √(1 + (| |a| − g | / this)²) (0: off)"),
    Param("shock_max", 0.2, "s", (0.0, 1000.0), VALUE, P_SHOCK_MAX,
          "a shock is at most this long: beyond accel_gate for longer, the acceleration is sustained and the "
          "accelerometer is used again (low-passed), never coasted on; the gyro bias does not learn from it either "
          "way (bias_hold)"),
    Param("reject_timeout", 3.0, "s", (0.01, 10000), VALUE, P_REJ_TIMEOUT,
          "a rejected accelerometer is forced back in after this long"),
    Param("accel_bias_dev", 0.0, "m/s^2", (0.0, 1000.0), VALUE, P_ACC_BIAS_DEV,
          "no gyro-bias learning from the accelerometer while | |a| − g | exceeds this, and for bias_hold s after "
          "(0: always learn)"),
    Param("bias_hold", 1.0, "s", (0.0, 1000.0), VALUE, P_BIAS_HOLD,
          "hold-off after a large | |a| − g | before the bias learns again"),
    Param("bias_max", 0.0, "rad/s", (0.0, 10.0), VALUE, P_BIAS_MAX,
          "bound on each gyro-bias component (0: none)"),
    Param("accel_vertical_bias", False, "bool", (0, 1), FLAG, P_ACC_VBIAS,
          "accelerometer updates may correct the gyro-bias component about the world vertical (which gravity does "
          "not observe; false: only the heading and rest detection learn it)"),
    Param("accel_heading", False, "bool", (0, 1), FLAG, P_ACC_HEAD,
          "accelerometer updates may move heading through cross-covariances (false: they correct inclination only, "
          "as gravity observes no heading)"),
    Param("mag_disturbance_hold", 0.5, "s", (0.0, 1000.0), VALUE, P_MAG_HOLD,
          "the magnetic de-weighting follows the largest recent deviation (norm, dip, a gate rejection), decaying "
          "with this time constant, so samples that pass by chance inside a disturbance stay de-weighted (0: per "
          "sample)"),
    Param("mag_reference_tau", 3600.0, "s", (0.0, 1e6), VALUE, P_MAG_REF_TAU,
          "the reference norm and dip the magnetometer's gates compare with: the mean of the accepted field, a "
          "running mean over the first this-many seconds, then forgetting with this time constant (the earth's "
          "field changes only as the vessel moves over it; 0: the first sample, for the whole run)"),
    Param("mag_new_time", 20.0, "s", (0.0, 1e6), VALUE, P_MAG_NEW_TIME,
          "no lock-out of the magnetometer: a field its gates reject, but which stays within those gates of itself "
          "(homogeneous) for this long while the body turns, becomes the new reference (the sensor moved, or the "
          "field at the start was the disturbed one; VQF's magNewTime; 0: never)"),
    Param("mag_new_min_rate", 20.0, "deg/s", (0.0, 10000), RADIANS, P_MAG_NEW_RATE,
          "... only time while the body turns faster than this counts: a magnet riding with the sensor changes the "
          "field's norm and dip as the body turns, a new homogeneous field does not (VQF's magNewMinGyr; 0: any "
          "time counts, a still sensor's too, so a magnet held beside it becomes the reference)"),
    Param("mag_new_first_time", 5.0, "s", (0.0, 1e6), VALUE, P_MAG_NEW_FIRST,
          "... this long instead while the reference is not yet confirmed (its own field has not yet held this long"
          " while the body turned: the field where a recording starts may be the disturbed one; VQF's "
          "magNewFirstTime; 0: the start's field counts as confirmed)"),
    Param("mag_heading_density", 1.2, "deg*sqrt(s)", (0.01, 100.0), DERIVED, None,
          "σ of the magnetic heading as a noise density: σ per sample = this / √dt, so the heading's time constant "
          "(≈ radians(this) / gyro_noise ≈ 21 s) is the same at any rate ('full' mode: of m̂, rad; an update of n "
          "samples uses σ²/n)"),
    Param("mag_heading_floor_deg", 5.0, "deg", (0.0, 180.0), DERIVED, None,
          "... and at least this per sample: one sample's own white noise (≈ 1.5 µT on a 17 µT horizontal field), "
          "which a slow magnetometer's density alone would under-state"),
    Param("mag_noise_deg", 0.0, "deg", (0.0, 180.0), DERIVED, None,
          "σ of the magnetic heading per sample, pinned whatever the rate (0: from mag_heading_density; files saved"
          " before it existed pin 20; else at least 0.01)"),
    Param("heading_input_noise_deg", 1.0, "deg", (0.001, 180.0), RADIANS, P_HDG_NOISE,
          "σ of an external true heading per update (gyrocompass HDT/THS, channel heading_true); with one, the "
          "magnetometer is not used"),
    Param("heading_input_interval", 1.0, "s", (0.0, 3600.0), VALUE, P_HDG_EVERY,
          "the external heading is used at most once per this interval: a gyrocompass's errors are correlated over "
          "seconds, and an interpolated or held column must not count each IMU sample as an independent fix (0: "
          "every sample)"),
    Param("heading_input_latency", 0.0, "s", (0.0, 10.0), UNUSED, None,
          "delay of the external heading: a fix stamped t is the heading at t − latency (a gyrocompass's HDT is "
          "often 0.1–1 s late; at 3 °/s 0.5 s is 1.5° of heading); the heading is read that much later"),
    Param("mag_norm_gate", 0.15, "1", (0.0, 10.0), VALUE, P_MAG_NORM_GATE,
          "skip mag when | |m|/m_ref − 1 | exceeds this fraction (0: off)"),
    Param("mag_dip_gate_deg", 10.0, "deg", (0.0, 90.0), RADIANS, P_MAG_DIP_GATE,
          "skip mag when its dip departs from the reference by more (0: off)"),
    Param("mag_norm_soft", 0.05, "1", (0.0, 10.0), VALUE, P_MAG_NORM_SOFT,
          "mag σ² × (1 + (norm deviation / this)²): de-weighting (0: off)"),
    Param("mag_dip_soft_deg", 5.0, "deg", (0.0, 90.0), RADIANS, P_MAG_DIP_SOFT,
          "mag σ² × (1 + (dip deviation / this)²): de-weighting (0: off)"),
    Param("mag_bias", True, "bool", (0, 1), FLAG, P_MAG_BIAS,
          "magnetic heading updates may correct the gyro bias"),
    Param("mag_bias_gate", 3.0, "1", (0.0, 1e6), VALUE, P_MAG_BIAS_GATE,
          "... only from heading innovations within this many σ (σ² = the heading's variance + the magnetometer's "
          "undisturbed σ² per update): a heading off by more (a wrong start, a field the gates pass) is an error of"
          " the heading, not of the gyro, so the bias is left as it is (a Schmidt update; 0: always; mag_mode "
          "heading only, the 'full' vector update is not gated)"),
    Param("gravity", 9.80665, "m/s^2", (9.7, 9.9), VALUE, P_GRAVITY,
          "local gravity"),
    Param("rest_gyro", 0.05, "rad/s", (0.0, 10.0), VALUE, P_REST_GYRO,
          "rest: |ω − b| below this on every axis ..."),
    Param("rest_accel", 0.3, "m/s^2", (0.0, 100.0), VALUE, P_REST_ACC,
          "... and | |a| − g | below this ..."),
    Param("rest_time", 1.0, "s", (0.0, 10000), VALUE, P_REST_TIME,
          "... for this long (0: no rest detection)"),
    Param("rest_noise", 0.05, "rad/s", (1e-6, 10.0), VALUE, P_REST_NOISE,
          "σ of the zero-rate pseudo-measurement at rest, per sample"),
    Param("gap_factor", 5.0, "1", (1.0, 1e6), DERIVED, None,
          "a time step longer than this × the median step is a gap"),
    Param("gap_rate_sigma", 0.2, "rad/s", (0.0, 100.0), VALUE, P_GAP_RATE,
          "attitude variance growth over a gap: (σ · gap)²"),
    Param("gyro_integration", "rectangular", "rectangular|trapezoid", (0, 0), DERIVED, None,
          "rate over a step: ω_k or ½(ω_{k−1} + ω_k)"),
    Param("update_every", 0, "samples", (0, 1e6), DERIVED, None,
          "covariance propagation + measurement updates every N samples (paper: 40); 0: N from update_rate_hz. The "
          "measurement σ stay per sample (an update stands for the n usable samples since that sensor's last one: R"
          " = σ²/n), so N changes the speed, not the filter"),
    Param("update_rate_hz", 50.0, "Hz", (0.0, 1e6), DERIVED, None,
          "with update_every 0: updates at least this often, every N = ⌊sample rate / this⌋ samples (1 with the raw"
          " accelerometer, accel_lp_tau 0; 0: every sample)"),
    Param("mag_mode", "heading", "heading|full|off", (0, 0), DERIVED, None,
          "magnetometer use: heading only (never touches roll/pitch), the paper's full 3-D vector, or none"),
    Param("nis_window", 10.0, "s", (0.0, 10000), VALUE, P_NIS_TAU,
          "self-check window: mean normalised innovation squared per degree of freedom over about this long (0: "
          "off)"),
    Param("nis_limit", 3.0, "1", (0.0, 1e6), VALUE, P_NIS_LIMIT,
          "self-check: samples whose windowed NIS exceeds this are flagged inconsistent (0: off)"),
    Param("tilt_check_window", 20.0, "s", (0.0, 10000), VALUE, P_TILT_WIN,
          "self-check of the vertical: the specific force in the world frame, low-passed over about this long (two "
          "stages of half of it), must point straight up, as a bounded velocity keeps its mean vertical (0: off)"),
    Param("tilt_check_deg", 3.0, "deg", (0.0, 90.0), RADIANS, P_TILT_LIM,
          "... samples where it tilts from the estimate's vertical by more than √(this² + (3 σ)²), σ² = the "
          "estimate's roll + pitch variance, are flagged inconsistent: a gyro in the wrong unit or scale, a "
          "reversed axis, an acceleration the filter was not told of"),
    Param("mag_check_time", 60.0, "s", (0.0, 1e6), UNUSED, None,
          "self-check of the heading: warn where the magnetometer was rejected for longer than this (the heading "
          "there is the gyro's alone; 0: off)"),
    Param("lever_arm_lp_tau", 0.1, "s", (0.0, 10.0), VALUE, P_LEVER_TAU,
          "low-pass of the body rate before differentiating it (lever arm)"),
    Param("init_roll_pitch_sigma_deg", 5.0, "deg", (0.0, 180.0), UNUSED, None,
          "initial σ of roll and pitch"),
    Param("init_heading_sigma_deg", 20.0, "deg", (0.0, 180.0), UNUSED, None,
          "initial σ of heading"),
    Param("init_bias_sigma", 0.01, "rad/s", (0.0, 10.0), UNUSED, None,
          "initial σ of each gyro-bias component"),
    Param("init_bias", (0.0, 0.0, 0.0), "rad/s", (-10.0, 10.0), UNUSED, None,
          "initial gyro bias [x, y, z]"),
    Param("aided", True, "bool", (0, 1), UNUSED, None,
          "with a GNSS velocity (vel_n/vel_e, sog/cog, --gnss), roll and pitch come from the velocity-aided filter "
          "(imutool/attitude/aided.py: the velocity fixes as Kalman measurements, velocity and accelerometer-bias "
          "states; false: the EKF's velocity aiding alone, as before)"),
    Param("aided_smoother", True, "bool", (0, 1), UNUSED, None,
          "offline (filter on a whole recording, not streamed or live): the aided filter smoothed backward (RTS), "
          "so the accelerometer bias a turn reveals corrects the tilt before it too (false: the forward pass)"),
    Param("gnss_velocity_noise", 0.05, "m/s", (0.001, 10.0), UNUSED, None,
          "σ of each GNSS velocity fix, north and east (a receiver's class: 0.05 single-frequency, 0.02 dual, 0.01 "
          "RTK)"),
    Param("gnss_nis_gate", 16.0, "1", (0.0, 1e6), UNUSED, None,
          "a velocity fix whose normalised innovation squared (2 degrees of freedom) exceeds this is an outlier: "
          "skipped and counted, for at most reject_timeout s running (0: off)"),
    Param("gnss_min_interval", 0.2, "s", (0.0, 3600.0), UNUSED, None,
          "velocity fixes closer than this to the previous one are not used: an interpolated velocity (--gnss "
          "interpolates its fixes onto the IMU rows) is not a fix per row; set it to the receiver's interval there "
          "(1 at 1 Hz), lower it for a receiver faster than 5 Hz that is held or NaN between fixes (0.05 at 10 Hz)"),
    Param("aided_gyro_noise", 0.0001, "rad/s/sqrt(Hz)", (1e-7, 1.0), UNUSED, None,
          "the aided filter's gyro white-noise density (the sensor's own figure: the velocity fixes, not a "
          "generous process noise, hold its tilt)"),
    Param("aided_gyro_bias_rw", 4e-05, "rad/s/sqrt(s)", (0.0, 1.0), UNUSED, None,
          "the aided filter's gyro bias random walk (a MEMS gyro's bias wanders: 4e-5 ≈ 0.0023 °/s/√s)"),
    Param("aided_gyro_scale_noise", 0.0005, "1", (0.0, 1.0), UNUSED, None,
          "the aided filter's attitude noise per unit of angle turned (gyro scale factor and misalignment)"),
    Param("aided_accel_noise", 0.005, "m/s^2/sqrt(Hz)", (1e-6, 10.0), UNUSED, None,
          "the aided filter's accelerometer white-noise density (velocity random walk)"),
    Param("accel_bias_sigma", 0.04, "m/s^2", (0.0, 10.0), UNUSED, None,
          "prior σ of each accelerometer-bias component (a MEMS turn-on bias; 0.01 after a calibration); the tilt's σ "
          "keeps it until a turn or a change of speed makes the bias observable"),
    Param("accel_bias_rw", 5e-05, "m/s^2/sqrt(s)", (0.0, 10.0), UNUSED, None,
          "accelerometer bias random walk: process noise of the aided filter's bias states"),
    Param("init_accel_bias", (0.0, 0.0, 0.0), "m/s^2", (-10.0, 10.0), UNUSED, None,
          "initial accelerometer bias [x, y, z] of the aided filter (a previous run's accel_bias estimate)"),
    Param("aided_start_sigma_deg", 1.0, "deg", (0.0, 180.0), UNUSED, None,
          "the aided filter starts from the EKF at the first velocity fix where the EKF's roll and pitch σ are "
          "below this (the EKF's output before)"),
)
# fmt: on

PARAMS_BY_NAME: dict[str, Param] = {p.name: p for p in PARAMS}

# name -> (unit, (lowest, highest) allowed, one-line meaning): the table's documentation columns
PARAM_DOC: dict[str, tuple[str, tuple[float, float], str]] = {p.name: (p.unit, p.range, p.doc) for p in PARAMS}

# the kernel slots EkfCoefficients fills (they depend on the sample intervals or on a choice)
COEFFICIENT_SLOTS = (P_MAG_NOISE, P_GAP_DT, P_GYRO_PREV_W)


def _check_slots() -> None:
    """Every slot of the kernel's parameter vector is filled exactly once: by a table row or a coefficient."""
    slots = [p.slot for p in PARAMS if p.slot is not None] + list(COEFFICIENT_SLOTS)
    if sorted(slots) != list(range(N_PARAMS)):
        raise RuntimeError(f"the EKF parameter table does not fill the kernel's {N_PARAMS} slots once each: {slots}")
    for p in PARAMS:
        if (p.slot is not None) != (p.to_kernel in (VALUE, RADIANS, FLAG)):
            raise RuntimeError(f"EKF parameter {p.name}: {p.to_kernel.name} with slot {p.slot}")


_check_slots()


def params_markdown() -> str:
    """The parameter table as Markdown (name, default, unit, range, meaning): docs/attitude.md holds it verbatim."""
    lines = ["| parameter | default | unit | range | meaning |", "|---|---|---|---|---|"]
    for p in PARAMS:
        rng = "" if p.unit == "bool" or "|" in p.unit else f"{p.range[0]:g} … {p.range[1]:g}"
        unit = p.unit.replace("|", " \\| ")
        default = "[" + ", ".join(f"{x:g}" for x in p.default) + "]" if isinstance(p.default, tuple) else p.default
        default = str(default).lower() if isinstance(default, bool) else default
        doc = p.doc.replace("|", "\\|")
        lines.append(f"| `{p.name}` | {default} | {unit} | {rng} | {doc} |")
    return "\n".join(lines) + "\n"
