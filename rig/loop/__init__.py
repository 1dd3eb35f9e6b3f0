"""Real-time limit enforcement on a servo-driven limb: the live loop and its safety supervisor.

- :mod:`rig.loop.supervisor` — the pure safety supervisor (exact oracle each cycle, holds,
  rate limits, the monotone recovery rule);
- :mod:`rig.loop.scheduler` — drift-free absolute-deadline scheduling;
- :mod:`rig.loop.targets` — target sources (CSV trajectories, scripted and adversarial
  motions, mirroring an IMU-worn limb);
- :mod:`rig.loop.runner` — the cycle, faults and safe states;
- :mod:`rig.loop.telemetry` — per-cycle rows, CSV / store writer thread, the run summary;
- :mod:`rig.loop.binding` — which constraint is enforced and whether the model matches it;
- :mod:`rig.loop.backstop` — servo position limits from the boundary;
- :mod:`rig.loop.enforce` — ``rig enforce`` as a library (:func:`run_enforce`:
  :class:`EnforceRequest` → :class:`EnforceResult`): checks, devices, store, the run.

``docs/loop.md`` describes the whole.
"""

from rig.loop.binding import Binding, ModelBindingError, bind_model
from rig.loop.enforce import EnforceHooks, EnforceRequest, EnforceResult, run_enforce
from rig.loop.runner import SAFE_STATES, EnforcementLoop, LoopConfig
from rig.loop.scheduler import Scheduler
from rig.loop.supervisor import Intervention, Supervisor, SupervisorConfig
from rig.loop.targets import CsvTrajectory, MirrorTargets, ScriptedTargets, open_targets
from rig.loop.telemetry import COLUMNS, Fault, Telemetry

__all__ = [
    "COLUMNS",
    "SAFE_STATES",
    "Binding",
    "CsvTrajectory",
    "EnforceHooks",
    "EnforceRequest",
    "EnforceResult",
    "EnforcementLoop",
    "Fault",
    "Intervention",
    "LoopConfig",
    "MirrorTargets",
    "ModelBindingError",
    "Scheduler",
    "ScriptedTargets",
    "Supervisor",
    "SupervisorConfig",
    "Telemetry",
    "bind_model",
    "open_targets",
    "run_enforce",
]
