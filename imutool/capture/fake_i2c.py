"""A fake SMBus implementing the MPU6050, HMC5883L and QMC5883L register maps (tests and demos, no hardware).

Devices hold 256 registers; writes are recorded; data registers are filled from a ``physics`` callback so a
test can set a known field/acceleration and check the driver's SI output. A missing device raises OSError
(errno 121, Remote I/O error), as the Linux i2c-dev driver does for an address nobody acknowledges.
"""

from __future__ import annotations

import errno
import struct


class FakeDevice:
    def __init__(self, regs: dict[int, int] | None = None):
        self.regs = bytearray(256)
        for k, v in (regs or {}).items():
            self.regs[k] = v
        self.writes: list[tuple[int, int]] = []

    def refresh(self) -> None:
        """Update data registers before a read (override)."""


class FakeMPU6050(FakeDevice):
    def __init__(self, accel_counts=(0, 0, 16384), gyro_counts=(0, 0, 0), temp_count=-5000, who_am_i=0x68):
        super().__init__({0x75: who_am_i, 0x6B: 0x40})
        self.accel_counts, self.gyro_counts, self.temp_count = accel_counts, gyro_counts, temp_count

    def refresh(self) -> None:
        self.regs[0x3B : 0x3B + 14] = struct.pack(">7h", *self.accel_counts, self.temp_count, *self.gyro_counts)


class FakeHMC5883L(FakeDevice):
    def __init__(self, counts_xyz=(0, 0, 0), ident=b"H43"):
        super().__init__({0x0A: ident[0], 0x0B: ident[1], 0x0C: ident[2]})
        self.counts_xyz = counts_xyz

    def refresh(self) -> None:
        x, y, z = self.counts_xyz
        self.regs[0x03:0x09] = struct.pack(">3h", x, z, y)  # the chip's X, Z, Y order


class FakeQMC5883L(FakeDevice):
    def __init__(self, counts_xyz=(0, 0, 0), chip_id=0xFF):
        super().__init__({0x0D: chip_id})
        self.counts_xyz = counts_xyz

    def refresh(self) -> None:
        self.regs[0x00:0x06] = struct.pack("<3h", *self.counts_xyz)
        self.regs[0x06] = 0x01


class FakeSMBus:
    """smbus2.SMBus look-alike: ``devices`` maps 7-bit address → FakeDevice.

    ``bypass_children`` are devices visible only after the MPU6050's INT_PIN_CFG bypass bit is set (as on a
    GY-86/GY-87 board where the magnetometer hangs off the MPU6050's auxiliary bus).
    """

    def __init__(self, devices: dict[int, FakeDevice], bypass_children: dict[int, FakeDevice] | None = None):
        self.devices = dict(devices)
        self.bypass_children = dict(bypass_children or {})

    def _dev(self, addr: int) -> FakeDevice:
        dev = self.devices.get(addr)
        if dev is None:
            for parent in self.devices.values():
                if isinstance(parent, FakeMPU6050) and parent.regs[0x37] & 0x02 and addr in self.bypass_children:
                    return self.bypass_children[addr]
            raise OSError(errno.EREMOTEIO, "Remote I/O error")
        return dev

    def read_byte_data(self, addr: int, reg: int) -> int:
        dev = self._dev(addr)
        dev.refresh()
        return dev.regs[reg]

    def write_byte_data(self, addr: int, reg: int, value: int) -> None:
        dev = self._dev(addr)
        dev.regs[reg] = value & 0xFF
        dev.writes.append((reg, value & 0xFF))

    def read_i2c_block_data(self, addr: int, reg: int, length: int) -> list[int]:
        dev = self._dev(addr)
        dev.refresh()
        return list(dev.regs[reg : reg + length])

    def close(self) -> None:
        pass
