"""The true values of the coupled clinical tests (:mod:`calibration.clinical_tests`) of a
simulated limb (:func:`rig.sim.patients.anatomical_limb`), read from the clinical limits it
was drawn with (``limb.provenance["clinical"]``), not from its constraint geometry: what
``coupled_measures`` must recover from the limb file.

- the leg: straight-leg raise = hip flexion with the knee straight (the 0° keyframe);
  popliteal angle = the knee angle at which the hip's interpolated flexion limit reaches 90°
  (the limb file's interpolation of a vertex on one great circle, ``docs/limb-format.md``,
  solved exactly per keyframe interval); Silfverskiöld = ankle dorsiflexion with the knee at
  0° and at 90°; the Thomas test = hip extension (uncoupled from the knee in the simulated
  leg) and knee flexion (the hinge's upper limit);
- the arm: shoulder flexion is the same with the elbow straight or bent (the simulated arm
  couples only extension); shoulder extension with the elbow straight (0° keyframe) and bent
  (90°).
"""

from __future__ import annotations

import itertools
import math

from models.limb import Limb

__all__ = ["coupled_test_truth"]


def _crossing(at: list[float], f: list[float], target: float) -> float:
    """The coupling angle at which the interpolated flexion limit reaches ``target``
    (degrees): ``angle(t) = atan2((1-t) s0 + t s1, (1-t) c0 + t c1)`` solved per keyframe
    interval."""
    for (a0, f0), (a1, f1) in itertools.pairwise(zip(at, f, strict=True)):
        if f0 <= target <= f1:
            c0, s0 = math.cos(math.radians(f0)), math.sin(math.radians(f0))
            c1, s1 = math.cos(math.radians(f1)), math.sin(math.radians(f1))
            tt, ct = math.tan(math.radians(target)), math.cos(math.radians(target))
            t = (c0 / (c0 - c1) if abs(ct) < 1e-12
                 else (s0 - tt * c0) / ((s0 - tt * c0) - (s1 - tt * c1)))
            return a0 + t * (a1 - a0)
    raise ValueError(f"the flexion limits {f} never reach {target}°")


def coupled_test_truth(limb: Limb) -> dict[str, float]:
    """Measure key (:data:`calibration.clinical_tests.MEASURES`) → its true value (degrees)
    for a limb made by :func:`rig.sim.patients.anatomical_limb` (module doc).

    Raises
    ------
    ValueError
        A limb without the simulator's ``provenance["clinical"]``.
    """
    c = (limb.provenance or {}).get("clinical")
    if not c:
        raise ValueError(f"limb {limb.name!r}: no provenance['clinical'] (not made by "
                         "rig.sim.patients.anatomical_limb)")
    if limb.limb == "leg":
        h, k, a = c["hip"], c["knee"], c["ankle"]
        slr, flex = h["flexion_knee_straight"], h["flexion"]
        return {"straight_leg_raise": slr,
                "popliteal_angle": _crossing([0, 45, 90], [slr, 0.5 * (slr + flex), flex], 90),
                "silfverskiold_straight": a["dorsiflexion"],
                "silfverskiold_bent": a["dorsiflexion_knee_bent"],
                "thomas_hip": h["extension"], "thomas_knee": k["flexion"]}
    s = c["shoulder"]
    return {"shoulder_flexion_straight": s["flexion"], "shoulder_flexion_bent": s["flexion"],
            "shoulder_extension_straight": s["extension_elbow_straight"],
            "shoulder_extension_bent": s["extension"]}
