"""Linux I2C sensor drivers (smbus2): MPU6050 (0x68/0x69), HMC5883L (0x1E), QMC5883L (0x0D).

Register maps and scale factors from the datasheets (MPU-6000/6050 Register Map rev 4.2; HMC5883L datasheet
rev E; QMC5883L datasheet v1.0). Each driver probes its ID register first and raises a clear error naming
the bus and address when the chip does not answer or answers with the wrong ID. Works with any object that
has smbus2's ``read_byte_data / write_byte_data / read_i2c_block_data`` (a fake bus in tests).
"""

from __future__ import annotations

import struct
import time as _time
from pathlib import Path

import numpy as np

from formats.errors import ImutoolError

from .bridge import HMC5883L_LSB_PER_GAUSS, QMC5883L_LSB_PER_GAUSS, Scales
from .runtime import CaptureStats, StatusLine, StopFlag, finish_poll_capture, iso_utc, poll
from .sink import CaptureCsv

# MPU6050 registers
MPU_SMPLRT_DIV, MPU_CONFIG, MPU_GYRO_CONFIG, MPU_ACCEL_CONFIG = 0x19, 0x1A, 0x1B, 0x1C
MPU_INT_PIN_CFG, MPU_ACCEL_XOUT_H, MPU_USER_CTRL, MPU_PWR_MGMT_1, MPU_WHO_AM_I = 0x37, 0x3B, 0x6A, 0x6B, 0x75
MPU_ACCEL_FS = {2: 0, 4: 1, 8: 2, 16: 3}
MPU_GYRO_FS = {250: 0, 500: 1, 1000: 2, 2000: 3}
# HMC5883L registers
HMC_ADDR, HMC_CRA, HMC_CRB, HMC_MODE, HMC_DATA, HMC_ID = 0x1E, 0x00, 0x01, 0x02, 0x03, 0x0A
HMC_ID_BYTES = b"H43"
# QMC5883L registers
QMC_ADDR, QMC_DATA, QMC_STATUS, QMC_CTRL1, QMC_SETRESET, QMC_CHIP_ID = 0x0D, 0x00, 0x06, 0x09, 0x0B, 0x0D


def open_bus(bus: int | str):
    """An smbus2.SMBus for /dev/i2c-<bus> (smbus2 is an optional extra: pip install imutool[i2c])."""
    try:
        from smbus2 import SMBus
    except ImportError:
        raise ImutoolError("I2C capture needs smbus2: pip install 'imutool[i2c]'") from None
    try:
        return SMBus(int(bus) if str(bus).isdigit() else bus)
    except (OSError, FileNotFoundError) as e:
        raise ImutoolError(f"cannot open I2C bus {bus}: {e}") from None


def _io(fn, what: str, bus_name: str, addr: int):
    try:
        return fn()
    except OSError as e:
        raise ImutoolError(
            f"I2C bus {bus_name}, address 0x{addr:02X} ({what}): no answer ({e.strerror or e})"
        ) from None


class MPU6050:
    """MPU6050 6-axis IMU: accel (m/s²), gyro (rad/s), temperature (°C)."""

    def __init__(
        self,
        bus,
        address: int = 0x68,
        accel_fs_g: int = 2,
        gyro_fs_dps: int = 250,
        dlpf: int = 3,
        sample_div: int = 4,
        bus_name: str = "?",
        bypass: bool = False,
    ):
        if address not in (0x68, 0x69):
            raise ImutoolError(f"MPU6050 address 0x{address:02X}: must be 0x68 (AD0 low) or 0x69 (AD0 high)")
        self.bus, self.addr, self.bus_name = bus, address, bus_name
        self.scales = Scales(accel_fs_g=accel_fs_g, gyro_fs_dps=gyro_fs_dps)
        who = _io(lambda: bus.read_byte_data(address, MPU_WHO_AM_I), "WHO_AM_I", bus_name, address)
        if (who & 0x7E) != 0x68:  # WHO_AM_I holds bits 6:1 of the address: 0x68 regardless of AD0
            raise ImutoolError(
                f"I2C bus {bus_name}, address 0x{address:02X}: WHO_AM_I = 0x{who:02X}, expected 0x68 "
                "(not an MPU6050; an MPU6500/9250 answers 0x70/0x71)"
            )
        w = lambda reg, val: _io(  # noqa: E731
            lambda: bus.write_byte_data(address, reg, val),
            f"write 0x{reg:02X}",
            bus_name,
            address,
        )
        w(MPU_PWR_MGMT_1, 0x01)  # wake, clock from the X gyro PLL
        w(MPU_SMPLRT_DIV, sample_div)  # sample rate = 1 kHz / (1 + div) with the DLPF on
        w(MPU_CONFIG, dlpf & 0x07)
        w(MPU_GYRO_CONFIG, MPU_GYRO_FS[gyro_fs_dps] << 3)
        w(MPU_ACCEL_CONFIG, MPU_ACCEL_FS[accel_fs_g] << 3)
        if bypass:  # expose the auxiliary I2C bus (GY-86/GY-87: magnetometer behind the MPU6050)
            w(MPU_USER_CTRL, 0x00)
            w(MPU_INT_PIN_CFG, 0x02)

    def read(self) -> tuple[np.ndarray, np.ndarray, float]:
        raw = _io(
            lambda: self.bus.read_i2c_block_data(self.addr, MPU_ACCEL_XOUT_H, 14), "read data", self.bus_name, self.addr
        )
        v = struct.unpack(">7h", bytes(raw))
        acc = np.array(v[0:3], dtype=float) * self.scales.accel
        gyr = np.array(v[4:7], dtype=float) * self.scales.gyro
        temp = v[3] / 340.0 + 36.53
        return acc, gyr, temp


class HMC5883L:
    """HMC5883L 3-axis magnetometer, µT. Data registers are ordered X, Z, Y (big-endian)."""

    def __init__(self, bus, gain: int = 1, rate_code: int = 6, bus_name: str = "?"):
        self.bus, self.addr, self.bus_name = bus, HMC_ADDR, bus_name
        self.lsb_per_gauss = HMC5883L_LSB_PER_GAUSS[gain]
        ident = bytes(_io(lambda: bus.read_i2c_block_data(HMC_ADDR, HMC_ID, 3), "ID registers", bus_name, HMC_ADDR))
        if ident != HMC_ID_BYTES:
            raise ImutoolError(
                f"I2C bus {bus_name}, address 0x1E: ID = {ident!r}, expected b'H43' (not an HMC5883L;"
                " a QMC5883L sits at 0x0D)"
            )
        w = lambda reg, val: _io(  # noqa: E731
            lambda: bus.write_byte_data(HMC_ADDR, reg, val),
            f"write 0x{reg:02X}",
            bus_name,
            HMC_ADDR,
        )
        w(HMC_CRA, (0b11 << 5) | (rate_code << 2))  # 8-sample average, output rate code (6 = 75 Hz)
        w(HMC_CRB, gain << 5)
        w(HMC_MODE, 0x00)  # continuous measurement

    def read(self) -> np.ndarray:
        raw = _io(lambda: self.bus.read_i2c_block_data(HMC_ADDR, HMC_DATA, 6), "read data", self.bus_name, HMC_ADDR)
        x, z, y = struct.unpack(">3h", bytes(raw))
        v = np.array([x, y, z], dtype=float)
        v[v == -4096] = np.nan  # the chip's overflow code
        return v * 100.0 / self.lsb_per_gauss


class QMC5883L:
    """QMC5883L 3-axis magnetometer, µT. Data registers X, Y, Z little-endian; range ±2 or ±8 gauss."""

    def __init__(self, bus, range_gauss: int = 8, bus_name: str = "?"):
        self.bus, self.addr, self.bus_name = bus, QMC_ADDR, bus_name
        self.lsb_per_gauss = QMC5883L_LSB_PER_GAUSS[range_gauss]
        chip = _io(lambda: bus.read_byte_data(QMC_ADDR, QMC_CHIP_ID), "chip ID", bus_name, QMC_ADDR)
        if chip != 0xFF:
            raise ImutoolError(
                f"I2C bus {bus_name}, address 0x0D: chip ID = 0x{chip:02X}, expected 0xFF (not a QMC5883L)"
            )
        w = lambda reg, val: _io(  # noqa: E731
            lambda: bus.write_byte_data(QMC_ADDR, reg, val),
            f"write 0x{reg:02X}",
            bus_name,
            QMC_ADDR,
        )
        w(QMC_SETRESET, 0x01)
        rng = 0x10 if range_gauss == 8 else 0x00
        w(QMC_CTRL1, 0x01 | 0x0C | rng)  # continuous, 200 Hz, range, OSR 512

    def read(self) -> np.ndarray:
        raw = _io(lambda: self.bus.read_i2c_block_data(QMC_ADDR, QMC_DATA, 6), "read data", self.bus_name, QMC_ADDR)
        v = np.array(struct.unpack("<3h", bytes(raw)), dtype=float)
        return v * 100.0 / self.lsb_per_gauss


def capture_i2c(
    bus_id: str,
    out: str,
    imu: str | None = "mpu6050",
    mag: str | None = "hmc5883l",
    rate_hz: float = 200.0,
    imu_address: int = 0x68,
    accel_fs_g: int = 2,
    gyro_fs_dps: int = 250,
    mag_gain: int | None = None,
    bypass: bool = False,
    duration: float | None = None,
    rotate_s: float | None = None,
    status_s: float | None = 10.0,
    quiet: bool = False,
    append: bool = False,
    force: bool = False,
    bus=None,
    stop: StopFlag | None = None,
) -> dict:
    """Read an MPU6050 and/or a magnetometer on a Linux I2C bus at a steady rate into an imutool CSV (SI)."""
    from .serial_capture import utc_name

    if bus is None:
        bus = open_bus(bus_id)
    name = f"/dev/i2c-{bus_id}" if str(bus_id).isdigit() else str(bus_id)
    dev_imu = None
    if imu:
        if imu != "mpu6050":
            raise ImutoolError(f"IMU {imu!r} not supported (mpu6050)")
        dev_imu = MPU6050(bus, imu_address, accel_fs_g, gyro_fs_dps, bus_name=name, bypass=bypass)
    dev_mag = None
    if mag == "hmc5883l":
        dev_mag = HMC5883L(bus, 1 if mag_gain is None else mag_gain, bus_name=name)
    elif mag == "qmc5883l":
        dev_mag = QMC5883L(bus, 8 if mag_gain is None else mag_gain, bus_name=name)
    elif mag:
        raise ImutoolError(f"magnetometer {mag!r} not supported (hmc5883l, qmc5883l)")
    if dev_imu is None and dev_mag is None:
        raise ImutoolError("nothing to read: give --imu and/or --mag")
    cols = ["time", "time_mono"]
    if dev_imu:
        cols += ["accel_x", "accel_y", "accel_z", "gyro_x", "gyro_y", "gyro_z", "temp"]
    if dev_mag:
        cols += ["mag_x", "mag_y", "mag_z"]
    base = Path(out)
    if base.suffix.lower() != ".csv":
        base = base / f"i2c_{utc_name()}.csv"
    meta = {
        "source": f"I2C {name}: {imu or '-'} @0x{imu_address:02X}, {mag or '-'}",
        "rate_hz": rate_hz,
        "time": "UTC epoch seconds",
        "units": "time_mono=s",
        "captured_by": "imutool capture i2c",
    }
    if dev_imu:
        meta["scales"] = dev_imu.scales.as_meta()
    csv = CaptureCsv(base, cols, meta, rotate_s=rotate_s, append=append, overwrite=force)
    stats = CaptureStats(started_utc=iso_utc(_time.time()))
    status = StatusLine(status_s, quiet)
    stop = stop or StopFlag()
    stop.install()
    pending: list[list[float]] = []

    def read_all():
        row = []
        if dev_imu:
            a, g, t = dev_imu.read()
            row += [*a, *g, t]
        if dev_mag:
            row += list(dev_mag.read())
        return row

    def on_sample(t_mono: float, row: list[float]) -> None:
        pending.append([_time.time(), t_mono, *row])
        stats.frames += 1
        if len(pending) >= max(1, int(rate_hz / 10)):
            csv.write_rows(np.array(pending))
            pending.clear()
            status.update(stats, csv.file.bytes_written)

    try:
        ps = poll(read_all, rate_hz, on_sample, duration, stop_check=lambda: stop.stop)
    finally:
        stop.restore()
        if pending:
            csv.write_rows(np.array(pending))
        status.finish()
    return finish_poll_capture(csv, stats, stop, ps, rate_hz)
