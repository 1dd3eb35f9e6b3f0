"""Sensor-to-segment alignment, joint orientation, boundary extraction and clinical angles.

Pure computation on orientation arrays (no device I/O); uses :mod:`models` for the quaternion
conventions (scalar-first ``w, x, y, z``, Hamilton, limb long axis +X) and the constraint file
format. Estimators follow scikit-learn: hyper-parameters in ``__init__``, ``fit`` returns
``self``, fitted state in trailing-underscore attributes, each with its residual in degrees.

Public API
----------
- :class:`ImuJointCalibration` — two-IMU calibration (static pose + flexion/extension), joint
  orientation ``thorax⁻¹ ⊗ humerus`` in segment frames (:mod:`calibration.alignment`).
- :func:`joint_orientation`, :func:`status_ok` — helpers of the same module.
- :class:`LimbImuCalibration` — one IMU per segment of an arm or a leg (static pose + each
  joint's flexion/extension): mounts, heading offsets, joint orientations
  (:mod:`calibration.limb_calibration`).
- :func:`fuse_vqf`, :class:`FusionResult` — 9-D fusion of one sensor's raw accelerometer,
  gyroscope and magnetometer samples with VQF (:mod:`calibration.fusion`).
- :class:`HeadingCorrection` — relative heading drift of the two IMUs removed at neutral-pose
  checkpoints (:mod:`calibration.heading`).
- :class:`CalibrationProtocol`, :class:`LimbCalibrationProtocol` — the guided calibration
  movements of the shoulder and of a whole arm or leg; :class:`ServoMoveProtocol` — a servo
  arm's, one single-axis move per servo (:mod:`calibration.protocol`).
- :class:`ServoChainCalibration` — servo zero offsets and directions (:mod:`calibration.servo`).
- :class:`BoundaryExtractor`, :func:`boundary_distance`, :func:`outside_fraction` —
  recording → constraint, and its accuracy measures (:mod:`calibration.boundary`).
- :func:`isb_angles`, :func:`range_of_motion`, :func:`format_rom_table`, :data:`NORMATIVE` —
  clinical angles and peaks (:mod:`calibration.clinical`).
- :class:`CalibrationError` — input that cannot determine a result.
"""

from calibration.alignment import ImuJointCalibration, joint_orientation, status_ok
from calibration.boundary import BoundaryExtractor, boundary_distance, outside_fraction
from calibration.clinical import NORMATIVE, format_rom_table, isb_angles, range_of_motion
from calibration.errors import CalibrationError
from calibration.fusion import FusionResult, fuse_vqf
from calibration.heading import HeadingCorrection
from calibration.limb_calibration import LimbImuCalibration
from calibration.protocol import CalibrationProtocol, LimbCalibrationProtocol, ServoMoveProtocol
from calibration.servo import ServoChainCalibration

__all__ = [
    "NORMATIVE",
    "BoundaryExtractor",
    "CalibrationError",
    "CalibrationProtocol",
    "FusionResult",
    "HeadingCorrection",
    "ImuJointCalibration",
    "LimbCalibrationProtocol",
    "LimbImuCalibration",
    "ServoChainCalibration",
    "ServoMoveProtocol",
    "boundary_distance",
    "format_rom_table",
    "fuse_vqf",
    "isb_angles",
    "joint_orientation",
    "outside_fraction",
    "range_of_motion",
    "status_ok",
]
