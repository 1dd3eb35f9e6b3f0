"""The main job end to end on the simulated rig (``rig demo``): :mod:`rig.demo.pipeline`."""

from rig.demo.pipeline import DemoOptions, DemoResult, StageResult, parse_ids, run_demo

__all__ = ["DemoOptions", "DemoResult", "StageResult", "parse_ids", "run_demo"]
