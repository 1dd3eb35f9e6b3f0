"""The forearm joint in ``calibration/``: elbow flexion and forearm pronation–supination from
the joint's orientations alone, their extraction as a ``kind: forearm`` constraint, and their
norms.

Clinical angles (:meth:`ForearmCalibration.clinical_angles`)
------------------------------------------------------------
A joint orientation ``q`` (forearm relative to upper arm, rig frames: +X along the segment
distally, +Y anterior, +Z to the body's right; a left arm mirrored through the sagittal plane
first, ``(w, x, y, z) → (w, −x, −y, z)``, as :mod:`calibration.joint_angles` does) is read as
the nearest ``F(θ) ⊗ R(φ)`` — flexion ``θ`` about the elbow's +Z, then axial rotation ``φ``
about the forearm's +X (:func:`models.kinds.forearm.decompose`, exact, closed form). These are
the ISB elbow's Cardan angles (Wu et al. 2005, *J Biomech* 38:981, §3.4: ``Rz(α) Rx(β)
Ry(γ)`` in ISB frames) with the carrying angle ``β`` taken out: **flexion = θ** (extension
negative) and, ISB's forearm +Y pointing proximally where the rig's +X points distally,
**pronation = −φ** (supination negative). On an orientation with no carrying angle they equal
:func:`calibration.joint_angles.joint_angles`'s ``alpha`` and ``gamma`` exactly.

Where the forearm's rotation is recorded matters: it happens between the radius and the ulna,
so a model whose forearm segment is the ulna (CMU's BVH skeleton: ``ulna`` and ``hand``
segments) carries most pronation between the forearm and the hand, not at the elbow
(``tests/calibration/data/real/README.md``); the angles here are those of the joint given.

Norms (:attr:`ForearmCalibration.norms`)
----------------------------------------
AAOS 1965 (*Joint motion: method of measuring and recording*, American Academy of Orthopaedic
Surgeons): elbow flexion 150°, extension 0°, forearm pronation 80°, supination 80° — the values
:data:`calibration.joint_angles.NORMATIVE` gives the elbow.

Extraction (:class:`ForearmExtractor`)
--------------------------------------
As the hinge's (:class:`calibration.boundary.HingeExtractor`): usable samples, isolated spikes
dropped (:mod:`calibration.boundary.outliers`), then each interval the recorded extremes of
its angle, written rounded outwards to 1e-4° (the file holds what was recorded). The off-axis
motion (the angle to the nearest ``F(θ) ⊗ R(φ)``: the carrying angle) is reported, not fitted.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from calibration.boundary.hinge import AxisSettings
from calibration.boundary.outliers import find_spikes, usable_samples
from calibration.clinical import check_side, mirror_quaternions
from calibration.errors import CalibrationError
from calibration.kinds.base import CalibrationKind
from models import quaternion as Q
from models.constraint import JointConstraint
from models.kinds.forearm import decompose

__all__ = ["AAOS_FOREARM", "ELBOW_AXIS", "ForearmCalibration", "ForearmExtractor"]

#: The elbow's flexion axis in rig segment frames (the upper arm's +Z, to the body's right).
ELBOW_AXIS = (0.0, 0.0, 1.0)

#: AAOS 1965 normal values (degrees) of the forearm joint's movements (module doc).
AAOS_FOREARM: dict[str, float] = {"flexion": 150.0, "extension": 0.0, "pronation": 80.0,
                                  "supination": 80.0}


class ForearmExtractor(AxisSettings):
    """A forearm joint's flexion and rotation intervals from its recorded orientations.

    Parameters
    ----------
    axis : (3,) the flexion axis (parent frame)
    limb_axis : (3,) the forearm's long axis (its own frame)
    max_speed_dps, spike_max_samples, min_system_status
        As :class:`calibration.boundary.HingeExtractor`'s.
    name : str
        The written constraint's name.
    """

    def __init__(self, axis=ELBOW_AXIS, *, limb_axis=(1.0, 0.0, 0.0),
                 max_speed_dps: float = 3000.0, spike_max_samples: int = 2,
                 min_system_status: int = 2, name: str = "recorded") -> None:
        super().__init__(axis, "flexion axis", limb_axis=limb_axis,
                         max_speed_dps=max_speed_dps, spike_max_samples=spike_max_samples,
                         min_system_status=min_system_status, name=name)

    def fit(self, q, *, status=None, t=None, provenance: dict | None = None,
            **_error: Any) -> ForearmExtractor:
        """Extract the intervals from joint orientations ``q`` (N, 4) (child relative to
        parent), with their IMU ``status`` bytes and sample times ``t`` when known. A measured
        slow error (``slow_error_deg``, ``reach_error_deg``) moves nothing in: the intervals
        hold the recorded extremes."""
        usable = usable_samples(q, status, t, min_system_status=self.min_system_status)
        recorded = Q.rotate(usable.q, self.limb_axis)
        spikes = find_spikes(recorded, usable.t, self.max_speed_dps, self.spike_max_samples)
        qk = usable.q[~spikes]
        theta, phi, sigma = decompose(qk, self.axis, self.limb_axis)
        theta, phi = np.degrees(theta), np.degrees(phi)
        for what, a in (("flexion", theta), ("axial rotation", phi)):
            if np.ptp(a) > 300.0:
                raise CalibrationError(f"the recorded {what} turns all the way round: not a "
                                       "forearm joint about these axes")
        s = np.minimum(sigma, 1.0)
        off = np.degrees(2.0 * np.arctan2(np.sqrt(np.maximum(1.0 - s * s, 0.0)), s))
        self.n_samples_ = usable.n_samples
        self.n_status_dropped_ = usable.n_status_dropped
        self.n_spikes_ = int(spikes.sum())
        self.n_used_ = len(qk)
        self.flexion_deg_ = (float(theta.min()), float(theta.max()))
        self.rotation_deg_ = (float(phi.min()), float(phi.max()))
        self.off_axis_rms_deg_ = float(np.sqrt(np.mean(off ** 2)))
        self.off_axis_p99_deg_ = float(np.percentile(off, 99))
        prov = dict(provenance or {})
        prov.update({"method": "calibration.kinds.forearm.ForearmExtractor",
                     "parameters": self.params(), "samples": int(usable.n_samples),
                     "samples_used": self.n_used_,
                     "dropped_status": int(usable.n_status_dropped), "spikes": self.n_spikes_,
                     "off_axis_rms_deg": round(self.off_axis_rms_deg_, 3),
                     "off_axis_p99_deg": round(self.off_axis_p99_deg_, 3)})
        (f_lo, f_hi), (r_lo, r_hi) = self.flexion_deg_, self.rotation_deg_
        self.constraint_ = JointConstraint.from_dict({
            "name": self.name, "kind": ForearmCalibration.name,
            "limb_axis": self.limb_axis.tolist(),
            "forearm": {"flexion": {"axis": self.axis.tolist(), "min_deg": _down(f_lo),
                                    "max_deg": _up(f_hi)},
                        "rotation": {"min_deg": _down(r_lo), "max_deg": _up(r_hi)}},
            "provenance": prov})
        return self

    def report(self) -> dict[str, Any]:
        """What the extraction did, as plain types (for the CLI and the store)."""
        return {"kind": ForearmCalibration.name, "samples": self.n_samples_,
                "samples_used": self.n_used_, "dropped_status": self.n_status_dropped_,
                "spikes": self.n_spikes_, "flexion_deg": list(self.flexion_deg_),
                "rotation_deg": list(self.rotation_deg_),
                "off_axis_rms_deg": self.off_axis_rms_deg_,
                "off_axis_p99_deg": self.off_axis_p99_deg_}


def _down(v: float) -> float:
    return max(-180.0, math.floor(v * 1e4) / 1e4)


def _up(v: float) -> float:
    return min(180.0, math.ceil(v * 1e4) / 1e4)


class ForearmCalibration(CalibrationKind):
    """The forearm joint's extraction, clinical angles and norms (module doc)."""

    name = "forearm"
    angles = (0, 2)
    unmeasured_words = "not measured by a forearm joint"
    reads_in_band = False
    bounds = (0, 2)
    movements = (("flexion", "extension"), ("pronation", "supination"))
    norms = AAOS_FOREARM
    norms_source = "AAOS 1965, Joint motion: method of measuring and recording"

    def extractor(self, spec, *, limb_axis, alpha_deg, max_vertices, by_swing, name) -> Any:
        axis = ELBOW_AXIS if spec is None or spec.hinge_axis is None else spec.hinge_axis
        return ForearmExtractor(axis, limb_axis=limb_axis, name=name)

    def clinical_angles(self, q, side: str = "right") -> dict[str, np.ndarray]:
        q = Q.check_quaternions(np.atleast_2d(q), normalize=True, name="joint orientation")
        if check_side(side) == "left":
            q = mirror_quaternions(q)
        theta, phi, _ = decompose(q, np.array(ELBOW_AXIS), np.array([1.0, 0.0, 0.0]))
        return {"flexion": np.degrees(theta), "pronation": -np.degrees(phi)}

    def describe_extraction(self, ex, report) -> list[str]:
        r = report
        f_lo, f_hi = r["flexion_deg"]
        r_lo, r_hi = r["rotation_deg"]
        return [f"  samples     {r['samples']} ({r['samples_used']} used, "
                f"{r['dropped_status']} dropped for IMU status, {r['spikes']} isolated spikes)",
                f"  flexion     {f_lo:.1f} .. {f_hi:.1f} deg about "
                f"{', '.join(f'{v:g}' for v in ex.axis)}",
                f"  rotation    {r_lo:.1f} .. {r_hi:.1f} deg about the limb's long axis "
                f"(pronation {max(0.0, -r_lo):.1f}, supination {max(0.0, r_hi):.1f} deg)",
                f"  off-axis    {r['off_axis_rms_deg']:.1f} deg RMS, "
                f"{r['off_axis_p99_deg']:.1f} deg p99 (carrying angle and other motion: "
                "corrected onto the joint, not a limit)"]

    def allowed_samples(self, constraint, step_deg: float) -> np.ndarray:
        f = constraint.limits
        step = min(step_deg, 0.5)
        th = np.radians(np.arange(f.flexion_min_deg, f.flexion_max_deg + 1e-9, step))
        ph = np.radians(np.arange(f.rotation_min_deg, f.rotation_max_deg + 1e-9, step))
        lo_hi_t = np.radians([f.flexion_min_deg, f.flexion_max_deg])
        lo_hi_p = np.radians([f.rotation_min_deg, f.rotation_max_deg])
        t = np.concatenate((np.repeat(lo_hi_t, len(ph)), th, th))
        p = np.concatenate((np.tile(ph, 2), np.full(len(th), lo_hi_p[0]),
                            np.full(len(th), lo_hi_p[1])))
        n = np.asarray(f.axis, float)
        return Q.multiply(Q.from_axis_angle(n, t),
                          Q.from_axis_angle(np.asarray(constraint.limb_axis, float), p))
