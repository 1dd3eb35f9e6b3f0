"""``sim://`` backends of :func:`rig.devices.ports.open_port` (imported only when used).

Each opener starts a simulator from :mod:`rig.sim` on a pseudo-terminal and returns a
:class:`~rig.devices.ports.Port` whose ``close`` stops it. The simulated patient
(``patient=``) is a :class:`rig.sim.limb.SimulatedLimb` whose range of motion is a constraint
file or a shipped shape (:mod:`models.shapes`).

Back-driving (``sim://dynamixel?...&patient=...``): each servo's hand position is a function of
the simulator's clock, ``ticks_i(t) = IK(limb.joint(t - t0))_i`` with the chain's closed-form
inverse kinematics (:class:`rig.devices.kinematics.ChainKinematics`), evaluated once per
millisecond of simulated time and shared by the servos; the IK solution nearest the previous one
keeps the joint angles continuous. While torque is off, Present Position follows it
(:meth:`rig.sim.dynamixel.DynamixelBus.set_hand`), as a clinician moving a back-drivable limb.
"""

from __future__ import annotations

import threading
import urllib.parse
from typing import Any

import numpy as np

from rig.devices.ports import Port, _closing
from rig.errors import RigConfigError, UnreachableError

_DXL_OWN_KEYS = frozenset({"patient", "chain", "speed", "excursion"})


def load_patient(spec: str, *, sensors: int = 2, seed: int = 0, noise: str = "default",
                 speed: float = 1.0, excursion: float = 1.0, url: str = "") -> Any:
    """A :class:`~rig.sim.limb.SimulatedLimb` for ``patient=<shape name | constraint path>``."""
    from models.constraint import load_constraint
    from models.errors import ModelsError
    from models.shapes import SHAPES, load_shape
    from rig.sim.limb import NoiseModel, SimulatedLimb

    try:
        constraint = load_shape(spec) if spec in SHAPES else load_constraint(spec)
    except FileNotFoundError as err:
        raise RigConfigError(f"port {url!r}: patient {spec!r} is neither a shape "
                             f"({', '.join(SHAPES)}) nor a constraint file") from err
    except ModelsError as err:
        raise RigConfigError(f"port {url!r}: patient {spec!r}: {err}") from err
    if noise not in ("default", "ideal"):
        raise RigConfigError(f"port {url!r}: noise must be 'default' or 'ideal', got {noise!r}")
    model = NoiseModel.ideal() if noise == "ideal" else NoiseModel()
    try:
        return SimulatedLimb.from_constraint(constraint, sensors=sensors, seed=seed, noise=model,
                                             speed=speed, excursion=excursion)
    except ValueError as err:
        raise RigConfigError(f"port {url!r}: {err}") from err


def _patient_t0(clock: Any, t0: float) -> float:
    """:attr:`Port.patient_t0 <rig.devices.ports.Port.patient_t0>` of a patient whose motion
    time is 0 when the simulator's ``clock`` reads ``t0``: host monotonic time on the real clock
    and on a :class:`~rig.sim.clock.ScaledClock` (its ``host_time``), the clock's own reading on
    a :class:`~rig.sim.clock.ManualClock` (whose time no host time corresponds to)."""
    host_time = getattr(clock, "host_time", None)
    return float(host_time(t0)) if host_time is not None else float(t0)


def _num(one: dict[str, str], key: str, default: Any, kind: type, url: str) -> Any:
    if key not in one:
        return default
    try:
        return kind(one[key])
    except ValueError:
        raise RigConfigError(f"port {url!r}: {key}={one[key]!r} is not a "
                             f"{'number' if kind is float else 'whole number'}") from None


class _BackDrive:
    """Joint ticks of a simulated patient through the chain's IK, cached per millisecond."""

    def __init__(self, limb: Any, kinematics: Any, t0: float) -> None:
        self.limb = limb
        self.kin = kinematics
        self.t0 = t0
        self._lock = threading.Lock()
        self._key: int | None = None
        self._ticks = kinematics.zero_ticks.astype(np.float64)
        self.unreachable = 0

    def ticks(self, now: float) -> np.ndarray:
        key = int(now * 1000.0)
        with self._lock:
            if key != self._key:
                self._key = key
                q = self.limb.joint(max(0.0, key / 1000.0 - self.t0))[0]
                self._ticks, reached = self._step(q, self._ticks)
                self.unreachable += not reached
            return self._ticks

    def _step(self, q: np.ndarray, ticks: np.ndarray) -> tuple[np.ndarray, bool]:
        """The chain's ticks for limb orientation ``q``: the IK solution nearest ``ticks``, or
        ``ticks`` unchanged where ``q`` is out of reach (the servo limb cannot follow: it stays
        put). Also says whether ``q`` was reached."""
        try:
            return self.kin.inverse_float(q, ticks), True
        except UnreachableError:
            return ticks, False

    def follow(self, joint_q: np.ndarray) -> tuple[np.ndarray, int]:
        """The orientations (N, 4) the chain takes, from its zero, while the patient moves
        through ``joint_q`` (N, 4), unquantised, and how many of them were out of reach."""
        ticks = self.kin.zero_ticks.astype(np.float64)
        out = np.empty((len(joint_q), len(ticks)))
        missed = 0
        for i, q in enumerate(joint_q):
            ticks, reached = self._step(q, ticks)
            missed += not reached
            out[i] = ticks
        return self.kin.forward_batch(out), missed

    def hand(self, index: int):
        return lambda now: float(self.ticks(now)[index])


def open_sim_dynamixel(url: str, *, baud: int | None = None) -> Port:
    from rig.sim.dynamixel import bus_from_url

    parts = urllib.parse.urlsplit(url)
    query = urllib.parse.parse_qs(parts.query, keep_blank_values=True)
    own = {k: v[-1] for k, v in query.items() if k in _DXL_OWN_KEYS}
    overrides: dict[str, Any] = {}
    if "baud" not in query and baud is not None:
        overrides["baud_rate"] = int(baud)
    try:
        bus = bus_from_url(url, also_known=tuple(sorted(_DXL_OWN_KEYS)), **overrides)
    except RigConfigError as err:  # every message names the URL
        raise RigConfigError(str(err) if url in str(err) else f"{url}: {err}") from err
    port = Port(url=url, path=bus.port, simulator=bus, kind="sim-dynamixel")
    port._closers.append(_closing(bus))
    if "patient" not in own:
        if own:
            port.close()
            raise RigConfigError(f"port {url!r}: {', '.join(sorted(own))} need patient=")
        return port
    try:
        from rig.devices.config import load_rig_config

        chain_name = own.get("chain", "sim-shoulder")
        cfg = load_rig_config(chain_name)
        if cfg.servos is None:
            raise RigConfigError(f"port {url!r}: chain={chain_name!r} has no servo chain")
        kin = cfg.servos.kinematics()
        missing = [i for i in kin.ids if i not in bus.servos]
        if missing:
            raise RigConfigError(f"port {url!r}: chain {chain_name!r} needs servo IDs "
                                 f"{list(kin.ids)}, the simulated bus has no ID {missing[0]}")
        seed = _num({k: v[-1] for k, v in query.items()}, "seed", 0, int, url)
        limb = load_patient(own["patient"], sensors=2, seed=seed,
                            speed=_num(own, "speed", 1.0, float, url),
                            excursion=_num(own, "excursion", 1.0, float, url), url=url)
        t0 = bus.clock()
        drive = _BackDrive(limb, kin, t0)
        for k, dxl_id in enumerate(kin.ids):
            bus.set_hand(dxl_id, drive.hand(k))
        port.patient = limb
        port.patient_t0 = _patient_t0(bus.clock, t0)
        port.backdrive = drive  # type: ignore[attr-defined]
    except BaseException:
        port.close()
        raise
    return port


def open_sim_bno055(url: str, *, baud: int | None = None) -> Port:
    """``sim://bno055?...``: :func:`rig.sim.imu.bno055_from_url` (keys documented there)."""
    from rig.sim.imu import bno055_from_url

    return _open_sim_imu(url, bno055_from_url, "sim-bno055")


def open_sim_imu_stream(url: str, *, baud: int | None = None) -> Port:
    """``sim://imu-stream?...``: :func:`rig.sim.imu.stream_from_url` (keys documented there)."""
    from rig.sim.imu import stream_from_url

    return _open_sim_imu(url, stream_from_url, "sim-imu-stream")


def _open_sim_imu(url: str, start: Any, kind: str) -> Port:
    sim = start(url)
    # the simulator samples its patient at clock() - started_at (its device time)
    port = Port(url=url, path=sim.port, simulator=sim, kind=kind, patient=sim.limb,
                patient_t0=_patient_t0(sim.clock, sim.started_at))
    port._closers.append(_closing(sim))
    return port
