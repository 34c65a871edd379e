"""The simulator: vessel/foot motion, a MEMS sensor model and truth columns (``ref_*``).

Scenarios are functions ``f(duration=None, rate_hz=None, seed=0, **options) -> Recording`` registered by name
in :data:`SCENARIOS` (module path, function) and imported on use. Every scenario is deterministic for a seed.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from formats import Recording
from formats.errors import ImutoolError

# scenario name -> (module, function)
SCENARIOS: dict[str, tuple[str, str]] = {
    "ship-roll": ("imutool.sim.ship", "ship_roll"),
    "sea-state": ("imutool.sim.ship", "sea_state"),
    "turn": ("imutool.sim.ship", "turning_ship"),
    "compass-swing": ("imutool.sim.ship", "compass_swing"),
    "mag-sphere": ("imutool.sim.ship", "mag_sphere"),
    "static": ("imutool.sim.ship", "static"),
    "heave-platform": ("imutool.sim.heave", "heave_platform"),
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
    for name, (mod, fn) in SCENARIOS.items():
        if importlib.util.find_spec(mod) is not None:
            out.append(name)
    return out


def simulate(name: str, **options) -> Recording:
    """Run a scenario by name (see :data:`SCENARIOS`)."""
    return scenario(name)(**options)
