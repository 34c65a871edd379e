"""The simulator: vessel/foot motion, a MEMS sensor model and truth columns (``ref_*``).

Scenarios are functions ``f(duration=None, rate_hz=None, seed=0, **options) -> Recording`` registered by name
in :data:`SCENARIOS` (module path, function) and imported on use. Every scenario is deterministic for a seed.
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable

from formats import Recording
from formats.errors import ImutoolError

# scenario name -> (module, function)
SCENARIOS: dict[str, tuple[str, str]] = {
    "ship-roll": ("imutool.sim.ship", "ship_roll"),
    "turn": ("imutool.sim.ship", "turning_ship"),
    "static": ("imutool.sim.ship", "static"),
    "sea-state": ("imutool.sim.sea", "sea_state"),
    "heave-platform": ("imutool.sim.sea", "heave_platform"),
    "compass-swing": ("imutool.sim.magnetic", "compass_swing"),
    "mag-sphere": ("imutool.sim.magnetic", "mag_sphere"),
    "walk": ("imutool.sim.walk", "walk"),
    "accel-array": ("imutool.sim.accel_array", "accel_array"),
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


def simulate(name: str, **options) -> Recording:
    """Run a scenario by name (see :data:`SCENARIOS`)."""
    return scenario(name)(**options)
