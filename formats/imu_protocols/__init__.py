"""Raw-IMU serial protocols that MEMS units speak, as incremental decoders (bytes in, SI samples out).

``PROTOCOLS[name]`` → the decoder class; ``make_decoder(name, **options)``. Each decoder has ``feed(bytes) ->``
:class:`ImuSamples` (gyro rad/s, accel m/s² specific force, mag µT, all body FRD; the vendor's attitude in
imutool's signs), a ``stats`` :class:`DecoderStats` (good frames, bad checksums, garbage bytes, resyncs) and a
``conventions`` text (the vendor's axes and signs and the conversion) for a recording's metadata.

- ``vectornav``: VectorNav ASCII ``$VNYMR`` / ``$VNIMU`` (:mod:`.vectornav`)
- ``witmotion``: WitMotion WT901/JY901 binary 0x55 packets (:mod:`.witmotion`)
"""

from __future__ import annotations

from typing import Any

from formats.errors import ImutoolError

from .base import DecoderStats, ImuSamples
from .vectornav import VectorNavDecoder
from .witmotion import WitMotionDecoder

PROTOCOLS: dict[str, type] = {"vectornav": VectorNavDecoder, "witmotion": WitMotionDecoder}

__all__ = ["PROTOCOLS", "DecoderStats", "ImuSamples", "VectorNavDecoder", "WitMotionDecoder", "make_decoder"]


def make_decoder(name: str, **options: Any) -> Any:
    """A fresh decoder of protocol ``name`` (options: e.g. ``mag_ut_per_count`` for witmotion)."""
    if name not in PROTOCOLS:
        raise ImutoolError(f"IMU protocol {name!r}: known {', '.join(sorted(PROTOCOLS))}")
    return PROTOCOLS[name](**options)
