"""A hinge's interval from a recording (the elbow, the knee): :class:`HingeExtractor`.

The same principle and the same steps as the swing-twist extraction
(:class:`~calibration.boundary.BoundaryExtractor`), on one angle:

1. usable samples (IMU status, times) and isolated spikes of the child segment's long-axis
   direction (:mod:`~calibration.boundary.outliers`): a glitch, not motion;
2. the hinge angle of every other sample — the rotation about the hinge axis
   (:func:`calibration.joints.hinge_angles`; out-of-axis motion does not move it);
3. its envelope, each end moved in only as far as the recording's own measured errors support
   (:func:`~calibration.boundary.twist.twist_envelope`, the twist range's method: the fast
   noise measured on the angle, a dwell at the limit for slow errors): the interval written.

What the interval holds is then measured on it: the share of the recorded angles inside it and
within 1° of it. Out-of-axis motion — a real elbow's carrying angle and forearm rotation, a
knee's small abduction and rotation, an IMU's soft-tissue artefact — is reported (RMS and 99th
percentile of the angle to the nearest hinge rotation), not fitted: the hinge's correction
takes any orientation to the nearest allowed hinge rotation (:mod:`models.oracle`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from calibration.boundary.outliers import find_spikes, usable_samples
from calibration.boundary.twist import TwistSettings, twist_envelope
from calibration.errors import CalibrationError
from calibration.joints import hinge_angles, off_axis_angles
from models import quaternion as Q
from models.constraint import JointConstraint

__all__ = ["HingeExtractor"]


class AxisSettings:
    """What the extractors of a joint turning about a given axis share (a hinge,
    :class:`HingeExtractor`; a forearm, :class:`calibration.kinds.forearm.ForearmExtractor`):
    the axis (parent frame), the child's long axis (spikes are found on its direction), the
    spike test's speed and length, the lowest IMU system status used, the constraint's name."""

    def __init__(self, axis, axis_name: str, *, limb_axis=(1.0, 0.0, 0.0),
                 max_speed_dps: float = 3000.0, spike_max_samples: int = 2,
                 min_system_status: int = 2, name: str = "recorded") -> None:
        self.axis = Q.check_vectors(axis, name=axis_name)
        self.limb_axis = Q.check_vectors(limb_axis, name="limb_axis")
        if not max_speed_dps > 0:
            raise ValueError(f"max_speed_dps must be > 0, got {max_speed_dps!r}")
        self.max_speed_dps = float(max_speed_dps)
        self.spike_max_samples = int(spike_max_samples)
        self.min_system_status = int(min_system_status)
        self.name = name

    def params(self) -> dict[str, Any]:
        """The settings, as plain types (the written constraint's provenance)."""
        return {"axis": [float(v) for v in self.axis], "max_speed_dps": self.max_speed_dps,
                "spike_max_samples": self.spike_max_samples,
                "min_system_status": self.min_system_status}


class HingeExtractor(AxisSettings):
    """Recorded joint orientations → a ``hinge`` constraint (module doc).

    Parameters
    ----------
    axis : (3,) array_like
        The hinge axis (parent frame = child frame at the hinge's zero).
    limb_axis : (3,) array_like
        The child segment's long axis (spikes are found on its direction).
    max_speed_dps, spike_max_samples, min_system_status
        As :class:`~calibration.boundary.BoundaryExtractor`'s.
    noise_correction : bool
        Move each end in by the measured errors (False: the envelope as recorded).
    name : str
        The constraint's name.

    Attributes
    ----------
    constraint_ : models.constraint.JointConstraint
    interval_deg_ : (float, float)
    inside_, inside_1deg_ : float, shares of the recorded angles inside / within 1°
    off_axis_rms_deg_, off_axis_p99_deg_ : float
    noise_deg_, inset_deg_ : the measured fast noise of the angle and each end's inset
    n_samples_, n_used_, n_spikes_, n_status_dropped_ : int
    """

    def __init__(self, axis=(0.0, 0.0, 1.0), *, limb_axis=(1.0, 0.0, 0.0),
                 max_speed_dps: float = 3000.0, spike_max_samples: int = 2,
                 min_system_status: int = 2, noise_correction: bool = True,
                 name: str = "recorded") -> None:
        AxisSettings.__init__(self, axis, "hinge axis", limb_axis=limb_axis,
                              max_speed_dps=max_speed_dps, spike_max_samples=spike_max_samples,
                              min_system_status=min_system_status, name=name)
        self.noise_correction = bool(noise_correction)

    def params(self) -> dict[str, Any]:
        return {**AxisSettings.params(self), "noise_correction": self.noise_correction}

    def fit(self, q, *, status=None, t=None, provenance: dict | None = None,
            slow_error_deg: float | None = None) -> HingeExtractor:
        """Extract the interval from joint orientations ``q`` (N, 4) (child relative to parent),
        with their IMU ``status`` bytes and sample times ``t`` when known (as
        :meth:`~calibration.boundary.BoundaryExtractor.fit`)."""

        usable = usable_samples(q, status, t, min_system_status=self.min_system_status)
        recorded = Q.rotate(usable.q, self.limb_axis)
        spikes = find_spikes(recorded, usable.t, self.max_speed_dps, self.spike_max_samples)
        qk = usable.q[~spikes]
        theta = hinge_angles(qk, self.axis)
        if np.ptp(theta) > 300.0:
            raise CalibrationError("the recorded hinge angle turns all the way round: not a "
                                   "hinge about this axis")
        env = twist_envelope(np.radians(theta), TwistSettings(enabled=self.noise_correction),
                             slow_error_deg)
        lo, hi = env.min_deg, env.max_deg
        rel = Q.wrap_angle_mod(np.radians(theta) - env.mid)
        lo_r, hi_r = np.radians(lo) - env.mid, np.radians(hi) - env.mid
        outside = np.degrees(np.maximum(lo_r - rel, rel - hi_r))
        off = off_axis_angles(qk, self.axis)
        self.n_samples_ = usable.n_samples
        self.n_status_dropped_ = usable.n_status_dropped
        self.n_spikes_ = int(spikes.sum())
        self.n_used_ = len(qk)
        self.angles_ = theta
        self.interval_deg_ = (lo, hi)
        self.noise_deg_ = env.noise_deg
        self.inset_deg_ = env.inset_deg
        self.inside_ = float(np.mean(outside <= 1e-9))
        self.inside_1deg_ = float(np.mean(outside <= 1.0))
        self.off_axis_rms_deg_ = float(np.sqrt(np.mean(off ** 2)))
        self.off_axis_p99_deg_ = float(np.percentile(off, 99))
        prov = dict(provenance or {})
        prov.update({"method": "calibration.boundary.HingeExtractor", "parameters": self.params(),
                     "samples": int(usable.n_samples), "samples_used": self.n_used_,
                     "dropped_status": int(usable.n_status_dropped), "spikes": self.n_spikes_,
                     "noise_inset_deg": [round(x, 3) for x in env.inset_deg],
                     "inside": round(self.inside_, 6),
                     "off_axis_rms_deg": round(self.off_axis_rms_deg_, 3),
                     "off_axis_p99_deg": round(self.off_axis_p99_deg_, 3)})
        # written to 4 decimals, rounded outwards: the file holds what it was measured to hold
        self.constraint_ = JointConstraint.hinge_joint(
            self.axis.tolist(), math.floor(lo * 1e4) / 1e4, math.ceil(hi * 1e4) / 1e4,
            name=self.name,
            limb_axis=self.limb_axis.tolist(), provenance=prov)
        return self

    def report(self) -> dict[str, Any]:
        """What the extraction did, as plain types (for the CLI and the store)."""
        return {"kind": "hinge", "samples": self.n_samples_, "samples_used": self.n_used_,
                "dropped_status": self.n_status_dropped_, "spikes": self.n_spikes_,
                "hinge_deg": [float(v) for v in self.interval_deg_],
                "inside": self.inside_, "inside_1deg": self.inside_1deg_,
                "noise_inset_deg": [float(v) for v in self.inset_deg_],
                "off_axis_rms_deg": self.off_axis_rms_deg_,
                "off_axis_p99_deg": self.off_axis_p99_deg_}
