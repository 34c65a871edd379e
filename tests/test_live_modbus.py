"""`imutool live` from a Modbus RTU sensor: the live Modbus source against a real pymodbus RTU server.

The server (pymodbus's own ``ModbusSerialServer``, RTU framing) and the live source (capture's ``ModbusPoller``,
pymodbus's RTU client) each open a pseudo-terminal; a relay thread joins the two terminals' master ends like a
null-modem cable, so every request and answer crosses a serial line with its CRC."""

from __future__ import annotations

import asyncio
import os
import select
import threading
import time

import numpy as np
import pytest

pytest.importorskip("pymodbus", reason="the Modbus source needs pymodbus (the [modbus] extra)")
pytest.importorskip("serial", reason="the Modbus source needs pyserial")

from pymodbus.server import ModbusSerialServer  # noqa: E402
from pymodbus.simulator import DataType, SimData, SimDevice  # noqa: E402

from imutool.capture.serve import open_pty  # noqa: E402
from imutool.live import LiveHub, run_live  # noqa: E402
from imutool.live.sources import modbus_source  # noqa: E402

UNIT = 3
GYRO_SCALE, ACCEL_SCALE = 1e-4, 1e-3  # rad/s and m/s² per count
PROFILE = f"""[device]
name = "test IMU"
unit = {UNIT}
baud = 115200
rate_hz = 20
""" + "".join(
    f'[[register]]\nname = "{c}_{a}"\naddress = {10 + 3 * k + i}\ntype = "int16"\nscale = {s}\nunit = "{u}"\n'
    for k, (c, s, u) in enumerate((("gyro", GYRO_SCALE, "rad/s"), ("accel", ACCEL_SCALE, "m/s^2")))
    for i, a in enumerate("xyz")
)


def _counts(gyro, accel) -> list[int]:
    g = np.round(np.asarray(gyro) / GYRO_SCALE).astype(int)
    a = np.round(np.asarray(accel) / ACCEL_SCALE).astype(int)
    return [int(v) & 0xFFFF for v in (*g, *a)]


class NullModem:
    """Two pseudo-terminals whose master ends are joined by a thread: a serial cable between their devices."""

    def __init__(self) -> None:
        self.a, self.a_slave, self.a_name = open_pty()
        self.b, self.b_slave, self.b_name = open_pty()
        self.stop = threading.Event()
        self.th = threading.Thread(target=self._run, daemon=True)
        self.th.start()

    def _run(self) -> None:
        peer = {self.a: self.b, self.b: self.a}
        while not self.stop.is_set():
            r, _, _ = select.select(list(peer), [], [], 0.05)
            for fd in r:
                try:
                    os.write(peer[fd], os.read(fd, 4096))
                except OSError:
                    return

    def close(self) -> None:
        self.stop.set()
        self.th.join(1.0)
        for fd in (self.a, self.a_slave, self.b, self.b_slave):
            os.close(fd)


class Server:
    """pymodbus's RTU server (a simulated device) on a serial device, in its own thread and event loop;
    ``set(counts)`` changes the input registers 10..15 it answers with (its action fills them per request)."""

    def __init__(self, port: str, counts: list[int]) -> None:
        self.counts = list(counts)
        self.requests = 0
        regs = SimData(0, count=32, values=0, datatype=DataType.REGISTERS)
        self.device = SimDevice(UNIT, simdata=[regs], action=self._action)
        self.loop = asyncio.new_event_loop()
        self.server: ModbusSerialServer | None = None
        self.ready = threading.Event()
        self.th = threading.Thread(target=self._run, args=(port,), daemon=True)
        self.th.start()
        assert self.ready.wait(10.0), "the pymodbus server did not start"

    def set(self, counts: list[int]) -> None:
        self.counts = list(counts)

    async def _action(self, function_code, start_address, address, count, current_registers, set_values):
        self.requests += 1
        for i in range(count):
            k = address + i - 10
            if 0 <= k < len(self.counts):
                current_registers[address - start_address + i] = self.counts[k]
        return None

    def _run(self, port: str) -> None:
        asyncio.set_event_loop(self.loop)

        async def main() -> None:
            self.server = ModbusSerialServer(self.device, port=port, baudrate=115200)
            await self.server.listen()
            self.ready.set()
            await self.server.serving

        try:
            self.loop.run_until_complete(main())
        except asyncio.CancelledError:
            pass

    def close(self) -> None:
        if self.server is not None:
            asyncio.run_coroutine_threadsafe(self.server.shutdown(), self.loop).result(5.0)
        self.th.join(5.0)


@pytest.fixture
def modbus(tmp_path):
    prof = tmp_path / "imu.toml"
    prof.write_text(PROFILE)
    cable = NullModem()
    server = Server(cable.b_name, _counts([0.01, -0.02, 0.003], [0.5, -0.25, -9.80665]))
    yield cable.a_name, str(prof), server
    server.close()
    cable.close()


def test_modbus_source_reads_a_pymodbus_server(modbus):
    port, prof, server = modbus
    src = modbus_source(port, prof, rate_hz=20.0)
    try:
        blocks = []
        t_end = time.monotonic() + 1.0
        while time.monotonic() < t_end:
            b = src.read(0.1)
            if b is not None:
                blocks.append(b)
        assert len(blocks) >= 10 and src.stats["read_errors"] == 0 and src.stats["frames"] == len(blocks)
        g = np.concatenate([b.gyro for b in blocks])
        a = np.concatenate([b.accel for b in blocks])
        np.testing.assert_allclose(g, np.tile([0.01, -0.02, 0.003], (len(g), 1)), atol=0.5 * GYRO_SCALE)
        np.testing.assert_allclose(a, np.tile([0.5, -0.25, -9.80665], (len(a), 1)), atol=0.5 * ACCEL_SCALE)
        t = np.concatenate([b.t for b in blocks])
        assert np.all(np.diff(t) > 0) and 0.03 < np.median(np.diff(t)) < 0.07  # polled at 20 Hz
        assert abs(t[-1] - time.time()) < 1.0  # UTC of the host (monotonic-based)
        # the server's registers change: the next polls follow (signs of int16 kept)
        server.set(_counts([-0.03, 0.0, 0.02], [-1.0, 2.0, -9.0]))
        time.sleep(0.1)
        got = None
        t_end = time.monotonic() + 1.0
        while time.monotonic() < t_end:
            b = src.read(0.1)
            if b is not None:
                got = b
        assert got is not None
        np.testing.assert_allclose(got.gyro[0], [-0.03, 0.0, 0.02], atol=0.5 * GYRO_SCALE)
        np.testing.assert_allclose(got.accel[0], [-1.0, 2.0, -9.0], atol=0.5 * ACCEL_SCALE)
    finally:
        src.close()


def test_live_runs_from_a_modbus_server_and_counts_its_silence(modbus):
    port, prof, server = modbus
    server.set(_counts([0.0, 0.0, 0.0], [0.5, -0.25, -9.80665]))  # at rest, tilted
    logs: list[str] = []
    hub = LiveHub()
    sub = hub.subscribe(10_000)
    stopped: list[float] = []

    def stop() -> str:  # the server goes away after 4 s of running: read errors, V, then the end
        if not stopped:
            stopped.append(time.monotonic())
        if time.monotonic() - stopped[0] > 4.0 and server.server is not None:
            server.close()
            server.server = None
            stopped.append(time.monotonic())
        return "test over" if len(stopped) > 1 and time.monotonic() - stopped[1] > 2.5 else ""

    res = run_live(port=port, modbus_profile=prof, rate_hz=20.0, motion="ship", settle_s=1.0, hub=hub, stop=stop,
                   log=logs.append, handle_signals=False)  # fmt: skip
    snaps = []
    while (s := sub.get(0)) is not None:
        snaps.append(s)
    summ = res.summary
    assert summ["source"].startswith("Modbus") and summ["samples"] >= 40
    assert summ["source_stats"]["read_errors"] > 0  # the server stopped answering
    # at rest, gravity along −z with 0.5 / −0.25 m/s² on x / y: roll = atan2(−a_y, −a_z) = 1.46° (+ starboard)
    good = [s for s in snaps if s.status == "A"]
    assert good, logs
    np.testing.assert_allclose(good[-1].roll_deg, np.degrees(np.arctan2(0.25, 9.80665)), atol=0.2)
    assert snaps[-1].status == "V" and "no samples" in snaps[-1].cause
