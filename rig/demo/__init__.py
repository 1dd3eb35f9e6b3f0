"""The main job end to end on the simulated rig (``rig demo``, ``rig demo --limb arm|leg``): one
pipeline, :func:`rig.demo.pipeline.run_demo`, for the shoulder (:mod:`rig.demo.joint`) and a
whole limb (:mod:`rig.demo.limb`), with the stages' shared parts in :mod:`rig.demo.stages`."""

from rig.demo.joint import parse_ids
from rig.demo.pipeline import run_demo
from rig.demo.stages import DemoOptions, DemoResult, StageResult

__all__ = ["DemoOptions", "DemoResult", "StageResult", "parse_ids", "run_demo"]
