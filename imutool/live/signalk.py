"""Signal K for `imutool live`: the hello and delta messages of imutool's own stream, and a pusher of deltas to
an existing Signal K server.

Paths (Signal K specification 1.7, SI units, radians): ``navigation.attitude`` {roll, pitch, yaw} (roll + list
to starboard, pitch + bow up, yaw = the heading, + clockwise; null without a heading), ``navigation.rateOfTurn``
(rad/s, + to starboard), ``navigation.headingTrue`` or ``navigation.headingMagnetic`` (rad) by the heading's
reference. The specification has no heave path, so heave is not sent. Every update carries its ``source``
({label, type}) and its ``timestamp`` (ISO 8601 UTC of the estimate). A delta with status V is not sent: a
Signal K value has no validity flag, and a stale roll shown as current is worse than an old timestamp.

    pusher = SignalKPush("ws://127.0.0.1:3000/signalk/v1/stream", hub)   # a hub consumer: pusher.stop()
"""

from __future__ import annotations

import asyncio
import json
import math
import threading
import time
from collections.abc import Callable
from datetime import datetime, timezone
from typing import Any
from urllib.parse import urlparse, urlunparse

from formats.errors import ImutoolError

from .hub import LiveHub, LiveSnapshot

SIGNALK_VERSION = "1.7.0"
SOURCE_LABEL = "imutool"
PUSH_HZ = 10.0  # deltas per second pushed (the hub's rate at real-time speed)


def iso_utc(epoch_s: float) -> str:
    """ISO 8601 UTC with milliseconds and Z."""
    return datetime.fromtimestamp(epoch_s, timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def hello(self_id: str = "urn:mrn:signalk:uuid:imutool") -> dict[str, Any]:
    """The hello message of imutool's Signal K stream."""
    from imutool import __version__

    return {
        "name": "imutool",
        "version": __version__,
        "self": f"vessels.{self_id}",
        "roles": ["master", "main"],
        "timestamp": iso_utc(time.time()),
    }


def delta(snap: LiveSnapshot, label: str = SOURCE_LABEL) -> dict[str, Any] | None:
    """One Signal K delta of a snapshot (None when its status is V or its roll is not a number)."""
    if snap.status != "A" or not math.isfinite(snap.roll_deg):
        return None
    rad = math.radians
    yaw = rad(snap.heading_deg) if snap.heading_deg is not None else None
    values: list[dict[str, Any]] = [
        {"path": "navigation.attitude", "value": {"roll": rad(snap.roll_deg), "pitch": rad(snap.pitch_deg), "yaw": yaw}}
    ]
    if snap.rot_deg_min is not None and math.isfinite(snap.rot_deg_min):
        values.append({"path": "navigation.rateOfTurn", "value": rad(snap.rot_deg_min) / 60.0})
    if yaw is not None:
        path = "navigation.headingTrue" if snap.heading_ref == "true" else "navigation.headingMagnetic"
        values.append({"path": path, "value": yaw})
    update = {"source": {"label": label, "type": "imutool"}, "timestamp": iso_utc(snap.utc), "values": values}
    return {"context": "vessels.self", "updates": [update]}


def stream_url(url: str) -> str:
    """The WebSocket stream URL of a Signal K server given as ws://, wss://, http:// or https:// HOST:PORT[/path]."""
    u = urlparse(url)
    scheme = {"http": "ws", "https": "wss", "ws": "ws", "wss": "wss"}.get(u.scheme)
    if scheme is None or not u.hostname:
        raise ImutoolError(f"--signalk-push {url!r}: expected ws://HOST:PORT or http://HOST:PORT of a Signal K server")
    path = u.path if u.path.rstrip("/").endswith("/stream") else "/signalk/v1/stream"
    return urlunparse((scheme, u.netloc, path, "", "subscribe=none", ""))


class SignalKPush:
    """Push the hub's deltas (≤ ``hz`` per second, the newest only) to a Signal K server's WebSocket stream, on
    its own thread; reconnects every ``retry_s`` while the server is away; the last delta is sent at stop.

    The server must accept deltas from this client (security off, or a device token given as ``token``)."""

    def __init__(
        self, url: str, hub: LiveHub, *, hz: float = PUSH_HZ, token: str | None = None, retry_s: float = 2.0,
        log: Callable[[str], None] | None = None,
    ) -> None:  # fmt: skip
        self.url = stream_url(url)
        self.hub, self.hz, self.token, self.retry_s = hub, float(hz), token, float(retry_s)
        self.log = log or (lambda m: None)
        self.sent = 0
        self.connects = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="imutool-signalk-push", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Send the newest delta, close the connection and end the thread."""
        self._stop.set()
        self._thread.join(5.0)

    def _run(self) -> None:
        asyncio.run(self._main())

    async def _main(self) -> None:
        import aiohttp

        headers = {"Authorization": f"Bearer {self.token}"} if self.token else {}
        last_utc = None
        async with aiohttp.ClientSession(headers=headers) as session:
            while not self._stop.is_set():
                try:
                    async with session.ws_connect(self.url, heartbeat=10.0) as ws:
                        self.connects += 1
                        self.log(f"Signal K: pushing deltas to {self.url}")
                        while True:
                            stopping = self._stop.is_set()
                            snap = self.hub.latest()
                            if snap is not None and snap.utc != last_utc:
                                msg = delta(snap)
                                last_utc = snap.utc
                                if msg is not None:
                                    await ws.send_str(json.dumps(msg))
                                    self.sent += 1
                            if stopping or ws.closed:
                                break
                            await asyncio.sleep(1.0 / self.hz)
                        if stopping:
                            await asyncio.sleep(0.2)  # let the server take the last delta before the close
                            return
                except (aiohttp.ClientError, OSError, asyncio.TimeoutError) as e:
                    self.log(f"Signal K: {self.url} not reachable ({e}); retrying in {self.retry_s:g} s")
                if self._stop.wait(self.retry_s):
                    return
