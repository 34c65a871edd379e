"""Capture on deck: serial NMEA 0183, the imutool serial bridge protocol, Linux I2C sensors, Modbus RTU.

Outputs are imutool CSVs written incrementally (readable while the capture runs) plus, for NMEA, the raw
log of every line as received. See docs/capture.md and docs/bridge_protocol.md.
"""
