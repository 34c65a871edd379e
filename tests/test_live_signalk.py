"""Signal K: imutool's own delta stream (hello, ≥ 5 deltas/s), and a real `signalk-server` (the npm package,
started on free loopback ports with a temporary configuration) that receives imutool's pushed deltas and its
NMEA 0183 sentences over UDP. The server is found by IMUTOOL_SIGNALK_SERVER, on PATH or in
/opt/signalk/node_modules/.bin; the tests skip with a reason where it (or node) is absent."""

from __future__ import annotations

import asyncio
import json
import math
import os
import shutil
import socket
import subprocess
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

import formats
from imutool.live import LiveHub, run_live
from imutool.live.signalk import delta
from imutool.sim import run_simulate

aiohttp = pytest.importorskip("aiohttp", reason="Signal K needs aiohttp (imutool[live])")

SERVER = (
    os.environ.get("IMUTOOL_SIGNALK_SERVER")
    or shutil.which("signalk-server")
    or next((p for p in ["/opt/signalk/node_modules/.bin/signalk-server"] if os.path.exists(p)), None)
)
needs_server = pytest.mark.skipif(
    not (SERVER and shutil.which("node")),
    reason="no signalk-server + node (npm install signalk-server; set IMUTOOL_SIGNALK_SERVER to its bin)",
)


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def ship_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("ship") / "ship.csv"
    run_simulate("ship-roll", path, seed=3, duration=120.0, rate_hz=50.0)
    return path


def get_json(url: str):
    with urllib.request.urlopen(url, timeout=5) as r:
        return json.loads(r.read())


def wait_json(url: str, timeout: float):
    end = time.monotonic() + timeout
    while True:
        try:
            return get_json(url)
        except OSError:
            if time.monotonic() > end:
                raise
            time.sleep(0.3)


@pytest.fixture
def signalk_server(tmp_path):
    """A signalk-server on a free loopback port, security off, NMEA 0183 input on a free UDP port."""
    port, udp = free_port(), free_port(socket.SOCK_DGRAM)
    cfg = tmp_path / "signalk"
    cfg.mkdir()
    settings = {
        "port": port,
        "ssl": False,
        "mdns": False,
        "interfaces": {"nmea-tcp": False, "tcp": False, "appstore": False},
        "pipedProviders": [
            {
                "id": "imutool-udp",
                "enabled": True,
                "pipeElements": [
                    {
                        "type": "providers/simple",
                        "options": {"logging": False, "type": "NMEA0183", "subOptions": {"type": "udp", "port": udp}},
                    }
                ],
            }
        ],
    }
    (cfg / "settings.json").write_text(json.dumps(settings))
    (cfg / "package.json").write_text('{"name": "signalk-server-config", "version": "0.0.1", "dependencies": {}}')
    env = {**os.environ, "PORT": str(port), "SKIP_ADMINUI_VERSION_CHECK": "true", "HOME": str(tmp_path)}
    log = open(tmp_path / "signalk.log", "w")
    proc = subprocess.Popen([SERVER, "-c", str(cfg)], env=env, stdout=log, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}"
    try:
        end = time.monotonic() + 90
        while True:
            try:
                get_json(f"{base}/signalk")
                break
            except OSError:
                if proc.poll() is not None or time.monotonic() > end:
                    pytest.fail(f"signalk-server did not start: {(tmp_path / 'signalk.log').read_text()[-2000:]}")
                time.sleep(0.3)
        _wait_udp_provider(proc, base, udp, end, tmp_path / "signalk.log")
        yield base, udp
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()


def _wait_udp_provider(proc, base: str, udp: int, end: float, log: Path) -> None:
    """The NMEA 0183 provider takes input some seconds after the HTTP server answers: send a probe (a magnetic
    heading of 0.0) until the server shows it."""
    probe = b"$IIHDG,0.0,,,,*49\r\n"
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        while True:
            s.sendto(probe, ("127.0.0.1", udp))
            try:
                get_json(f"{base}/signalk/v1/api/vessels/self/navigation/headingMagnetic")
                return
            except OSError:
                if proc.poll() is not None or time.monotonic() > end:
                    pytest.fail(f"signalk-server took no NMEA 0183 on UDP {udp}: {log.read_text()[-2000:]}")
                time.sleep(0.3)


def _estimate_roll_at(folder: Path, t: float) -> float:
    est = formats.read(sorted(folder.glob("estimate_*.csv"))[0])
    i = int(np.argmin(np.abs(est.time - t)))
    assert abs(est.time[i] - t) < 1e-3
    return float(est["roll"][i])


@needs_server
def test_push_to_signalk_server(signalk_server, ship_csv, tmp_path):
    """imutool's deltas pushed to a real signalk-server: its REST API returns the replay's last roll (≤ 0.01°)."""
    base, _udp = signalk_server
    hub = LiveHub()
    from imutool.live.signalk import SignalKPush

    res = run_live(
        replay=ship_csv, speed=4, duration=40, motion="ship", settle_s=5, record=tmp_path / "rec", hub=hub,
        consumers=[lambda h: SignalKPush(base, h)], log=lambda m: None, handle_signals=False,
    )  # fmt: skip
    last = hub.latest()
    assert last is not None and last.status == "A", last
    assert res.summary["status"] == "A"
    url = f"{base}/signalk/v1/api/vessels/self/navigation/attitude"
    got = None
    for _ in range(30):
        try:
            got = get_json(url)
            if abs(math.degrees(got["value"]["roll"]) - last.roll_deg) < 0.01:
                break
        except OSError:
            pass
        time.sleep(0.2)
    assert got is not None, "signalk-server has no navigation.attitude"
    roll_sk = math.degrees(got["value"]["roll"])
    assert abs(roll_sk - last.roll_deg) <= 0.01, (roll_sk, last.roll_deg)
    assert abs(roll_sk - _estimate_roll_at(tmp_path / "rec", last.t)) <= 0.01  # the replay's own estimate
    assert abs(math.degrees(got["value"]["pitch"]) - last.pitch_deg) <= 0.01
    # the server names a WebSocket client's source itself ('ws.<principal>'); the update's timestamp is kept
    assert str(got.get("$source", "")).startswith("ws."), got.get("$source")
    assert got["timestamp"].startswith(delta(last)["updates"][0]["timestamp"][:19])


@needs_server
def test_nmea_over_udp_into_signalk_server(signalk_server, ship_csv):
    """The server's own NMEA 0183 parser takes imutool's HDG (magnetic heading; HDT with a gyrocompass) and ROT
    over UDP and shows the values of the last sentences sent; its parser (nmea0183-signalk 3.x) has no XDR hook,
    so the roll reaches Signal K only through the deltas (checked if a later parser takes XDR's ROLL)."""
    base, udp = signalk_server
    mine = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # a copy of what the server is sent
    mine.bind(("127.0.0.1", 0))
    mine.settimeout(0.5)
    lines: list[str] = []
    reader = threading.Thread(target=_collect, args=(mine, lines), daemon=True)
    reader.start()
    run_live(
        replay=ship_csv, speed=4, duration=45, motion="ship", settle_s=5, sentences=["XDR", "HDT", "ROT"],
        outputs=[f"udp://127.0.0.1:{udp}", f"udp://127.0.0.1:{mine.getsockname()[1]}"], rates={"HDT": 10, "ROT": 10},
        log=lambda m: None, handle_signals=False,
    )  # fmt: skip
    time.sleep(0.8)
    mine.close()
    reader.join(5)
    last = {}
    for line in lines:
        body = line.strip().lstrip("$").split("*")[0].split(",")
        last[body[0][2:]] = body[1:]
    assert {"XDR", "HDG", "ROT"} <= set(last), sorted(last)
    nav = wait_json(f"{base}/signalk/v1/api/vessels/self/navigation", 10.0)
    for _ in range(20):  # the last datagrams may still be on their way
        if abs(math.degrees(nav.get("rateOfTurn", {}).get("value", 1e9)) * 60.0 - float(last["ROT"][0])) <= 0.06:
            break
        time.sleep(0.3)
        nav = get_json(f"{base}/signalk/v1/api/vessels/self/navigation")
    assert last["ROT"][1] == "A", "the run ended with status V"
    assert "rateOfTurn" in nav, sorted(nav)
    assert nav["rateOfTurn"]["$source"].endswith(".II") and nav["rateOfTurn"]["sentence"] == "ROT"
    assert abs(math.degrees(nav["rateOfTurn"]["value"]) * 60.0 - float(last["ROT"][0])) <= 0.06  # deg/min
    assert abs(math.degrees(nav["headingMagnetic"]["value"]) - float(last["HDG"][0])) <= 0.06
    if "attitude" in nav:  # a parser that takes XDR's ROLL: the same roll
        roll = float(last["XDR"][last["XDR"].index("ROLL") - 2])
        assert abs(math.degrees(nav["attitude"]["value"]["roll"]) - roll) <= 0.01


def _collect(sock: socket.socket, lines: list[str]) -> None:
    while True:
        try:
            data = sock.recv(65536)
        except TimeoutError:
            continue
        except OSError:
            return
        lines.extend(x for x in data.decode().splitlines() if x)


def test_own_stream_hello_and_rate(ship_csv):
    """A plain WebSocket client of imutool's /signalk/v1/stream: the hello, then ≥ 5 deltas per second."""
    from imutool.live.http import BridgeServer

    hub = LiveHub()
    servers: list[BridgeServer] = []
    seen: dict = {}

    def client(port: int) -> None:
        async def main() -> None:
            async with aiohttp.ClientSession() as s, s.ws_connect(f"http://127.0.0.1:{port}/signalk/v1/stream") as ws:
                seen["hello"] = json.loads((await ws.receive()).data)
                await ws.receive(timeout=90)  # the first delta: the filter has settled (no delta while V)
                deltas, t0 = [], time.monotonic()
                while time.monotonic() - t0 < 3.0:
                    m = await ws.receive(timeout=5)
                    deltas.append(json.loads(m.data))
                seen["deltas"] = deltas

        asyncio.run(main())

    def start(h):
        srv = BridgeServer(h, "127.0.0.1", 0)
        servers.append(srv)
        th = threading.Thread(target=client, args=(srv.port,))
        th.start()
        seen["thread"] = th
        return srv

    run_live(
        replay=ship_csv, speed=1, duration=100, motion="ship", settle_s=5, hub=hub, consumers=[start],
        log=lambda m: None, handle_signals=False, stop=lambda: "client done" if "deltas" in seen else "",
    )  # fmt: skip
    seen["thread"].join(10)
    hello = seen["hello"]
    assert hello["name"] == "imutool" and "version" in hello and hello["self"].startswith("vessels.")
    deltas = seen["deltas"]
    assert len(deltas) / 3.0 >= 5.0, len(deltas)
    v = deltas[-1]["updates"][0]
    assert v["source"]["label"] == "imutool" and v["timestamp"].endswith("Z")
    paths = {x["path"] for x in v["values"]}
    assert {"navigation.attitude", "navigation.rateOfTurn"} <= paths
    att = next(x["value"] for x in v["values"] if x["path"] == "navigation.attitude")
    assert set(att) == {"roll", "pitch", "yaw"} and abs(att["roll"]) < math.radians(60)


def test_http_listen_address_and_offline_assets():
    """--http: loopback by default, a warning for another address; the page's assets come from the package
    and name no other host (no CDN)."""
    from formats.errors import ImutoolError
    from imutool.live.http import BridgeServer, parse_listen

    assert parse_listen("8080") == ("127.0.0.1", 8080)
    assert parse_listen("0.0.0.0:8081") == ("0.0.0.0", 8081)
    assert parse_listen("[::1]:8082") == ("::1", 8082)
    with pytest.raises(ImutoolError):
        parse_listen("localhost:http")
    logs: list[str] = []
    srv = BridgeServer(LiveHub(), "0.0.0.0", 0, log=logs.append)
    try:
        assert any("not on loopback" in m for m in logs), logs
        base = f"http://127.0.0.1:{srv.port}"
        page = urllib.request.urlopen(f"{base}/", timeout=5).read().decode()
        assets = [
            urllib.request.urlopen(f"{base}/static/{n}", timeout=5).read().decode() for n in ("bridge.css", "bridge.js")
        ]
        assert get_json(f"{base}/api/latest") is None  # nothing published yet
        with pytest.raises(urllib.error.HTTPError):
            urllib.request.urlopen(f"{base}/static/../http.py", timeout=5)
    finally:
        srv.stop()
    assert 'src="/static/bridge.js"' in page
    for text in [page, *assets]:
        assert "http://" not in text.replace("http://www.w3.org/2000/svg", "") and "https://" not in text
    logs.clear()
    srv = BridgeServer(LiveHub(), "127.0.0.1", 0, log=logs.append)
    srv.stop()
    assert not any("not on loopback" in m for m in logs)
