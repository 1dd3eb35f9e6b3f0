"""Pure wire formats: bytes in, bytes out, no I/O.

Sub-packages
------------
dynamixel
    ROBOTIS Dynamixel Protocol 2.0: framing, byte stuffing, CRC-16, instructions, control tables.
imu
    Bosch BNO055 UART register protocol and the rig's own multi-IMU stream protocol (SPEC.md).

Nothing here opens a port; the simulators that *serve* these protocols are backends in ``rig``.
"""
