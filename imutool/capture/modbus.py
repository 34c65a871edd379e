"""Modbus RTU polling (pymodbus, optional extra): an inclinometer or compass described by a TOML profile.

Profile::

    [device]
    name = "Example inclinometer"
    unit = 1                  # Modbus device (slave) id; the CLI's --unit overrides it
    baud = 9600
    parity = "N"              # N, E or O
    rate_hz = 10

    [[register]]
    name = "roll"             # imutool channel name
    address = 0               # zero-based register address
    table = "input"           # input (function 04) or holding (function 03)
    type = "int16"            # int16, uint16, int32, uint32, float32
    scale = 0.01              # value = raw × scale + offset
    offset = 0.0
    unit = "deg"
    word_order = "big"        # for 32-bit types: which register holds the high word

Consecutive registers of the same table are read in one request.
"""

from __future__ import annotations

import math
import struct
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from formats.columns import load_profile
from formats.errors import ImutoolError
from formats.units import is_known

_TYPES = {"int16": (1, ">h"), "uint16": (1, ">H"), "int32": (2, ">i"), "uint32": (2, ">I"), "float32": (2, ">f")}


@dataclass
class Register:
    name: str
    address: int
    table: str = "input"
    type: str = "int16"
    scale: float = 1.0
    offset: float = 0.0
    unit: str | None = None
    word_order: str = "big"

    @property
    def words(self) -> int:
        return _TYPES[self.type][0]

    def decode(self, words: list[int]) -> float:
        w = list(words)
        if self.word_order == "little":
            w.reverse()
        raw = struct.unpack(_TYPES[self.type][1], b"".join(struct.pack(">H", x & 0xFFFF) for x in w))[0]
        return raw * self.scale + self.offset


@dataclass
class Profile:
    name: str
    unit: int
    baud: int
    parity: str
    rate_hz: float
    registers: list[Register]


def _typed(table: dict, key: str, default: object, kind: str, where: str, path: str) -> object:
    """``table[key]`` (or ``default``) of the TOML type ``kind``: 'str', 'int' or 'number' (finite); a wrong
    type is one line naming the key."""
    v = table.get(key, default)
    if kind == "str":
        ok = isinstance(v, str)
    elif kind == "int":
        ok = isinstance(v, int) and not isinstance(v, bool)
    else:
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    if not ok:
        want = {"str": "a string", "int": "a whole number", "number": "a finite number"}[kind]
        raise ImutoolError(f"{where}: {key} = {v!r} must be {want}", path=path)
    return v


def read_profile(path: str) -> Profile:
    """Parse and check a Modbus register profile (clear errors naming the register and the key)."""
    doc = load_profile(path)
    dev = doc.get("device", {})
    if not isinstance(dev, dict):
        raise ImutoolError("[device] must be a table", path=path)
    items = doc.get("register", [])
    if not isinstance(items, list) or not all(isinstance(r, dict) for r in items):
        raise ImutoolError("register entries must be [[register]] tables", path=path)
    regs = []
    for i, r in enumerate(items):
        where = f"register {i + 1} ({r.get('name', '?')})"
        for key in ("name", "address"):
            if key not in r:
                raise ImutoolError(f"{where}: missing '{key}'", path=path)
        unit = r.get("unit")
        if unit is not None and not isinstance(unit, str):
            raise ImutoolError(f"{where}: unit = {unit!r} must be a string", path=path)
        reg = Register(
            str(_typed(r, "name", None, "str", where, path)),
            int(_typed(r, "address", None, "int", where, path)),  # type: ignore[arg-type]
            str(_typed(r, "table", "input", "str", where, path)),
            str(_typed(r, "type", "int16", "str", where, path)),
            float(_typed(r, "scale", 1.0, "number", where, path)),  # type: ignore[arg-type]
            float(_typed(r, "offset", 0.0, "number", where, path)),  # type: ignore[arg-type]
            unit,
            str(_typed(r, "word_order", "big", "str", where, path)),
        )
        if reg.table not in ("input", "holding"):
            raise ImutoolError(f"{where}: table must be 'input' or 'holding'", path=path)
        if reg.type not in _TYPES:
            raise ImutoolError(f"{where}: type must be one of {', '.join(_TYPES)}", path=path)
        if reg.word_order not in ("big", "little"):
            raise ImutoolError(f"{where}: word_order must be 'big' or 'little'", path=path)
        if reg.unit and not is_known(reg.unit):
            raise ImutoolError(f"{where}: unknown unit {reg.unit!r}", path=path)
        if not 0 <= reg.address <= 65535:
            raise ImutoolError(f"{where}: address out of range 0..65535", path=path)
        regs.append(reg)
    if not regs:
        raise ImutoolError("no [[register]] entries", path=path)
    rate = float(_typed(dev, "rate_hz", 10.0, "number", "[device]", path))  # type: ignore[arg-type]
    if not 0 < rate <= 100_000:
        raise ImutoolError(f"[device]: rate_hz = {rate!r} must be > 0 and at most 100 000 Hz", path=path)
    return Profile(
        str(_typed(dev, "name", "modbus device", "str", "[device]", path)),
        int(_typed(dev, "unit", 1, "int", "[device]", path)),  # type: ignore[arg-type]
        int(_typed(dev, "baud", 9600, "int", "[device]", path)),  # type: ignore[arg-type]
        str(_typed(dev, "parity", "N", "str", "[device]", path)),
        rate,
        regs,
    )


def request_blocks(regs: list[Register]) -> list[tuple[str, int, int]]:
    """(table, start address, count) requests covering all registers, merging contiguous runs (≤ 125 words)."""
    blocks: list[tuple[str, int, int]] = []
    for table in ("input", "holding"):
        spans = sorted((r.address, r.address + r.words) for r in regs if r.table == table)
        for a, b in spans:
            if blocks and blocks[-1][0] == table and a <= blocks[-1][1] + blocks[-1][2] and b - blocks[-1][1] <= 125:
                t, s, n = blocks[-1]
                blocks[-1] = (t, s, max(n, b - s))
            else:
                blocks.append((table, a, b - a))
    return blocks


class ModbusPoller:
    """Reads all profile registers from one device with pymodbus's RTU client."""

    def __init__(
        self, port: str, profile: Profile, unit: int | None = None, baud: int | None = None, timeout: float = 0.5
    ):
        try:
            from pymodbus.client import ModbusSerialClient
        except ImportError:
            raise ImutoolError("Modbus capture needs pymodbus: pip install 'imutool[modbus]'") from None
        self.profile = profile
        self.unit = profile.unit if unit is None else unit
        self.port = port
        self.client = ModbusSerialClient(
            port, baudrate=baud or profile.baud, parity=profile.parity, timeout=timeout, retries=1
        )
        if not self.client.connect():
            raise ImutoolError("cannot open the Modbus serial port", path=port)
        self.blocks = request_blocks(profile.registers)

    def read(self) -> dict[str, float]:
        """One poll: name → scaled value. Raises ImutoolError on no answer or an exception response."""
        words: dict[tuple[str, int], int] = {}
        for table, start, count in self.blocks:
            fn = self.client.read_input_registers if table == "input" else self.client.read_holding_registers
            try:
                rr = fn(start, count=count, device_id=self.unit)
            except Exception as e:  # pymodbus raises ModbusException / ConnectionException
                raise ImutoolError(
                    f"Modbus unit {self.unit}: no answer reading {table} {start}+{count}: {e}", path=self.port
                ) from None
            if rr.isError():
                raise ImutoolError(
                    f"Modbus unit {self.unit}: exception response {rr} for {table} {start}+{count}", path=self.port
                )
            for i, w in enumerate(rr.registers):
                words[(table, start + i)] = w
        return {
            r.name: r.decode([words[(r.table, r.address + k)] for k in range(r.words)]) for r in self.profile.registers
        }

    def close(self) -> None:
        self.client.close()


def capture_modbus(
    port: str,
    profile_path: str,
    out: str,
    unit: int | None = None,
    baud: int | None = None,
    rate_hz: float | None = None,
    duration: float | None = None,
    rotate_s: float | None = None,
    status_s: float | None = 10.0,
    quiet: bool = False,
    append: bool = False,
    force: bool = False,
    stop=None,
) -> dict:
    """Poll a Modbus RTU device at a steady rate into an imutool CSV (values scaled per the profile)."""
    from .runtime import CaptureStats, StatusLine, StopFlag, finish_poll_capture, iso_utc, poll
    from .serial_capture import utc_name
    from .sink import CaptureCsv

    prof = read_profile(profile_path)
    rate = rate_hz or prof.rate_hz
    poller = ModbusPoller(port, prof, unit, baud)
    cols = ["time", "time_mono"] + [r.name for r in prof.registers]
    base = Path(out)
    if base.suffix.lower() != ".csv":
        base = base / f"modbus_{utc_name()}.csv"
    units = ", ".join(f"{r.name}={r.unit}" for r in prof.registers if r.unit)
    meta = {
        "source": f"Modbus RTU {port} unit {poller.unit}: {prof.name}",
        "profile": profile_path,
        "rate_hz": rate,
        "time": "UTC epoch seconds",
        "units": units + (", " if units else "") + "time_mono=s",
        "captured_by": "imutool capture modbus",
    }
    csv = CaptureCsv(base, cols, meta, rotate_s=rotate_s, append=append, overwrite=force)
    stats = CaptureStats(started_utc=iso_utc(time.time()))
    status = StatusLine(status_s, quiet)
    stop = stop or StopFlag()
    stop.install()

    def on_sample(t_mono: float, values: dict) -> None:
        csv.write_rows(np.array([[time.time(), t_mono] + [values[r.name] for r in prof.registers]]))
        stats.frames += 1
        status.update(stats, csv.file.bytes_written)

    try:
        ps = poll(poller.read, rate, on_sample, duration, stop_check=lambda: stop.stop)
    finally:
        stop.restore()
        poller.close()
        status.finish()
    return finish_poll_capture(csv, stats, stop, ps, rate)
