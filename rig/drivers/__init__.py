"""Host-side device drivers. They open a port (hardware or a simulator's pty) with pyserial or
dynamixel_sdk and use :mod:`firmware_protocol` for the bytes."""
