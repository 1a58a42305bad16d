"""The sensor board's wire protocol: frames on the serial line (DESIGN.md section 3).

:mod:`~bendsense.wire.framing` cuts the byte stream into frames (COBS, CRC-16);
:mod:`~bendsense.wire.frames` decodes their payloads (HELLO, SAMPLE, TEXT, SETPOINT).
"""
