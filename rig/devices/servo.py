"""A servo as a bus knows it: ID, name, goal range — nothing about what it moves.

A leaf module (no imports from the rest of :mod:`rig`), so that rig configurations and the servo
bus (:mod:`rig.devices.bus`) can both name servos without importing each other.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Servo"]


@dataclass(frozen=True)
class Servo:
    """One servo on a bus.

    Attributes
    ----------
    id : int
        Bus ID (Dynamixel: 0..252).
    name : str or None
        Optional label (e.g. ``"elevation"``); :attr:`rig.devices.bus.ServoBus.names`
        falls back to the ID.
    min_ticks, max_ticks : int
        Allowed goal range, ticks (written to the servo's position-limit registers where it
        has them).
    """

    id: int
    name: str | None = None
    min_ticks: int = 0
    max_ticks: int = 4095
