"""`imutool live`: a live IMU turned into an electronic inclinometer's outputs (MSC.363(92)).

Modules, one concept each: `hub` (snapshots for displays), `sources` (live and replayed input),
`stepper` (the small-block EKF, shared with the streamed `filter`), `engine` (the loop), `status`
(A/V and its causes), `rollstats` (incremental amplitude, period and peak-hold), `outputs` (serial,
UDP, TCP writers on their own threads), `sentences` (the scheduler of IEC 61162 sentences),
`config` (the TOML file) and `route` (`run_live`).
"""

from imutool.live.hub import LiveHub, LiveSnapshot, Subscription
from imutool.live.route import run_live

__all__ = ["LiveHub", "LiveSnapshot", "Subscription", "run_live"]
