"""The EKF's parameters: :class:`EkfParams` (its fields come from the table :data:`PARAMS` in
:mod:`~imutool.attitude.param_table`), the coefficients derived from them once per run (:class:`EkfCoefficients`),
and the versioned parameter TOML with its migrations (:func:`read_params_file`, :data:`MIGRATIONS`).

VQF keeps ``VQFParams`` (independent of the sampling rate) and ``VQFCoefficients`` (derived from them and the sample
times) apart; so does this module: nothing in :class:`EkfParams` depends on the rate.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from formats.errors import ImutoolError
from imutool.attitude.layout import N_PARAMS, P_GAP_DT, P_GYRO_PREV_W, P_MAG_NOISE
from imutool.attitude.param_table import FLAG, PARAM_DOC, PARAMS, PARAMS_BY_NAME, RADIANS, Param, ToKernel

try:  # the standard library's TOML reader from Python 3.11; tomli (the same code) before
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

__all__ = [
    "MIGRATIONS",
    "PARAMS",
    "PARAMS_VERSION",
    "PARAM_DOC",
    "EkfCoefficients",
    "EkfParams",
    "Migration",
    "Param",
    "ParamsFile",
    "ToKernel",
    "params_from_options",
    "read_params_file",
]


def _field_type(default: Any) -> str:
    return "tuple[float, float, float]" if isinstance(default, tuple) else type(default).__name__


def _fields_from_table(cls: type) -> type:
    """Make ``cls`` a dataclass with one field per row of :data:`PARAMS` (type of its default, its default), and
    list the parameters, their units and defaults in its docstring."""
    cls.__annotations__ = {p.name: _field_type(p.default) for p in PARAMS}
    for p in PARAMS:
        setattr(cls, p.name, p.default)
    cls.__doc__ = (
        (cls.__doc__ or "")
        + "\n\n    Parameters (default, unit: meaning):\n\n"
        + "\n".join(f"    - ``{p.name}`` = {p.default!r} ({p.unit}): {p.doc}" for p in PARAMS)
    )
    return dataclass(cls)


@_fields_from_table
class EkfParams:
    """Every tuning constant of :func:`run_ekf` (the fields come from :data:`PARAMS`). One-sigma noise figures.

    Load and save as TOML (:meth:`from_toml`, :meth:`to_toml`) so a configuration can be kept, shared and cited;
    ``imutool filter --params FILE`` reads one and writes the parameters it used into the output's metadata."""

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
            if name == "motion":
                if self.motion not in MOTIONS:
                    raise ImutoolError(f"motion {self.motion!r}: expected {', '.join(MOTIONS)}")
                continue
            vector = name in ("init_bias", "init_accel_bias")
            vals = v if vector else (v,)
            try:
                arr = np.asarray(vals, dtype=float)
            except (TypeError, ValueError):
                raise ImutoolError(f"EKF parameter {name} = {v!r}: expected a number ({unit})") from None
            if arr.shape != ((3,) if vector else (1,)):
                want = "3 numbers" if vector else "one number"
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
        for key in ("init_bias", "init_accel_bias"):
            if key in kw and isinstance(kw[key], list):
                kw[key] = tuple(kw[key])
        for k, v in kw.items():
            default = PARAMS_BY_NAME[k].default
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
        """Read a parameters file: keys at the top level or under ``[ekf]`` (as :meth:`to_toml` writes), migrated
        from its ``version`` (:func:`read_params_file`, which also gives the migration notes)."""
        return read_params_file(path).params

    def to_toml(self) -> str:
        """The parameters as a commented TOML ``[ekf]`` table (units and meaning on every line), with the file
        format's ``version``."""
        lines = [
            "# imutool EKF parameters (imutool filter --params FILE); units and meaning per line",
            f"version = {PARAMS_VERSION}  # of this file's format: an older one is migrated when read, a newer refused",
            "[ekf]",
        ]
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
        own interval where it is slower than the IMU (default: ``dt_nominal``). See :class:`EkfCoefficients`."""
        return EkfCoefficients.derive(self, dt_nominal, dt_mag).kernel_vector(self)

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
        """The previous gyro sample's weight in a step's rate: 0 rectangular, ½ trapezoid."""
        try:
            return {"trapezoid": 0.5, "rectangular": 0.0}[self.gyro_integration]
        except KeyError:
            raise ImutoolError(
                f"gyro integration {self.gyro_integration!r}: expected trapezoid or rectangular"
            ) from None

    def mag_mode_code(self) -> int:
        """The kernel's magnetometer mode: 0 off, 1 heading, 2 full."""
        try:
            return {"off": 0, "heading": 1, "full": 2}[self.mag_mode]
        except KeyError:
            raise ImutoolError(f"mag mode {self.mag_mode!r}: expected heading, full or off") from None

    def as_dict(self) -> dict[str, Any]:
        """The parameters as plain values (tuples as lists), in the table's order: the output's ``filter`` metadata."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}


@dataclass(frozen=True)
class EkfCoefficients:
    """What the kernel needs that depends on the sample intervals or on a choice, derived once per run from
    :class:`EkfParams` (which never depends on the rate) by :meth:`derive`."""

    dt_nominal: float  # s, the IMU's nominal sample interval
    gap_dt: float  # s, a step longer than this is a gap: gap_factor · dt_nominal
    mag_sigma: float  # rad, σ of one magnetometer sample (EkfParams.mag_sigma_per_sample at its interval)
    gyro_prev_weight: float  # the previous gyro sample's weight in a step (gyro_integration: 0 or ½)
    samples_per_update: int  # N: covariance propagation and updates every N samples
    mag_mode_code: int  # 0 off, 1 heading, 2 full (mag_mode)

    @classmethod
    def derive(cls, params: EkfParams, dt_nominal: float, dt_mag: float | None = None) -> EkfCoefficients:
        """The coefficients at nominal IMU step ``dt_nominal`` (s) and magnetometer interval ``dt_mag`` (s; None,
        NaN or ≤ 0: ``dt_nominal``)."""
        usable = dt_mag is not None and bool(np.isfinite(dt_mag)) and dt_mag > 0
        return cls(
            dt_nominal=dt_nominal,
            gap_dt=params.gap_factor * dt_nominal,
            mag_sigma=params.mag_sigma_per_sample(dt_mag if usable else dt_nominal),  # type: ignore[arg-type]
            gyro_prev_weight=params.gyro_prev_weight(),
            samples_per_update=params.samples_per_update(dt_nominal),
            mag_mode_code=params.mag_mode_code(),
        )

    def kernel_vector(self, params: EkfParams) -> np.ndarray:
        """The kernel's parameter vector (``prm[P_*]``): each table row with a slot as :class:`ToKernel` says,
        then these coefficients."""
        p = np.zeros(N_PARAMS)
        for row in PARAMS:
            if row.slot is None:
                continue
            v = getattr(params, row.name)
            if row.to_kernel is RADIANS:
                p[row.slot] = np.radians(v)
            elif row.to_kernel is FLAG:
                p[row.slot] = 1.0 if v else 0.0
            else:
                p[row.slot] = v
        p[P_MAG_NOISE] = self.mag_sigma
        p[P_GAP_DT] = self.gap_dt
        p[P_GYRO_PREV_W] = self.gyro_prev_weight
        return p


# ============================================ the parameter TOML ============================================
# The format's version, written by EkfParams.to_toml as `version = N` above the [ekf] table. A file without one is
# version 0: every file saved before versions existed (2026-11-27). Raise it when a parameter's meaning changes,
# with a Migration below saying what changed.
PARAMS_VERSION = 4
MOTIONS = ("auto", "ship", "handheld")  # EkfParams.motion (imutool/attitude/motion.py)


@dataclass(frozen=True)
class Migration:
    """One change of meaning between parameter-file versions, and what a file from before it is told.

    A migration keeps the file's values (a saved configuration is what its user chose and cited) and says, once per
    run, what those values now mean. ``notes(path, keys, used, overridden)`` gives the lines for a run that uses
    parameters ``used`` after names ``overridden`` on the command line (empty: nothing to say any more); ``keys``
    are the names the file gives."""

    name: str
    since: str  # when the meaning changed: date and commit
    changed: str  # what changed, in one line
    before_version: int  # applies to files of a version below this one
    # for version-0 files (no version written): whether the file predates the change, guessed from its keys and
    # values (None: every file below before_version does)
    detect: Callable[[dict[str, Any]], bool] | None
    notes: Callable[[str, frozenset[str], Any, frozenset[str]], list[str]]


def _pins_mag_sigma(table: dict[str, Any]) -> bool:
    """The file pins the magnetometer's σ per sample (``mag_noise_deg`` > 0): every file written before it became a
    density does (20, the old default), and so does such a file saved again."""
    v = table.get("mag_noise_deg", 0)
    return isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0


def _every_sample_notes(path: str, keys: frozenset[str], used: Any, overridden: frozenset[str]) -> list[str]:
    if "update_every" in overridden or used.update_every != 1:
        return []
    return [
        f"{path} sets update_every = 1, as every parameters file saved before 2026-11-26 does: the filter "
        "updates every sample (the same filter, about 2.3x slower than the default); set update_every = 0 "
        "there, or --update-every 0, for updates every ⌊rate / update_rate_hz⌋ samples"
    ]


def _mag_density_notes(path: str, keys: frozenset[str], used: Any, overridden: frozenset[str]) -> list[str]:
    if not used.mag_noise_deg > 0:
        return []
    out = [
        f"{path} sets mag_noise_deg = {used.mag_noise_deg:g}, a σ per sample at any rate (every parameters file "
        "saved before mag_heading_density existed does), so the heading's time constant grows as the rate falls "
        "(21 s at 286 Hz, 49 s at 50 Hz); set mag_noise_deg = 0 there, or --param mag_noise_deg=0, for "
        "mag_heading_density (deg·√s, the same at every rate)"
    ]
    if "mag_reference_tau" not in keys:
        out.append(
            "the magnetometer's gates now compare with the mean accepted field, not its first sample "
            "(mag_reference_tau = 0: as before)"
        )
    return out


def _new_field_notes(path: str, keys: frozenset[str], used: Any, overridden: frozenset[str]) -> list[str]:
    if "mag_new_time" in overridden:
        return []
    return [
        f"{path} does not set mag_new_time or mag_bias_gate (files saved before the new-field acceptance, commit "
        "1816144, do not): the magnetometer's new-field acceptance and the gate on its bias learning apply with "
        "their defaults (set either to 0 for the behaviour before)"
    ]


def _butterworth_notes(path: str, keys: frozenset[str], used: Any, overridden: frozenset[str]) -> list[str]:
    return [
        f"{path} sets accel_lp_tau and has no smoother_lp_tau, as every parameters file saved before the "
        "accelerometer's low-pass became a second-order Butterworth (2026-11-27) does: if it is such a file, its "
        "accel_lp_tau is now the Butterworth's delay (its 3 s with 0.003 and 2.8: 0.736° mean inclination on "
        "BROAD, 0.739 with the old two stages); the defaults are accel_lp_tau 2.5, gyro_scale_noise 0.01, "
        "accel_noise_gain 4 (0.727°) — delete those three keys to take them"
    ]


def _lever_estimate_notes(path: str, keys: frozenset[str], used: Any, overridden: frozenset[str]) -> list[str]:
    if "lever_arm_estimate" in overridden or not used.lever_arm_estimate or used.motion == "handheld":
        return []
    return [
        f"{path} was saved before the lever-arm estimate (version < 3, 2026-11-27): on ship motion with no "
        "--lever-arm the sensor's lever arm is now estimated from the data and used; --param "
        "lever_arm_estimate=false for the behaviour before"
    ]


def _motion_notes(path: str, keys: frozenset[str], used: Any, overridden: frozenset[str]) -> list[str]:
    if "motion" in overridden or used.motion == "handheld":
        return []
    return [
        f"{path} was saved before the motion model (version < 2, 2026-11-27): with motion = 'auto' a recording "
        f"whose gyro shows ship motion takes ship_lp_tau ({used.ship_lp_tau:g} s) as its low-pass, not the file's "
        "accel_lp_tau; --param motion=handheld for the behaviour before"
    ]


def _aided_smoother_notes(path: str, keys: frozenset[str], used: Any, overridden: frozenset[str]) -> list[str]:
    if "aided_smoother" in overridden or not (used.aided and used.aided_smoother):
        return []
    return [
        f"{path} was saved before the aided pass was smoothed (version < 4, 2026-12-06): with a GNSS velocity, "
        "filter on a whole recording now smooths the velocity-aided pass backward (the accelerometer bias a turn "
        "reveals corrects the tilt before it too); --param aided_smoother=false for the forward pass of before"
    ]


# Every change of a parameter's meaning since files were first saved, oldest first. Version 0 had no version key,
# so which of its changes a file predates is guessed from the keys it gives (every file is saved with every
# parameter of its day) and the values the old defaults wrote.
MIGRATIONS: tuple[Migration, ...] = (
    Migration(
        "updates_every_n_samples",
        "2026-11-26, commit 441c5ab",
        "updates every N = ⌊rate / update_rate_hz⌋ samples by default, not every sample (update_every 1 → 0)",
        1,
        lambda t: t.get("update_every") == 1 and "update_rate_hz" not in t,
        _every_sample_notes,
    ),
    Migration(
        "mag_sigma_density",
        "2026-11-26, commits c92361b and cf4f8f8",
        "the magnetometer's σ is a density (mag_heading_density, deg·√s) unless mag_noise_deg pins it per sample; "
        "the gates compare with the mean accepted field (mag_reference_tau)",
        1,
        _pins_mag_sigma,
        _mag_density_notes,
    ),
    Migration(
        "mag_new_field",
        "2026-11-26, commit 1816144",
        "a new homogeneous field is accepted as the reference (mag_new_time) and bias learning from the "
        "magnetometer is gated (mag_bias_gate)",
        1,
        lambda t: "mag_new_time" not in t and ("mag_heading_density" in t or _pins_mag_sigma(t)),
        _new_field_notes,
    ),
    Migration(
        "butterworth_lowpass",
        "2026-11-27, commit 44d1fba",
        "accel_lp_tau is the delay of a second-order Butterworth, not of two first-order stages; the smoother's own "
        "smoother_lp_tau",
        1,
        lambda t: "accel_lp_tau" in t and "smoother_lp_tau" not in t,
        _butterworth_notes,
    ),
    Migration(
        "motion_model",
        "2026-11-27",
        "motion auto: on ship motion the low-pass is ship_lp_tau, not accel_lp_tau",
        2,
        None,
        _motion_notes,
    ),
    Migration(
        "lever_arm_estimate",
        "2026-11-27",
        "on ship motion with no lever arm given, the lever arm is estimated (lever_arm_estimate)",
        3,
        None,
        _lever_estimate_notes,
    ),
    Migration(
        "aided_smoother",
        "2026-12-06",
        "offline, the GNSS-velocity-aided pass is smoothed backward (aided_smoother)",
        4,
        None,
        _aided_smoother_notes,
    ),
)


@dataclass(frozen=True)
class ParamsFile:
    """A parameters file as read: its ``version`` (0: none written), the names it gives, the parameters, and the
    :data:`MIGRATIONS` that apply to it."""

    path: str
    version: int
    keys: frozenset[str]
    params: EkfParams
    migrations: tuple[Migration, ...] = field(default_factory=tuple)

    def notes(self, used: EkfParams | None = None, overridden: Iterable[str] = ()) -> list[str]:
        """What changed in meaning since the file was saved, one line each, for a run with parameters ``used``
        (default: the file's) where ``overridden`` names were set after the file (command line)."""
        over = frozenset(overridden)
        used = self.params if used is None else used
        return [line for m in self.migrations for line in m.notes(self.path, self.keys, used, over)]


def _read_toml(path: str) -> dict[str, Any]:
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except OSError as e:
        raise ImutoolError(f"cannot read parameters: {e.strerror}", path=path) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ImutoolError(f"not a valid TOML parameters file: {e}", path=path) from None


def read_params_file(path: str) -> ParamsFile:
    """Read a parameters file: keys under ``[ekf]`` (as :meth:`EkfParams.to_toml` writes) or at the top level,
    ``version`` at the top level (or in the table); a file newer than :data:`PARAMS_VERSION` is refused, an older
    one gets the :data:`MIGRATIONS` since its version. Unknown names, wrong types and values out of range are
    refused (ImutoolError, one line)."""
    path = str(path)
    data = _read_toml(path)
    table = data.get("ekf", data)
    if not isinstance(table, dict):
        raise ImutoolError("[ekf] must be a table", path=path)
    table = dict(table)
    version = data.get("version", table.get("version", 0))
    table.pop("version", None)
    table.pop("imutool_params", None)  # a marker some early files carry
    if isinstance(version, bool) or not isinstance(version, int) or version < 0:
        raise ImutoolError(f"parameters file version {version!r}: expected a whole number ≥ 0", path=path)
    if version > PARAMS_VERSION:
        raise ImutoolError(
            f"parameters file version {version} is newer than this imutool reads ({PARAMS_VERSION}): "
            "update imutool, or save the parameters again with this one (--save-params)",
            path=path,
        )
    params = EkfParams.from_dict(table, source=path)
    applied = tuple(
        m for m in MIGRATIONS if version < m.before_version and (version > 0 or m.detect is None or m.detect(table))
    )
    return ParamsFile(path, version, frozenset(table), params, applied)


def params_from_options(
    params_file: str | None = None,
    items: Iterable[str] = (),
    *,
    update_every: int | None = None,
    mag_mode: str | None = None,
) -> tuple[EkfParams, list[str]]:
    """The run's :class:`EkfParams` and the notes of the file's migrations for it: the defaults, then the
    parameters file ``params_file`` (``--params``), then ``items`` (``--param NAME=VALUE``, each value parsed as
    its default's type), then ``update_every`` and ``mag_mode`` (the everyday flags; None: not given). The notes
    (:meth:`ParamsFile.notes`) say what changed in meaning since an older file was saved, for the names the
    command line did not set. A bad name or value is an ImutoolError naming ``--param``."""
    values: dict[str, Any] = {}
    overridden: set[str] = set()
    pfile = read_params_file(params_file) if params_file else None
    if pfile is not None:
        values.update(vars(pfile.params))
    defaults = EkfParams()
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip().replace("-", "_")
        if not sep or name not in PARAM_DOC:
            raise ImutoolError(f"--param {item!r}: expected NAME=VALUE with NAME one of {', '.join(PARAM_DOC)}")
        values[name] = parse_param_value(name, text.strip(), getattr(defaults, name))
        overridden.add(name)
    for name, value in (("update_every", update_every), ("mag_mode", mag_mode)):
        if value is not None:
            values[name] = value
            overridden.add(name)
    params = EkfParams.from_dict(values, source="--params/--param")
    return params, [] if pfile is None else pfile.notes(params, overridden)


def parse_param_value(name: str, text: str, default: Any) -> Any:
    """``--param NAME=TEXT``'s value as the type of the parameter's ``default`` (bool: true/false/1/0/yes/no;
    tuple: comma-separated numbers); an ImutoolError otherwise."""
    try:
        if isinstance(default, bool):
            if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError
            return text.lower() in ("true", "1", "yes")
        if isinstance(default, tuple):
            return tuple(float(x) for x in text.split(","))
        if isinstance(default, int):
            return int(text)
        if isinstance(default, float):
            return float(text)
        return text
    except ValueError:
        raise ImutoolError(f"--param {name}={text!r}: expected a value like {default!r}") from None
