"""IMU wire formats: the Bosch BNO055 UART register protocol and the rig's stream protocol.

Modules
-------
bno055
    Register reads and writes over the BNO055 UART (datasheet section 4.7), register map subset,
    value codecs, streaming request/response decoders.
stream
    The rig's own COBS-framed, CRC-32-checked multi-IMU stream protocol; normative text in
    ``SPEC.md`` beside this file, reference C encoder in ``c/``.
cobs
    Consistent Overhead Byte Stuffing, canonical form.
"""

from firmware_protocol.imu import bno055, cobs, stream

__all__ = ["bno055", "cobs", "stream"]
