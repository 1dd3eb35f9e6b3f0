"""The guided calibration protocol: what the patient is asked to do, as a function of time.

Two phases, then free recording (frames of :mod:`calibration.alignment`: +X inferior along the
arm, +Y anterior, +Z = X × Y; flexion is a positive rotation about +Z):

1. **static** (``static_s`` seconds): neutral pose, arm hanging at the side, forearm forward;
   the joint orientation is the identity.
2. **functional** (``functional_s`` seconds): flexion/extension in the sagittal plane,
   ``θ(t) = A(t) sin(2π t / period_s)``, flexion first; ``A = flexion_deg`` while
   ``sin > 0``, ``extension_deg`` otherwise. Joint orientation ``Rz(θ)``.

:meth:`CalibrationProtocol.joint` gives the scripted joint orientation (a simulator drives the
simulated patient with it, through the patient's own range limits); :meth:`windows` gives the
time windows a recorder slices the samples by. Times are seconds from the start of the
protocol.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from models import quaternion as Q

__all__ = ["CalibrationProtocol"]

_Z = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class CalibrationProtocol:
    """Durations (s) and amplitudes (deg) of the calibration movements (see module doc).

    ``settle_s`` at the start and end of each phase are excluded from its window (the patient
    getting into position).
    """

    static_s: float = 5.0
    functional_s: float = 10.0
    flexion_deg: float = 30.0
    extension_deg: float = 15.0
    period_s: float = 5.0
    settle_s: float = 0.5

    def __post_init__(self) -> None:
        for name in ("static_s", "functional_s", "period_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not 0 <= 2 * self.settle_s < min(self.static_s, self.functional_s):
            raise ValueError("settle_s must leave part of each phase")

    @property
    def duration_s(self) -> float:
        """Total length of the protocol, seconds."""
        return self.static_s + self.functional_s

    def windows(self) -> dict[str, tuple[float, float]]:
        """``{"static": (t0, t1), "functional": (t0, t1)}``, seconds from the protocol start."""
        s = self.settle_s
        return {
            "static": (s, self.static_s - s),
            "functional": (self.static_s + s, self.duration_s - s),
        }

    def flexion_angle(self, t) -> np.ndarray:
        """Scripted flexion angle θ(t), radians (0 during the static phase and after the end)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        u = t - self.static_s
        s = np.sin(2.0 * math.pi * u / self.period_s)
        amp = np.where(s > 0, math.radians(self.flexion_deg), math.radians(self.extension_deg))
        active = (u >= 0) & (u <= self.functional_s)
        return np.where(active, amp * s, 0.0)

    def joint(self, t) -> np.ndarray:
        """Scripted joint orientation (N, 4), limb relative to thorax, at times ``t`` (N,)."""
        return Q.from_axis_angle(_Z, self.flexion_angle(t))
