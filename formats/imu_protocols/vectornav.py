"""VectorNav ASCII asynchronous output (VN-100/VN-200/VN-300): ``$VNYMR`` and ``$VNIMU`` sentences.

Source: VectorNav *VN-100 User Manual* (UM001, firmware v2.1.0.0, rev 2.22), §3.8 "Checksum / CRC" and the
output registers "Yaw, Pitch, Roll, Magnetic, Acceleration and Angular Rates" (register 27, async header
``VNYMR``) and "IMU Measurements" (register 54, header ``VNIMU``); the same tables are in the VN-200/VN-300
manuals. Written from those documents; no vendor code.

Frames (ASCII, one per line, ``\\r\\n`` ended; numbers with sign and fixed decimals)::

    $VNYMR,yaw,pitch,roll,magX,magY,magZ,accelX,accelY,accelZ,gyroX,gyroY,gyroZ*XX
    $VNIMU,magX,magY,magZ,accelX,accelY,accelZ,gyroX,gyroY,gyroZ,temp,pressure*XX

Units: yaw/pitch/roll deg; mag gauss; accel m/s²; gyro rad/s; temp °C; pressure kPa. VNIMU's values are the
*uncompensated* (factory calibrated, not bias/alignment compensated) IMU readings; VNYMR's are compensated.
Check: ``*`` then 2 hex digits = 8-bit XOR of every byte between ``$`` and ``*``; or 4 hex digits = 16-bit CRC
(CRC-16-CCITT, polynomial 0x1021, initial value 0, over the same bytes); ``*XX`` / ``*XXXX`` = check bypassed
(accepted, counted as ``unchecked``).

Signs and axes: VectorNav's body frame is x forward, y right, z down — imutool's FRD already. Its
accelerometer output is the specific force (it reads about (0, 0, −9.8) m/s² at rest level: gravity along +z
appears as −9.8), which is imutool's convention (+g upward at rest), so accel, gyro and mag pass unchanged
(mag × 100: gauss → µT). Yaw, pitch, roll are the 3-2-1 Euler angles of the body in local NED: roll + right
wing (starboard) down, pitch + nose up, yaw clockwise from north — imutool's signs. Check against the manual's
own example of register 27 (roll −1.953°, accel (+0.005, +0.344, −9.758)): imutool's tilt from that accel is
roll −2.02°, pitch −0.03° — the same signs with no conversion (tested).

No device clock is in these sentences: samples are timed by their arrival at the host.
"""

from __future__ import annotations

from collections.abc import Sequence

from .base import DecoderStats, ImuSamples, SampleRows

NAME = "vectornav"
CONVENTIONS = (
    "VectorNav ASCII $VNYMR/$VNIMU (VN-100 User Manual UM001 §3.8, registers 27 and 54): body x forward, "
    "y right, z down = imutool FRD; accel is specific force (reads (0,0,-9.8) m/s^2 at rest level) = imutool's "
    "sign, passed unchanged; gyro rad/s unchanged; mag gauss x100 -> uT; yaw/pitch/roll deg 3-2-1 in NED "
    "(roll + starboard down, pitch + bow up) = imutool's signs; times: host arrival"
)
GAUSS_TO_UT = 100.0
MAX_LINE = 512  # longer without an end: not a VectorNav sentence
_SPACE = frozenset(b" \t\r\n")


def xor_checksum(body: bytes) -> int:
    """The 8-bit checksum: XOR of the bytes between ``$`` and ``*``."""
    c = 0
    for b in body:
        c ^= b
    return c


def crc16(body: bytes) -> int:
    """The 16-bit CRC: CRC-16-CCITT (poly 0x1021, init 0, no reflection) of the bytes between ``$`` and ``*``."""
    crc = 0
    for b in body:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


class VectorNavDecoder:
    """Incremental decoder of ``$VNYMR`` / ``$VNIMU`` lines; other ``$VN…`` sentences are counted (``other``)."""

    name = NAME
    conventions = CONVENTIONS

    def __init__(self) -> None:
        self._buf = bytearray()
        self.stats = DecoderStats(extra={"unchecked": 0})

    def feed(self, data: bytes) -> ImuSamples:
        """Decode what ``data`` completes; keep a partial line for the next call."""
        base = len(self._buf)
        buf = self._buf
        buf += data
        rows = SampleRows()
        st = self.stats
        i, n = 0, len(buf)
        keep = n
        while i < n:
            j = buf.find(b"$", i)
            stop = n if j < 0 else j
            junk = sum(1 for b in buf[i:stop] if b not in _SPACE)
            if junk:
                st.garbage_bytes += junk
                st.resyncs += 1
            if j < 0:
                keep = n
                break
            k = _line_end(buf, j + 1)
            if k < 0:
                if n - j > MAX_LINE:  # a '$' that starts nothing: skip it and search again
                    st.garbage_bytes += 1
                    st.resyncs += 1
                    i = j + 1
                    continue
                keep = j
                break
            last = buf.rfind(b"$", j + 1, k)
            if last >= 0:  # a sentence cut short by another's start: the cut part is garbage
                st.garbage_bytes += last - j
                st.resyncs += 1
                j = last
            self._line(bytes(buf[j + 1 : k]), k + 1 - base, rows)
            i = k + 1
            keep = n
        del buf[:keep]
        out = rows.samples()
        st.samples += len(out)
        return out

    def _line(self, text: bytes, end: int, rows: SampleRows) -> None:
        st = self.stats
        star = text.rfind(b"*")
        if star < 0:
            st.malformed += 1
            return
        body, ck = text[:star], text[star + 1 :].strip()
        try:
            if ck in (b"XX", b"XXXX"):
                st.extra["unchecked"] += 1
                good = True
            elif len(ck) == 2:
                good = int(ck, 16) == xor_checksum(body)
            elif len(ck) == 4:
                good = int(ck, 16) == crc16(body)
            else:
                st.malformed += 1
                return
        except ValueError:
            st.bad_checksum += 1
            return
        if not good:
            st.bad_checksum += 1
            return
        fields = body.split(b",")
        head = fields[0]
        try:
            vals = [float(f) for f in fields[1:]]
        except ValueError:
            st.malformed += 1
            return
        if head == b"VNYMR" and len(vals) == 12:
            yaw, pitch, roll = vals[0:3]
            mag = [v * GAUSS_TO_UT for v in vals[3:6]]
            rows.add(end, vals[9:12], vals[6:9], mag, (roll, pitch, yaw))
        elif head == b"VNIMU" and len(vals) == 11:
            mag = [v * GAUSS_TO_UT for v in vals[0:3]]
            rows.add(end, vals[6:9], vals[3:6], mag, None, vals[9])
        elif head in (b"VNYMR", b"VNIMU"):
            st.malformed += 1
            return
        else:
            st.other += 1
        st.frames += 1


def _line_end(buf: bytearray, start: int) -> int:
    """Index of the first CR or LF at or after ``start``; −1 if none."""
    a = buf.find(b"\r", start)
    b = buf.find(b"\n", start)
    if a < 0:
        return b
    return a if b < 0 else min(a, b)


def _frame(body: str, crc: bool) -> bytes:
    raw = body.encode("ascii")
    ck = f"{crc16(raw):04X}" if crc else f"{xor_checksum(raw):02X}"
    return b"$" + raw + b"*" + ck.encode("ascii") + b"\r\n"


def encode_vnymr(
    roll_pitch_yaw_deg: Sequence[float],
    mag_ut: Sequence[float],
    accel: Sequence[float],
    gyro: Sequence[float],
    crc: bool = False,
) -> bytes:
    """A ``$VNYMR`` sentence from imutool-convention values (deg, µT, m/s² specific force FRD, rad/s FRD), with
    VectorNav's field widths (yaw/pitch/roll 3 decimals, mag 4, accel 3, gyro 6); ``crc``: the 16-bit CRC."""
    r, p, y = roll_pitch_yaw_deg
    m = [v / GAUSS_TO_UT for v in mag_ut]
    body = (
        f"VNYMR,{y:+08.3f},{p:+08.3f},{r:+08.3f},{m[0]:+08.4f},{m[1]:+08.4f},{m[2]:+08.4f},"
        f"{accel[0]:+07.3f},{accel[1]:+07.3f},{accel[2]:+07.3f},{gyro[0]:+010.6f},{gyro[1]:+010.6f},{gyro[2]:+010.6f}"
    )
    return _frame(body, crc)


def encode_vnimu(
    mag_ut: Sequence[float],
    accel: Sequence[float],
    gyro: Sequence[float],
    temp_c: float = 25.0,
    pressure_kpa: float = 101.325,
    crc: bool = False,
) -> bytes:
    """A ``$VNIMU`` sentence from imutool-convention values (µT, m/s², rad/s, °C, kPa)."""
    m = [v / GAUSS_TO_UT for v in mag_ut]
    body = (
        f"VNIMU,{m[0]:+08.4f},{m[1]:+08.4f},{m[2]:+08.4f},{accel[0]:+07.3f},{accel[1]:+07.3f},{accel[2]:+07.3f},"
        f"{gyro[0]:+010.6f},{gyro[1]:+010.6f},{gyro[2]:+010.6f},{temp_c:+06.1f},{pressure_kpa:+08.3f}"
    )
    return _frame(body, crc)
