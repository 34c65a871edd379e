"""The one TOML file of an `imutool live` service (``--config``): every option of :func:`run_live` by name.

    [source]                      # one of port / i2c / replay
    port = "/dev/ttyUSB0"
    protocol = "bridge"           # bridge | bridge-binary | a registered decoder
    baud = 115200
    aux = "/dev/ttyUSB1"          # GNSS RMC/VTG and gyrocompass HDT/THS (optional)
    aux_baud = 4800

    [filter]
    params_file = "ship.toml"     # as `filter --params`
    motion = "ship"               # ship | handheld | auto (decided after settle_s)
    settle_s = 60
    lever_arm = [0.0, 0.0, -2.0]  # m, body FRD, sensor from the roll centre
    mounting = "x,-y,-z"
    calibration_file = "cal.toml"

    [output]
    outputs = ["serial:///dev/ttyS1?baud=4800", "udp://192.168.1.255:10110", "tcp://0.0.0.0:10111"]
    sentences = ["HRM", "XDR", "PASHR"]
    rates = { XDR = 10, PASHR = 20 }
    talker = "II"

    [record]
    record = "/var/lib/imutool/live"
    rotate_s = 3600
    peak_state = "/var/lib/imutool/peak_hold.json"

Tables are for reading only: any key may stand in any table (or at the top level). An unknown key is refused
with the known ones; the command line's options override the file's.
"""

from __future__ import annotations

import inspect
from typing import Any

import tomllib

from formats.errors import ImutoolError

TABLES = ("source", "filter", "output", "record", "roll", "live")


def config_keys() -> list[str]:
    """The keys a configuration file may give: :func:`run_live`'s keyword options that are plain values."""
    from .route import run_live

    skip = {"params", "consumers", "hub", "stop", "log", "opener", "handle_signals"}
    return [p for p in inspect.signature(run_live).parameters if p not in skip]


def read_config(path: str) -> dict[str, Any]:
    """The options of a TOML configuration file, flattened (see the module docstring)."""
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except OSError as e:
        raise ImutoolError(f"cannot read the configuration: {e.strerror}", path=path) from None
    except tomllib.TOMLDecodeError as e:
        raise ImutoolError(f"not valid TOML: {e}", path=path) from None
    known = set(config_keys())
    out: dict[str, Any] = {}
    for key, value in data.items():
        items = value.items() if key in TABLES and isinstance(value, dict) else [(key, value)]
        for k, v in items:
            if k not in known:
                raise ImutoolError(f"unknown key {k!r}; known: {', '.join(sorted(known))}", path=path)
            out[k] = v
    return out
