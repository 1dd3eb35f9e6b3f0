"""One extraction entry: recorded joint orientations of a limb (one joint or several, in the
limb's order) → a limb file, each joint's limits by its kind's extraction
(:mod:`calibration.kinds`) and the couplings between them.

- :mod:`~calibration.extraction.joint`: one joint's extraction, looked up by its kind;
- :mod:`~calibration.extraction.limb`: :class:`LimbExtractor`, a limb of one or more joints
  (a single joint is a limb of one joint).

This room sits above :mod:`calibration.boundary` (the steps: outliers, projection, alpha
shapes, twist, comparisons) and :mod:`calibration.kinds` (what each kind extracts), so that
neither of those imports it.
"""

from calibration.extraction.joint import fit_joint, joint_extractor
from calibration.extraction.limb import LimbExtractor

__all__ = ["LimbExtractor", "fit_joint", "joint_extractor"]
