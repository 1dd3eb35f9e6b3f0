"""Sensor-to-segment alignment, joint orientation, boundary extraction and clinical angles.

Uses :mod:`models` for the quaternion conventions and the constraint file format.
"""
