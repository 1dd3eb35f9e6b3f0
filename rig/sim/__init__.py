"""Simulated devices that speak the real wire protocols on pseudo-terminals.

Each simulator is a backend, not a test double: the official client libraries (``dynamixel_sdk``,
``pyserial``) open its ``port`` exactly as they open a USB adapter.

Modules
-------
dynamixel
    A chain of Dynamixel X-series servos (Protocol 2.0) behind a simulated U2D2.
imu
    Simulated IMUs (BNO055 UART and the rig stream protocol).
"""
