"""The simulated patient's limb (:class:`SimulatedLimb`): one or more joints moving inside a known
range of motion, carrying orientation sensors — ground truth plus a sensor error model. A limb
of one joint (by default a shoulder below the thorax) is a :class:`SimulatedJoint`; a whole arm
or leg (three joints) a :class:`SimulatedWholeLimb`.

Frames and quaternions (scalar-first, Hamilton, conventions of :mod:`models.quaternion`)
---------------------------------------------------------------------------------------
- **world** — the sensors' earth frame (BNO055 fusion output): Z up, heading from magnetic north.
- **thorax** — the parent segment. ``thorax(t)`` is the thorax relative to world: a fixed
  ``world_from_thorax`` (default: heading 35°, and a 90° pitch so that the limb axis +X hangs
  down at the identity joint orientation) times a slow postural sway of ±``sway_deg``.
- **limb** — the upper arm, long axis +X. ``joint(t)`` is the limb relative to the thorax: the
  ground truth that calibration must recover.
- **sensor i** — strapped on the thorax or the limb with a fixed mounting rotation ``mount``
  (sensor relative to segment).

Modules (each part a small object or pure functions; the limbs compose them)
----------------------------------------------------------------------------
:mod:`~rig.sim.limb.motion`
    How segments move: the root segment's :class:`~rig.sim.limb.motion.Posture`, a joint's
    free motion through its range and its stop at the limits
    (:class:`~rig.sim.limb.motion.JointMotion`: seeded sinusoids, radial stop, the exact
    oracle's projection), and the smoothing (:class:`~rig.sim.limb.motion.SmoothPath`).
:mod:`~rig.sim.limb.schedule`
    What the patient does when: the guided calibration protocol, the hand-over to free motion
    and the neutral checkpoints (:class:`~rig.sim.limb.schedule.Schedule`), and the neutral
    pose each checkpoint holds (:class:`~rig.sim.limb.schedule.NeutralPoses`).
:mod:`~rig.sim.limb.sensors`
    Where the sensors sit (:class:`SensorMount`,
    :class:`~rig.sim.limb.sensors.SensorPlacement`) and what they report
    (:class:`NoiseModel`, :class:`~rig.sim.limb.sensors.SensorErrors`: noise, drift, magnetic
    disturbances, calibration status, raw accelerometer and magnetometer).
:mod:`~rig.sim.limb.base`
    :class:`SimulatedLimb`, what every simulated limb shares: the seeded streams, the root's
    posture, the schedule's times and the sensors' readings (:class:`Measurement`).
:mod:`~rig.sim.limb.joint`
    :class:`SimulatedJoint`: one joint, its schedule and its sensors; its :class:`JointState`.
:mod:`~rig.sim.limb.whole`
    :class:`SimulatedWholeLimb`: a whole arm or leg (four segments, three joints, a sensor on
    each segment) moving inside a limb constraint (:class:`models.limb.Limb`) with the same
    parts; its :class:`WholeLimbState`.
"""

from rig.sim.limb.base import Measurement, SimulatedLimb
from rig.sim.limb.joint import DEFAULT_CONSTRAINT, JointState, SimulatedJoint
from rig.sim.limb.sensors import (
    GRAVITY,
    NoiseModel,
    SensorMount,
    default_mounts,
    misplaced_mounts,
)
from rig.sim.limb.whole import SimulatedWholeLimb, WholeLimbState, limb_mounts

__all__ = [
    "DEFAULT_CONSTRAINT",
    "GRAVITY",
    "JointState",
    "Measurement",
    "NoiseModel",
    "SensorMount",
    "SimulatedJoint",
    "SimulatedLimb",
    "SimulatedWholeLimb",
    "WholeLimbState",
    "default_mounts",
    "limb_mounts",
    "misplaced_mounts",
]
