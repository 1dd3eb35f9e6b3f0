"""A limb moved (or read) by servos: a servo bus with the limb's kinematics above it.

:class:`ServoLimb` composes a :class:`~rig.devices.bus.ServoBus` (ticks, torque, alerts,
watchdog; no kinematics) and a :class:`~rig.devices.kinematics.LimbKinematics` (the bus's tick
vector ↔ ``(J, 4)`` joint orientations). The bus's servo order must be the kinematics' (joint 1's
servos first, each joint parent → child). A one-joint rig is a limb of one joint; a servo arm is
one bus and the kinematics of its joints; a leader arm is the same thing read instead of
written.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rig.devices.bus import ServoBus
from rig.devices.kinematics import JointKinematics, LimbKinematics
from rig.errors import RigConfigError

__all__ = ["ServoLimb"]


class ServoLimb:
    """A servo bus and the kinematics of the limb its servos move.

    Parameters
    ----------
    bus : ServoBus
        Opened; closed with the limb.
    kinematics : LimbKinematics or JointKinematics
        A joint's kinematics is taken as a limb of that one joint.

    Attributes
    ----------
    bus : ServoBus
    kinematics : LimbKinematics
    backstop : tuple of two (n,) int64 arrays, or None
        The position limits written to the servos from a boundary
        (:func:`rig.loop.runner.prepare_servos`), None when none was.

    Raises
    ------
    RigConfigError
        The kinematics' servos are not the bus's, in the bus's order.
    """

    def __init__(self, bus: ServoBus, kinematics: LimbKinematics | JointKinematics) -> None:
        if isinstance(kinematics, JointKinematics):
            kinematics = LimbKinematics([kinematics])
        if tuple(kinematics.ids) != tuple(bus.ids):
            raise RigConfigError("the limb's kinematics and its bus name different servos",
                                 actual=list(bus.ids), expected=list(kinematics.ids))
        self.bus = bus
        self.kinematics = kinematics
        self.backstop: tuple[np.ndarray, np.ndarray] | None = None

    # -- life cycle -----------------------------------------------------------------------
    def close(self) -> None:
        """Close the bus; idempotent."""
        self.bus.close()

    def __enter__(self) -> ServoLimb:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- orientations ---------------------------------------------------------------------
    def read_ticks(self) -> np.ndarray:
        """:meth:`ServoBus.read_ticks`: (n,) int64."""
        return self.bus.read_ticks()

    def read_orientations(self) -> np.ndarray:
        """Forward kinematics of one read: (J, 4), each joint's child relative to its parent."""
        return self.kinematics.forward(self.bus.read_ticks())

    def write_orientations(self, q: np.ndarray, near_ticks: Sequence[int]) -> np.ndarray:
        """Inverse kinematics of ``q`` (J, 4) nearest ``near_ticks`` (n,), then one goal write;
        returns the goal ticks (n,).

        Raises
        ------
        UnreachableError
            Nothing sent.
        """
        goal = self.kinematics.inverse(q, near_ticks)
        self.bus.write_goal_ticks(goal)
        return goal

    def set_position_limits(self, min_ticks: Sequence[int], max_ticks: Sequence[int]) -> None:
        """Replace every servo's tick limits, in the kinematics (IK) and on the bus (the goal
        check, the next :meth:`ServoBus.configure`); no bus traffic.

        Raises
        ------
        ValueError
            Not one min and one max per servo.
        RigConfigError
            A servo's zero outside its new limits (nothing changed).
        """
        kinematics = self.kinematics.with_limits(min_ticks, max_ticks)  # validates
        self.bus.set_position_limits(min_ticks, max_ticks)
        self.kinematics = kinematics
