"""The bridge display of `imutool live --http [HOST:]PORT`: a web page and its WebSocket feed, and imutool's own
Signal K stream, served by aiohttp on a thread of its own (a hub consumer).

Why aiohttp: one well-kept package gives the HTTP server, the WebSocket server (and the client the Signal K
pusher uses) on asyncio, with no ASGI server beside it; it is the optional extra ``imutool[live]``.

Routes:

- ``/`` the page (``static/index.html``, its CSS and JS from the installed package: no internet needed);
- ``/ws`` the page's feed: ``{"type": "history", "items": [...]}`` (the last 10 minutes, ~1 Hz) once, then
  ``{"type": "snapshot", ...}`` (:meth:`LiveSnapshot.as_dict`) at most ``max_hz`` per second (the newest only,
  so a slow browser never falls behind), and ``{"type": "stopped", "reason": ...}`` when the source stops;
- ``POST /api/reset`` asks the engine to reset the peak-hold (it logs the reset and reports it on HRM);
- ``/api/latest`` the newest snapshot as JSON;
- ``/signalk`` (discovery) and ``/signalk/v1/stream`` (Signal K hello, then deltas; ``?subscribe=none``: hello only).
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
from collections.abc import Callable
from importlib import resources
from typing import Any

from formats.errors import ImutoolError

from . import signalk
from .hub import LiveHub

MAX_HZ = 20.0  # messages per second at most, per client (the newest snapshot only)
HISTORY_S = 600.0  # the trend's span (s)
STATIC = ("index.html", "bridge.css", "bridge.js")
CONTENT_TYPES = {".html": "text/html", ".css": "text/css", ".js": "application/javascript"}


def parse_listen(spec: str | int) -> tuple[str, int]:
    """``[HOST:]PORT`` → (host, port); the host defaults to 127.0.0.1 (loopback)."""
    text = str(spec).strip()
    host, _, port = text.rpartition(":")
    host = host.strip("[]") or "127.0.0.1"
    try:
        p = int(port)
    except ValueError:
        raise ImutoolError(f"--http {text!r}: expected [HOST:]PORT, e.g. 8080 or 0.0.0.0:8080") from None
    if not 0 <= p <= 65535:
        raise ImutoolError(f"--http {text!r}: port out of range")
    return host, p


def is_loopback(host: str) -> bool:
    """True for a loopback address (the only one that keeps the ship's data on this computer)."""
    return host in ("localhost", "::1") or host.startswith("127.")


class BridgeServer:
    """The page, its feed and the Signal K stream on ``host``:``port`` (0: any free port; see ``.port``).

    Started by the constructor (raises ImutoolError when the address cannot be bound); ``stop()`` sends every
    client the stop's reason, closes them and ends the thread."""

    def __init__(
        self, hub: LiveHub, host: str = "127.0.0.1", port: int = 0, *, max_hz: float = MAX_HZ,
        log: Callable[[str], None] | None = None,
    ) -> None:  # fmt: skip
        self.hub, self.host, self.port, self.max_hz = hub, host, int(port), float(max_hz)
        self.log = log or (lambda m: None)
        self.clients = {"page": 0, "signalk": 0}
        self.messages = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="imutool-http", daemon=True)
        self._thread.start()
        self._ready.wait(30.0)
        if self._error is not None:
            raise ImutoolError(f"--http {host}:{port}: cannot serve ({self._error})")
        where = f"http://{host if ':' not in host else f'[{host}]'}:{self.port}/"
        self.url = where
        self.log(f"bridge display at {where} (Signal K stream at {where.replace('http', 'ws', 1)}signalk/v1/stream)")
        if not is_loopback(host):
            self.log(
                f"the bridge display listens on {host}, not on loopback: anyone on that network sees the ship's "
                "data and can reset the peak-hold"
            )

    # ------------------------------------------------------------------------------------------- the thread
    def _run(self) -> None:
        try:
            asyncio.run(self._serve())
        except BaseException as e:  # reported to the constructor when it happens at start
            self._error = e
            self._ready.set()

    async def _serve(self) -> None:
        from aiohttp import web

        self._loop = asyncio.get_running_loop()
        self._stopping = asyncio.Event()
        self._tasks: set[asyncio.Task] = set()
        app = web.Application()
        app.router.add_get("/", self._index)
        app.router.add_get("/static/{name}", self._static)
        app.router.add_get("/ws", self._page_ws)
        app.router.add_post("/api/reset", self._reset)
        app.router.add_get("/api/latest", self._latest)
        app.router.add_get("/signalk", self._discovery)
        app.router.add_get("/signalk/v1/stream", self._signalk_ws)
        runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await runner.setup()
        site = web.TCPSite(runner, self.host, self.port, reuse_address=True)
        await site.start()
        server = getattr(site, "_server", None)
        if server is not None and server.sockets:
            self.port = int(server.sockets[0].getsockname()[1])
        self._ready.set()
        await self._stopping.wait()
        if self._tasks:  # the clients send the stop's reason and close
            await asyncio.wait(list(self._tasks), timeout=2.0)
        await runner.cleanup()

    def stop(self) -> None:
        """Tell every client the reason the source stopped, close them and the server."""
        if self._loop is not None and self._stopping is not None:
            try:
                self._loop.call_soon_threadsafe(self._stopping.set)
            except RuntimeError:  # the loop already ended
                pass
        self._thread.join(10.0)

    # ------------------------------------------------------------------------------------------- the routes
    async def _index(self, request: Any) -> Any:
        return self._file("index.html")

    async def _static(self, request: Any) -> Any:
        from aiohttp import web

        name = request.match_info["name"]
        if name not in STATIC:
            raise web.HTTPNotFound()
        return self._file(name)

    def _file(self, name: str) -> Any:
        from aiohttp import web

        body = resources.files("imutool.live").joinpath("static", name).read_bytes()
        ctype = CONTENT_TYPES[name[name.rfind(".") :]]
        return web.Response(body=body, content_type=ctype, headers={"Cache-Control": "no-cache"})

    async def _reset(self, request: Any) -> Any:
        from aiohttp import web

        who = f"the bridge display ({request.remote})"
        self.hub.request_reset(who)
        self.log(f"peak-hold reset asked by {who}")
        return web.json_response({"ok": True, "requested_utc": signalk.iso_utc(time.time())})

    async def _latest(self, request: Any) -> Any:
        from aiohttp import web

        snap = self.hub.latest()
        return web.json_response(snap.as_dict() if snap is not None else None)

    async def _discovery(self, request: Any) -> Any:
        from aiohttp import web

        from imutool import __version__

        host = request.host
        return web.json_response(
            {
                "endpoints": {
                    "v1": {"version": signalk.SIGNALK_VERSION, "signalk-ws": f"ws://{host}/signalk/v1/stream"}
                },
                "server": {"id": "imutool", "version": __version__},
            }
        )

    async def _page_ws(self, request: Any) -> Any:
        history = {"type": "history", "items": [s.as_dict() for s in self.hub.history(HISTORY_S)]}
        return await self._feed(request, "page", history, lambda s: {"type": "snapshot", **s.as_dict()})

    async def _signalk_ws(self, request: Any) -> Any:
        subscribe = request.query.get("subscribe", "self")
        make = (lambda s: None) if subscribe == "none" else signalk.delta
        return await self._feed(request, "signalk", signalk.hello(), make)

    async def _feed(self, request: Any, kind: str, first: dict, make: Callable[[Any], dict | None]) -> Any:
        """Send ``first``, then ``make(snapshot)`` of each new snapshot (≤ max_hz, newest only) until the
        client goes or the server stops; a page is told why the source stopped."""
        from aiohttp import web

        ws = web.WebSocketResponse(heartbeat=10.0)
        await ws.prepare(request)
        task = asyncio.current_task()
        assert task is not None and self._stopping is not None
        self._tasks.add(task)
        self.clients[kind] += 1
        reader = asyncio.ensure_future(ws.receive())  # a closed client ends the feed at once
        try:
            await ws.send_str(json.dumps(first))
            last = None
            period = 1.0 / self.max_hz
            while not ws.closed and not self._stopping.is_set() and not reader.done():
                snap = self.hub.latest()
                if snap is not None and snap is not last:
                    last = snap
                    msg = make(snap)
                    if msg is not None:
                        await ws.send_str(json.dumps(msg))
                        self.messages += 1
                if self.hub.closed and kind == "page":
                    break
                await asyncio.wait([reader], timeout=period)
            if kind == "page" and self.hub.closed and not ws.closed:
                await ws.send_str(json.dumps({"type": "stopped", "reason": self.hub.stop_reason or "stopped"}))
        except (ConnectionError, RuntimeError):
            pass
        finally:
            reader.cancel()
            self.clients[kind] -= 1
            self._tasks.discard(task)
            if not ws.closed:
                await ws.close()
        return ws


def http_consumer(listen: str | int, log: Callable[[str], None] | None = None) -> Callable[[LiveHub], BridgeServer]:
    """A :func:`run_live` consumer serving the bridge display on ``[HOST:]PORT``."""
    host, port = parse_listen(listen)
    return lambda hub: BridgeServer(hub, host, port, log=log)
