"""The simulated patient: a shoulder moving inside a known range of motion, carrying orientation
sensors — ground truth plus a sensor error model.

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

Modules (each part a small object or pure functions; :class:`SimulatedLimb` composes them)
------------------------------------------------------------------------------------------
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
:mod:`~rig.sim.limb.simulated`
    :class:`SimulatedLimb`, the facade: one joint, its schedule and its sensors; the
    :class:`LimbState` / :class:`Measurement` it returns.
:mod:`~rig.sim.limb.chain`
    :class:`SimulatedChain`: a whole arm or leg (four segments, three joints, a sensor on each
    segment) moving inside a limb constraint (:class:`models.limb.Limb`) with the same parts;
    its :class:`ChainState`.
"""

from rig.sim.limb.chain import ChainState, SimulatedChain, chain_mounts
from rig.sim.limb.sensors import GRAVITY, NoiseModel, SensorMount, default_mounts
from rig.sim.limb.simulated import DEFAULT_CONSTRAINT, LimbState, Measurement, SimulatedLimb

__all__ = [
    "DEFAULT_CONSTRAINT",
    "GRAVITY",
    "ChainState",
    "LimbState",
    "Measurement",
    "NoiseModel",
    "SensorMount",
    "SimulatedChain",
    "SimulatedLimb",
    "chain_mounts",
    "default_mounts",
]
