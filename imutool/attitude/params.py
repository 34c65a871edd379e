"""The EKF's tuning constants: :data:`PARAM_DOC` (unit, range, meaning) and :class:`EkfParams` (defaults, TOML)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from formats.errors import ImutoolError
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

# Every tuning constant of the EKF, with its unit, in one place (VQF's PyVQFParams is the model). Each entry:
# name -> (unit, (lowest, highest) allowed, one-line meaning). The defaults are the dataclass defaults below;
# they were chosen on all 16 shared BROAD trials and the simulator, never on one file (docs/attitude.md).
PARAM_DOC: dict[str, tuple[str, tuple[float, float], str]] = {
    "gyro_noise": ("rad/s/√Hz", (1e-7, 1.0), "gyro white-noise density: process noise of the attitude"),
    "gyro_scale_noise": (
        "1",
        (0.0, 1.0),
        "rate-proportional process noise of the tilt (across the world "
        "vertical): the attitude uncertainty that gyro scale-factor and "
        "misalignment errors add while the body turns (0: off)",
    ),
    "heading_scale_noise": (
        "1",
        (0.0, 1.0),
        "rate-proportional process noise about the world vertical only: "
        "the heading uncertainty that gyro scale-factor errors add while "
        "the body turns (gravity corrects the tilt part; 0: off)",
    ),
    "bias_rw": ("rad/s/√s", (0.0, 1.0), "gyro bias random walk: process noise of the bias"),
    "accel_noise": (
        "rad",
        (1e-5, 3.0),
        "σ floor of the normalised accelerometer direction, per sample (an update of n samples uses σ²/n)",
    ),
    "accel_noise_gain": ("1", (0.0, 100.0), "σ² += (gain × learned accelerometer white-noise σ / g)²"),
    "accel_noise_rise_time": (
        "s",
        (0.0, 1e6),
        "the learned accelerometer white noise is a sensor property: its "
        "floor follows the 10-s mean down at once and up with this time "
        "constant, so the jerk of a spell of fast motion is not taken for "
        "sensor noise (0: the 10-s mean itself)",
    ),
    "accel_lp_tau": (
        "s",
        (0.0, 100.0),
        "delay of the specific force's low-pass in the quasi-inertial frame "
        "(second-order Butterworth, cut-off √2/τ rad/s; 0: raw accelerometer, as "
        "in the paper)",
    ),
    "smoother_lp_tau": (
        "s",
        (0.0, 100.0),
        "delay of the smoother's low-pass of the specific force, run forwards "
        "and backwards (no lag: a longer τ costs it no delay; offline VQF's "
        "3 s) (0: accel_lp_tau)",
    ),
    "accel_lp_lag": (
        "bool",
        (0, 1),
        "the low-passed measurement lags a gyro-bias error by the low-pass's delay: "
        "H holds that term (false: H sees the tilt only)",
    ),
    "accel_gate": (
        "m/s^2",
        (0.0, 1e3),
        "shock gate: accelerometer samples with | |a| − g | above this are skipped for at most shock_max s (0: off)",
    ),
    "accel_nis_gate": ("1", (0.0, 1e6), "skip accelerometer updates whose NIS exceeds this (0: off)"),
    "accel_nis_soft": ("bool", (0, 1), "above accel_nis_gate inflate R by NIS/gate instead of skipping"),
    "accel_adapt": ("m/s^2", (0.0, 1e3), "accelerometer σ × √(1 + (| |a| − g | / this)²) (0: off)"),
    "shock_max": (
        "s",
        (0.0, 1e3),
        "a shock is at most this long: beyond accel_gate for longer, the acceleration "
        "is sustained and the accelerometer is used again (low-passed), never coasted "
        "on; the gyro bias does not learn from it either way (bias_hold)",
    ),
    "reject_timeout": ("s", (0.01, 1e4), "a rejected accelerometer is forced back in after this long"),
    "accel_bias_dev": (
        "m/s^2",
        (0.0, 1e3),
        "no gyro-bias learning from the accelerometer while | |a| − g | "
        "exceeds this, and for bias_hold s after (0: always learn)",
    ),
    "bias_hold": ("s", (0.0, 1e3), "hold-off after a large | |a| − g | before the bias learns again"),
    "bias_max": ("rad/s", (0.0, 10.0), "bound on each gyro-bias component (0: none)"),
    "accel_heading": (
        "bool",
        (0, 1),
        "accelerometer updates may move heading through cross-covariances (false: "
        "they correct inclination only, as gravity observes no heading)",
    ),
    "accel_vertical_bias": (
        "bool",
        (0, 1),
        "accelerometer updates may correct the gyro-bias component about the "
        "world vertical (which gravity does not observe; false: only the "
        "heading and rest detection learn it)",
    ),
    "heading_input_noise_deg": (
        "deg",
        (1e-3, 180.0),
        "σ of an external true heading per update (gyrocompass HDT/THS, "
        "channel heading_true); with one, the magnetometer is not used",
    ),
    "heading_input_interval": (
        "s",
        (0.0, 3600.0),
        "the external heading is used at most once per this interval: "
        "a gyrocompass's errors are correlated over seconds, and an "
        "interpolated or held column must not count each IMU sample "
        "as an independent fix (0: every sample)",
    ),
    "heading_input_latency": (
        "s",
        (0.0, 10.0),
        "delay of the external heading: a fix stamped t is the heading at "
        "t − latency (a gyrocompass's HDT is often 0.1–1 s late; at 3 °/s "
        "0.5 s is 1.5° of heading); the heading is read that much later",
    ),
    "mag_heading_density": (
        "deg*sqrt(s)",
        (0.01, 100.0),
        "σ of the magnetic heading as a noise density: σ per "
        "sample = this / √dt, so the heading's time constant "
        "(≈ radians(this) / gyro_noise ≈ 21 s) is the same at "
        "any rate ('full' mode: of m̂, rad; an update of n "
        "samples uses σ²/n)",
    ),
    "mag_heading_floor_deg": (
        "deg",
        (0.0, 180.0),
        "... and at least this per sample: one sample's own white noise "
        "(≈ 1.5 µT on a 17 µT horizontal field), which a slow "
        "magnetometer's density alone would under-state",
    ),
    "mag_noise_deg": (
        "deg",
        (0.0, 180.0),
        "σ of the magnetic heading per sample, pinned whatever the rate (0: "
        "from mag_heading_density; files saved before it existed pin 20; "
        "else at least 0.01)",
    ),
    "mag_norm_gate": ("1", (0.0, 10.0), "skip mag when | |m|/m_ref − 1 | exceeds this fraction (0: off)"),
    "mag_dip_gate_deg": ("deg", (0.0, 90.0), "skip mag when its dip departs from the reference by more (0: off)"),
    "mag_norm_soft": ("1", (0.0, 10.0), "mag σ² × (1 + (norm deviation / this)²): de-weighting (0: off)"),
    "mag_dip_soft_deg": ("deg", (0.0, 90.0), "mag σ² × (1 + (dip deviation / this)²): de-weighting (0: off)"),
    "mag_disturbance_hold": (
        "s",
        (0.0, 1e3),
        "the magnetic de-weighting follows the largest recent deviation "
        "(norm, dip, a gate rejection), decaying with this time constant, "
        "so samples that pass by chance inside a disturbance stay "
        "de-weighted (0: per sample)",
    ),
    "mag_reference_tau": (
        "s",
        (0.0, 1e6),
        "the reference norm and dip the magnetometer's gates compare with: the "
        "mean of the accepted field, a running mean over the first this-many "
        "seconds, then forgetting with this time constant (the earth's field "
        "changes only as the vessel moves over it; 0: the first sample, for the "
        "whole run)",
    ),
    "mag_new_time": (
        "s",
        (0.0, 1e6),
        "no lock-out of the magnetometer: a field its gates reject, but which stays "
        "within those gates of itself (homogeneous) for this long while the body "
        "turns, becomes the new reference (the sensor moved, or the field at the "
        "start was the disturbed one; VQF's magNewTime; 0: never)",
    ),
    "mag_new_first_time": (
        "s",
        (0.0, 1e6),
        "... this long instead while the reference is not yet confirmed (its "
        "own field has not yet held this long while the body turned: the field "
        "where a recording starts may be the disturbed one; VQF's "
        "magNewFirstTime; 0: the start's field counts as confirmed)",
    ),
    "mag_new_min_rate": (
        "deg/s",
        (0.0, 1e4),
        "... only time while the body turns faster than this counts: a "
        "magnet riding with the sensor changes the field's norm and dip as "
        "the body turns, a new homogeneous field does not (VQF's "
        "magNewMinGyr; 0: any time counts, a still sensor's too, so a magnet "
        "held beside it becomes the reference)",
    ),
    "mag_bias": ("bool", (0, 1), "magnetic heading updates may correct the gyro bias"),
    "mag_bias_gate": (
        "1",
        (0.0, 1e6),
        "... only from heading innovations within this many σ (σ² = the heading's "
        "variance + the magnetometer's undisturbed σ² per update): a heading off "
        "by more (a wrong start, a field the gates pass) is an error of the "
        "heading, not of the gyro, so the bias is left as it is (a Schmidt update; "
        "0: always; mag_mode heading only, the 'full' vector "
        "update is not gated)",
    ),
    "gravity": ("m/s^2", (9.7, 9.9), "local gravity"),
    "rest_gyro": ("rad/s", (0.0, 10.0), "rest: |ω − b| below this on every axis ..."),
    "rest_accel": ("m/s^2", (0.0, 100.0), "... and | |a| − g | below this ..."),
    "rest_time": ("s", (0.0, 1e4), "... for this long (0: no rest detection)"),
    "rest_noise": ("rad/s", (1e-6, 10.0), "σ of the zero-rate pseudo-measurement at rest, per sample"),
    "gap_factor": ("1", (1.0, 1e6), "a time step longer than this × the median step is a gap"),
    "gap_rate_sigma": ("rad/s", (0.0, 100.0), "attitude variance growth over a gap: (σ · gap)²"),
    "gyro_integration": ("rectangular|trapezoid", (0, 0), "rate over a step: ω_k or ½(ω_{k−1} + ω_k)"),
    "update_every": (
        "samples",
        (0, 1e6),
        "covariance propagation + measurement updates every N samples (paper: "
        "40); 0: N from update_rate_hz. The measurement σ stay per sample (an "
        "update stands for the n usable samples since that sensor's last one: "
        "R = σ²/n), so N changes the speed, not the filter",
    ),
    "update_rate_hz": (
        "Hz",
        (0.0, 1e6),
        "with update_every 0: updates at least this often, every N = ⌊sample "
        "rate / this⌋ samples (1 with the raw accelerometer, accel_lp_tau 0; "
        "0: every sample)",
    ),
    "mag_mode": (
        "heading|full|off",
        (0, 0),
        "magnetometer use: heading only (never touches roll/pitch), the paper's full 3-D vector, or none",
    ),
    "nis_window": (
        "s",
        (0.0, 1e4),
        "self-check window: mean normalised innovation squared per degree of freedom over about this long (0: off)",
    ),
    "nis_limit": (
        "1",
        (0.0, 1e6),
        "self-check: samples whose windowed NIS exceeds this are flagged inconsistent (0: off)",
    ),
    "tilt_check_window": (
        "s",
        (0.0, 1e4),
        "self-check of the vertical: the specific force in the world frame, "
        "low-passed over about this long (two stages of half of it), must "
        "point straight up, as a bounded velocity keeps its mean vertical "
        "(0: off)",
    ),
    "tilt_check_deg": (
        "deg",
        (0.0, 90.0),
        "... samples where it tilts from the estimate's vertical by more than "
        "√(this² + (3 σ)²), σ² = the estimate's roll + pitch variance, are "
        "flagged inconsistent: a gyro in the wrong unit or scale, a reversed "
        "axis, an acceleration the filter was not told of",
    ),
    "mag_check_time": (
        "s",
        (0.0, 1e6),
        "self-check of the heading: warn where the magnetometer was rejected "
        "for longer than this (the heading there is the gyro's alone; 0: off)",
    ),
    "lever_arm_lp_tau": ("s", (0.0, 10.0), "low-pass of the body rate before differentiating it (lever arm)"),
    "init_roll_pitch_sigma_deg": ("deg", (0.0, 180.0), "initial σ of roll and pitch"),
    "init_heading_sigma_deg": ("deg", (0.0, 180.0), "initial σ of heading"),
    "init_bias_sigma": ("rad/s", (0.0, 10.0), "initial σ of each gyro-bias component"),
    "init_bias": ("rad/s", (-10.0, 10.0), "initial gyro bias [x, y, z]"),
}


def _toml_table(path: str) -> dict:
    """The ``[ekf]`` table of a parameters file (or its top level)."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except OSError as e:
        raise ImutoolError(f"cannot read parameters: {e.strerror}", path=path) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ImutoolError(f"not a valid TOML parameters file: {e}", path=path) from None
    table = data.get("ekf", data)
    if not isinstance(table, dict):
        raise ImutoolError("[ekf] must be a table", path=path)
    return table


@dataclass
class EkfParams:
    """Every tuning constant of :func:`run_ekf` (units and meaning: :data:`PARAM_DOC`). One-sigma noise figures.

    Load and save as TOML (:meth:`from_toml`, :meth:`to_toml`) so a configuration can be kept, shared and cited;
    ``imutool filter --params FILE`` reads one and writes the parameters it used into the output's metadata.
    """

    gyro_noise: float = 1e-3
    gyro_scale_noise: float = 0.01
    heading_scale_noise: float = 0.0005
    bias_rw: float = 2e-5
    accel_noise: float = 0.03
    accel_noise_gain: float = 4.0
    accel_noise_rise_time: float = 300.0
    accel_lp_tau: float = 2.5
    smoother_lp_tau: float = 3.0
    accel_lp_lag: bool = True
    accel_gate: float = 0.0
    accel_nis_gate: float = 0.0
    accel_nis_soft: bool = False
    accel_adapt: float = 0.0
    shock_max: float = 0.2
    reject_timeout: float = 3.0
    accel_bias_dev: float = 0.0
    bias_hold: float = 1.0
    bias_max: float = 0.0
    accel_vertical_bias: bool = False
    accel_heading: bool = False
    mag_disturbance_hold: float = 0.5
    mag_reference_tau: float = 3600.0
    mag_new_time: float = 20.0
    mag_new_min_rate: float = 20.0
    mag_new_first_time: float = 5.0
    mag_heading_density: float = 1.2
    mag_heading_floor_deg: float = 5.0
    mag_noise_deg: float = 0.0
    heading_input_noise_deg: float = 1.0
    heading_input_interval: float = 1.0
    heading_input_latency: float = 0.0
    mag_norm_gate: float = 0.15
    mag_dip_gate_deg: float = 10.0
    mag_norm_soft: float = 0.05
    mag_dip_soft_deg: float = 5.0
    mag_bias: bool = True
    mag_bias_gate: float = 3.0
    gravity: float = 9.80665
    rest_gyro: float = 0.05
    rest_accel: float = 0.3
    rest_time: float = 1.0
    rest_noise: float = 0.05
    gap_factor: float = 5.0
    gap_rate_sigma: float = 0.2
    gyro_integration: str = "rectangular"
    update_every: int = 0
    update_rate_hz: float = 50.0
    mag_mode: str = "heading"
    nis_window: float = 10.0
    nis_limit: float = 3.0
    tilt_check_window: float = 20.0
    tilt_check_deg: float = 3.0
    mag_check_time: float = 60.0
    lever_arm_lp_tau: float = 0.1
    init_roll_pitch_sigma_deg: float = 5.0
    init_heading_sigma_deg: float = 20.0
    init_bias_sigma: float = 0.01
    init_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Refuse (ImutoolError) any value outside its declared range, NaN or inf, or an unknown choice."""
        for name, (unit, (lo, hi), _) in PARAM_DOC.items():
            v = getattr(self, name)
            if name == "gyro_integration":
                self.gyro_prev_weight()
                continue
            if name == "mag_mode":
                self.mag_mode_code()
                continue
            vals = v if name == "init_bias" else (v,)
            try:
                arr = np.asarray(vals, dtype=float)
            except (TypeError, ValueError):
                raise ImutoolError(f"EKF parameter {name} = {v!r}: expected a number ({unit})") from None
            if arr.shape != ((3,) if name == "init_bias" else (1,)):
                want = "3 numbers" if name == "init_bias" else "one number"
                raise ImutoolError(f"EKF parameter {name} = {v!r}: expected {want}")
            if not (np.all(np.isfinite(arr)) and np.all(arr >= lo) and np.all(arr <= hi)):
                raise ImutoolError(f"EKF parameter {name} = {v!r} is outside [{lo:g}, {hi:g}] {unit}")
            if name == "mag_noise_deg" and 0 < v < 0.01:
                raise ImutoolError(
                    f"EKF parameter mag_noise_deg = {v!r}: 0 (from mag_heading_density) or at least 0.01 deg"
                )

    @classmethod
    def from_dict(cls, values: dict, source: str = "parameters") -> EkfParams:
        """Parameters from a mapping (TOML table); unknown names are refused with the list of known ones."""
        unknown = sorted(set(values) - set(PARAM_DOC))
        if unknown:
            raise ImutoolError(
                f"{source}: unknown EKF parameter(s) {', '.join(unknown)}; known: {', '.join(PARAM_DOC)}"
            )
        kw = dict(values)
        if "init_bias" in kw and isinstance(kw["init_bias"], list):
            kw["init_bias"] = tuple(kw["init_bias"])
        for k, v in kw.items():
            default = getattr(cls, k, None)
            if isinstance(default, bool) and not isinstance(v, bool):
                raise ImutoolError(f"{source}: {k} must be true or false, not {v!r}")
            if isinstance(default, str) and not isinstance(v, str):
                raise ImutoolError(f"{source}: {k} must be a string, not {v!r}")
            if isinstance(default, int) and not isinstance(default, bool) and isinstance(v, float):
                if v != int(v):
                    raise ImutoolError(f"{source}: {k} must be a whole number, not {v!r}")
                kw[k] = int(v)
        return cls(**kw)

    @classmethod
    def from_toml(cls, path: str) -> EkfParams:
        """Read a parameters file: keys at the top level or under ``[ekf]`` (as :meth:`to_toml` writes)."""
        table = _toml_table(path)
        return cls.from_dict({k: v for k, v in table.items() if k != "imutool_params"}, source=str(path))

    @staticmethod
    def pins_every_sample(path: str) -> bool:
        """True for a parameters file written before updates every N samples became the default (2026-11-26): it
        says ``update_every = 1`` (the old default, written into every saved file) and has no ``update_rate_hz``."""
        table = _toml_table(path)
        return table.get("update_every") == 1 and "update_rate_hz" not in table

    @staticmethod
    def keys_in_file(path: str) -> set[str]:
        """The parameter names a parameters file gives (the rest take their defaults)."""
        return set(_toml_table(path))

    @staticmethod
    def pins_mag_sigma(path: str) -> bool:
        """True for a parameters file that pins the magnetometer's σ per sample (``mag_noise_deg`` > 0): every file
        written before it became a density does (20, the old default), and so does such a file saved again."""
        table = _toml_table(path)
        v = table.get("mag_noise_deg", 0)
        return isinstance(v, (int, float)) and v > 0

    def to_toml(self) -> str:
        """The parameters as a commented TOML ``[ekf]`` table (units and meaning on every line)."""
        lines = ["# imutool EKF parameters (imutool filter --params FILE); units and meaning per line", "[ekf]"]
        for name, (unit, _, meaning) in PARAM_DOC.items():
            v = getattr(self, name)
            if isinstance(v, bool):
                txt = "true" if v else "false"
            elif isinstance(v, str):
                txt = f'"{v}"'
            elif isinstance(v, tuple):
                txt = "[" + ", ".join(repr(float(x)) for x in v) + "]"
            else:
                txt = repr(v)
            lines.append(f"{name} = {txt}  # {unit}: {meaning}")
        return "\n".join(lines) + "\n"

    def vector(self, dt_nominal: float, dt_mag: float | None = None) -> np.ndarray:
        """The kernel's parameter vector at nominal step ``dt_nominal`` (s); ``dt_mag`` (s) the magnetometer's
        own interval where it is slower than the IMU (default: ``dt_nominal``)."""
        p = np.zeros(N_PARAMS)
        p[P_GYRO_NOISE] = self.gyro_noise
        p[P_BIAS_RW] = self.bias_rw
        p[P_ACC_NOISE] = self.accel_noise
        usable = dt_mag is not None and bool(np.isfinite(dt_mag)) and dt_mag > 0
        p[P_MAG_NOISE] = self.mag_sigma_per_sample(dt_mag if usable else dt_nominal)
        p[P_ACC_GATE] = self.accel_gate
        p[P_ACC_NIS] = self.accel_nis_gate
        p[P_MAG_NORM_GATE] = self.mag_norm_gate
        p[P_MAG_DIP_GATE] = np.radians(self.mag_dip_gate_deg)
        p[P_GRAVITY] = self.gravity
        p[P_REST_GYRO] = self.rest_gyro
        p[P_REST_ACC] = self.rest_accel
        p[P_REST_TIME] = self.rest_time
        p[P_REST_NOISE] = self.rest_noise
        p[P_GAP_DT] = self.gap_factor * dt_nominal
        p[P_GAP_RATE] = self.gap_rate_sigma
        p[P_REJ_TIMEOUT] = self.reject_timeout
        p[P_GYRO_SCALE] = self.gyro_scale_noise
        p[P_ACC_TAU] = self.accel_lp_tau
        p[P_GYRO_PREV_W] = self.gyro_prev_weight()
        p[P_ACC_ADAPT] = self.accel_adapt
        p[P_ACC_SOFT] = 1.0 if self.accel_nis_soft else 0.0
        p[P_ACC_WN_GAIN] = self.accel_noise_gain
        p[P_MAG_BIAS] = 1.0 if self.mag_bias else 0.0
        p[P_ACC_BIAS_DEV] = self.accel_bias_dev
        p[P_BIAS_MAX] = self.bias_max
        p[P_BIAS_HOLD] = self.bias_hold
        p[P_MAG_NORM_SOFT] = self.mag_norm_soft
        p[P_MAG_DIP_SOFT] = np.radians(self.mag_dip_soft_deg)
        p[P_NIS_TAU] = self.nis_window
        p[P_NIS_LIMIT] = self.nis_limit
        p[P_LEVER_TAU] = self.lever_arm_lp_tau
        p[P_SHOCK_MAX] = self.shock_max
        p[P_ACC_VBIAS] = 1.0 if self.accel_vertical_bias else 0.0
        p[P_ACC_HEAD] = 1.0 if self.accel_heading else 0.0
        p[P_MAG_HOLD] = self.mag_disturbance_hold
        p[P_HEAD_SCALE] = self.heading_scale_noise
        p[P_ACC_NOISE_RISE] = self.accel_noise_rise_time
        p[P_TILT_WIN] = self.tilt_check_window
        p[P_TILT_LIM] = np.radians(self.tilt_check_deg)
        p[P_ACC_LAG] = 1.0 if self.accel_lp_lag else 0.0
        p[P_HDG_NOISE] = np.radians(self.heading_input_noise_deg)
        p[P_HDG_EVERY] = self.heading_input_interval
        p[P_MAG_REF_TAU] = self.mag_reference_tau
        p[P_MAG_NEW_TIME] = self.mag_new_time
        p[P_MAG_NEW_RATE] = np.radians(self.mag_new_min_rate)
        p[P_MAG_NEW_FIRST] = self.mag_new_first_time
        p[P_MAG_BIAS_GATE] = self.mag_bias_gate
        return p

    def mag_sigma_per_sample(self, dt_mag: float) -> float:
        """σ of one magnetometer sample (rad), the magnetometer sampled every ``dt_mag`` (s): ``mag_noise_deg``
        where a file pins it, else ``mag_heading_density`` / √dt_mag and at least ``mag_heading_floor_deg``. The
        magnetometer's heading error is not white from sample to sample (calibration residuals, nearby iron), so a
        faster sensor must not be trusted more per second: with a density the heading's correction time constant,
        ≈ radians(density) / gyro_noise (≈ 21 s), is the same at 20 Hz as at 286 Hz (a fixed σ per sample made it
        21 s at 286 Hz and 49 s at 50 Hz). Below ≈ 17 Hz the floor (one sample's white noise) takes over."""
        if self.mag_noise_deg > 0:
            return float(np.radians(self.mag_noise_deg))
        if not (np.isfinite(dt_mag) and dt_mag > 0):
            raise ImutoolError(f"the magnetometer's sample interval {dt_mag!r} s is not a positive number")
        return float(np.radians(max(self.mag_heading_density / np.sqrt(dt_mag), self.mag_heading_floor_deg)))

    def samples_per_update(self, dt_nominal: float) -> int:
        """N: covariance propagation and measurement updates every N samples of nominal step ``dt_nominal`` (s)."""
        if self.update_every >= 1:
            return int(self.update_every)
        if self.update_rate_hz <= 0 or self.accel_lp_tau <= 0 or not dt_nominal > 0:
            return 1
        return max(1, int(np.floor(1.0 / (dt_nominal * self.update_rate_hz) + 1e-6)))

    def gyro_prev_weight(self) -> float:
        try:
            return {"trapezoid": 0.5, "rectangular": 0.0}[self.gyro_integration]
        except KeyError:
            raise ImutoolError(
                f"gyro integration {self.gyro_integration!r}: expected trapezoid or rectangular"
            ) from None

    def mag_mode_code(self) -> int:
        try:
            return {"off": 0, "heading": 1, "full": 2}[self.mag_mode]
        except KeyError:
            raise ImutoolError(f"mag mode {self.mag_mode!r}: expected heading, full or off") from None
