"""The simulator: vessel/foot motion, a MEMS sensor model and truth columns (``ref_*``).

Scenarios are functions ``f(duration=None, rate_hz=None, seed=0, **options) -> Recording`` registered by name
in :data:`SCENARIOS` (module path, function) and imported on use. Every scenario is deterministic for a seed.
:func:`run_simulate` (a scenario written to a file) is the route behind ``imutool simulate SCENARIO -o OUT``.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import os
from collections.abc import Callable
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.errors import ImutoolError
from imutool.routes import RouteResult, Stage

# scenario name -> (module, function)
SCENARIOS: dict[str, tuple[str, str]] = {
    "ship-roll": ("imutool.sim.ship", "ship_roll"),
    "turn": ("imutool.sim.ship", "turning_ship"),
    "ship-at-sea": ("imutool.sim.voyage", "ship_at_sea"),
    "static": ("imutool.sim.ship", "static"),
    "sea-state": ("imutool.sim.sea", "sea_state"),
    "parametric-roll": ("imutool.sim.parametric", "parametric_roll"),
    "heave-platform": ("imutool.sim.sea", "heave_platform"),
    "compass-swing": ("imutool.sim.magnetic", "compass_swing"),
    "mag-sphere": ("imutool.sim.magnetic", "mag_sphere"),
    "walk": ("imutool.sim.walk", "walk"),
    "accel-array": ("imutool.sim.accel_array", "accel_array"),
    "six-position": ("imutool.sim.calib_positions", "six_position"),
}


def scenario(name: str) -> Callable[..., Recording]:
    """The scenario function registered under ``name``."""
    if name not in SCENARIOS:
        raise ImutoolError(f"unknown scenario {name!r}; known: {', '.join(available())}")
    mod, fn = SCENARIOS[name]
    try:
        return getattr(importlib.import_module(mod), fn)
    except (ModuleNotFoundError, AttributeError):
        raise ImutoolError(f"scenario {name!r} is not available in this build") from None


def available() -> list[str]:
    out = []
    for name, (mod, _fn) in SCENARIOS.items():
        if importlib.util.find_spec(mod) is not None:
            out.append(name)
    return out


def options(name: str) -> list[str]:
    """The option names a scenario accepts (besides duration, rate_hz and seed)."""
    params = inspect.signature(scenario(name)).parameters
    return [
        p
        for p in params
        if p not in ("duration", "rate_hz", "seed")
        and params[p].kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    ]


def simulate(name: str, **options_) -> Recording:
    """Run a scenario by name (see :data:`SCENARIOS`); an unknown option is refused with the valid names."""
    valid = options(name)
    unknown = [k for k in options_ if k not in valid and k not in ("duration", "rate_hz", "seed")]
    if unknown:
        raise ImutoolError(
            f"scenario {name!r} has no option {', '.join(map(repr, unknown))}; valid: {', '.join(valid)}"
        )

    defaults = {k: v.default for k, v in inspect.signature(scenario(name)).parameters.items()}
    dur, rate = options_.get("duration", defaults.get("duration")), options_.get("rate_hz", defaults.get("rate_hz"))
    try:  # a scenario's own defaults are small; an unknown default rate counts as 1 kHz
        rows = float(dur or 0.0) * float(rate or 1000.0)
    except (TypeError, ValueError):
        rows = 0.0
    if not rows < MAX_ROWS:  # also NaN: an array that size cannot be allocated
        raise ImutoolError(f"scenario {name!r}: --duration {dur} s gives {rows:.3g} samples; at most {MAX_ROWS:.0e}")
    for key, value in options_.items():
        _check_option(name, key, value, defaults.get(key))
    try:
        return scenario(name)(**options_)
    except (ZeroDivisionError, FloatingPointError, OverflowError) as e:  # a value the scenario's physics cannot take
        given = ", ".join(f"{k}={v!r}" for k, v in options_.items()) or "its defaults"
        raise ImutoolError(f"scenario {name!r} cannot run with {given}: {e}") from None


def run_simulate(
    name: str,
    output: str | os.PathLike,
    *,
    seed: int = 0,
    duration: float | None = None,
    rate_hz: float | None = None,
    settings: dict[str, Any] | None = None,
    stage: Stage | None = None,
) -> RouteResult:
    """Scenario ``name`` (:data:`SCENARIOS`) with ``seed``, ``duration`` s and ``rate_hz`` (None: the scenario's
    default) and its own options ``settings`` (:func:`options`), written to ``output`` (format from the
    extension) with the scenario and seed in its metadata. ``stage(label)`` as it simulates, then writes."""
    output = os.fspath(output)
    opts = dict(settings or {})
    if duration is not None:
        opts["duration"] = duration
    if rate_hz is not None:
        opts["rate_hz"] = rate_hz
    if stage is not None:
        stage(f"simulating {name}")
    rec = simulate(name, seed=seed, **opts)
    rec.meta["scenario"] = name
    rec.meta["seed"] = seed
    if stage is not None:
        stage(f"writing {output}")
    formats.write(rec, output)
    summary = {
        "scenario": name,
        "output": output,
        "rows": len(rec),
        "duration_s": round(rec.duration, 3),
        "rate_hz": round(rec.rate_hz, 3),
        "channels": list(rec.channels),
    }
    return RouteResult(summary, recording=rec)


def _check_option(name: str, key: str, value: object, default: object) -> None:
    """A scenario option's value against its default's kind: a number where the default is one (finite; > 0 for a
    period, a rate or a duration), one line naming the option otherwise."""
    if isinstance(default, bool) or not isinstance(default, (int, float)) or default is None:
        return
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ImutoolError(f"scenario {name!r}: option {key}={value!r} must be a number (default {default!r})")
    if not np.isfinite(float(value)):
        raise ImutoolError(f"scenario {name!r}: option {key}={value!r} must be finite")
    positive = "period" in key or key.endswith(("_hz", "_s")) or key in ("duration", "rate_hz", "tp")
    if positive and default > 0 and not float(value) > 0:
        raise ImutoolError(f"scenario {name!r}: option {key}={value!r} must be > 0 (default {default!r})")
    if key in _NONNEGATIVE or any(w in key for w in ("noise", "damping", "fraction")):
        if not float(value) >= 0:
            raise ImutoolError(f"scenario {name!r}: option {key}={value!r} must be ≥ 0 (default {default!r})")
    if key in _COUNTS and not (float(value) >= 1 and float(value) == int(value)):
        raise ImutoolError(f"scenario {name!r}: option {key}={value!r} must be a whole number ≥ 1")
    if key == "gamma" and not float(value) >= 1:  # JONSWAP peak enhancement: 1 is Pierson-Moskowitz
        raise ImutoolError(f"scenario {name!r}: option gamma={value!r} must be ≥ 1 (JONSWAP; default {default!r})")


# scenario options that are sizes (a negative wave height or count has no meaning) and counts
_NONNEGATIVE = ("hs", "severity", "turns", "translation", "r", "swing_height", "step_length")
_COUNTS = ("components", "n_steps", "poses")


MAX_ROWS = 2e8  # samples one simulation may produce (≈ 11.6 days at 200 Hz; 10 columns of float64 = 16 GB)
