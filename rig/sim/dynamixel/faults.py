"""Fault injection on the simulated Dynamixel bus: what goes wrong on real buses, on demand.

Every fault is something a host sees on hardware, produced on the wire (the host's SDK meets
real timeouts, real CRC failures, a real EIO), never by patching the host:

=====================================  =========================================================
method                                 what the host sees
=====================================  =========================================================
``drop_responses(n)``                  the next ``n`` status packets never come (timeout)
``corrupt_responses(n)``               their CRC is wrong (``COMM_RX_CORRUPT``)
``truncate_responses(keep, n)``        only the first ``keep`` bytes come (corrupt / timeout)
``delay_responses(s, n)``              they come ``s`` seconds late (timeout, then stale bytes)
``corrupt_instructions(n)``            the next ``n`` instruction packets arrive with a bad CRC
                                       (line noise towards the servos): no servo answers or acts
``set_fault_rates(drop=, corrupt=)``   every status packet is dropped / corrupted with that
                                       probability (seeded), e.g. 1 % each for a soak test
``raise_hardware_error(id, kind)``     Hardware Error Status bit, alert bit on every status,
                                       torque off if the bit is in Shutdown (63)
``set_temperature(id, °C)``            Present Temperature; overheating above the limit
``unplug(ids)`` / ``replug(ids)``      those servos' cables pulled: they stop answering and
                                       hear nothing (their Bus Watchdog runs out)
``unplug()`` / ``replug()``            the bus cable between adapter and servos
``unplug(adapter=True)`` /             the USB adapter itself (:meth:`disconnect` /
``replug(adapter=True)``               :meth:`reconnect`): the port fails with EIO; a new pty
``schedule_unplug(after, for_s)``      the bus cable pulled once the bus has heard ``after``
                                       instruction packets (for ``for_s`` s of simulated
                                       time, or for good): the URL's ``unplug_after=``
=====================================  =========================================================

:attr:`FaultInjection.fault_counts` counts what was injected (``dropped``, ``corrupted``,
``truncated``, ``delayed``, ``instructions_corrupted``).
"""

from __future__ import annotations

import math
import random
from collections.abc import Iterable
from dataclasses import dataclass, field

from rig.sim.dynamixel.servo import HARDWARE_ERRORS

__all__ = ["FaultInjection", "Faults"]


@dataclass
class Faults:
    """Pending faults of a bus (counts of packets still to be affected, and random rates)."""

    drop: int = 0
    corrupt: int = 0
    delay: float = 0.0
    delay_count: int = 0
    truncate: int = 0
    truncate_keep: int = 0
    corrupt_instructions: int = 0
    drop_rate: float = 0.0
    corrupt_rate: float = 0.0
    rng: random.Random = field(default_factory=lambda: random.Random(0))
    bus_unplugged: bool = False
    unplug_window: tuple[float, float] | None = None  # [from, until) on the bus's clock, s
    unplug_after: int | None = None  # instructions heard before a scheduled unplug
    unplug_for: float = math.inf
    counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(
        ("dropped", "corrupted", "truncated", "delayed", "instructions_corrupted"), 0))

    def outgoing(self, packet: bytes) -> tuple[bytes | None, float]:
        """Apply the pending faults to one status packet: ``(bytes or None if dropped, extra
        delay in s)``."""
        c = self.counts
        if self.drop or (self.drop_rate and self.rng.random() < self.drop_rate):
            self.drop = max(0, self.drop - 1)
            c["dropped"] += 1
            return None, 0.0
        if self.corrupt or (self.corrupt_rate and self.rng.random() < self.corrupt_rate):
            self.corrupt = max(0, self.corrupt - 1)
            c["corrupted"] += 1
            packet = packet[:-2] + bytes((packet[-2] ^ 0xFF, packet[-1] ^ 0x5A))
        if self.truncate:
            self.truncate -= 1
            c["truncated"] += 1
            packet = packet[:self.truncate_keep]
        extra = 0.0
        if self.delay_count:
            self.delay_count -= 1
            c["delayed"] += 1
            extra = self.delay
        return packet, extra

    def heard(self, count: int, now: float) -> None:
        """The bus has heard its ``count``-th instruction at bus time ``now``: a scheduled
        unplug (:meth:`FaultInjection.schedule_unplug`) pulls the cable from this one on."""
        if self.unplug_after is not None and count > self.unplug_after:
            self.unplug_window = (now, now + self.unplug_for)
            self.unplug_after = None

    def cable_out(self, now: float) -> bool:
        """True while the bus cable is out at bus time ``now`` (pulled, or scheduled out)."""
        w = self.unplug_window
        return self.bus_unplugged or (w is not None and w[0] <= now < w[1])

    def spoil_instruction(self) -> bool:
        """True if the instruction packet just decoded is to be taken as arriving with a bad
        CRC (a pending :meth:`FaultInjection.corrupt_instructions`)."""
        if not self.corrupt_instructions:
            return False
        self.corrupt_instructions -= 1
        self.counts["instructions_corrupted"] += 1
        return True


class FaultInjection:
    """The fault-injection API of :class:`~rig.sim.dynamixel.bus.DynamixelBus` (a mixin).

    The host needs the same code on hardware and here; only the test or benchmark calls these.
    """

    # provided by DynamixelBus / PtyServer: lock, servos, port, servo(), disconnect(),
    # reconnect() (not declared here: a mixin's stubs would shadow them in the MRO)
    _faults: Faults

    @property
    def fault_counts(self) -> dict[str, int]:
        """Faults injected so far, by kind (a copy)."""
        with self.lock:  # type: ignore[attr-defined]
            return dict(self._faults.counts)

    def drop_responses(self, count: int = 1) -> None:
        """Do not send the next ``count`` status packets (the host times out)."""
        with self.lock:  # type: ignore[attr-defined]
            self._faults.drop += count

    def corrupt_responses(self, count: int = 1) -> None:
        """Flip the CRC of the next ``count`` status packets."""
        with self.lock:  # type: ignore[attr-defined]
            self._faults.corrupt += count

    def delay_responses(self, seconds: float, count: int = 1) -> None:
        """Send the next ``count`` status packets ``seconds`` (real time) late."""
        with self.lock:  # type: ignore[attr-defined]
            self._faults.delay, self._faults.delay_count = float(seconds), count

    def truncate_responses(self, keep: int = 9, count: int = 1) -> None:
        """Send only the first ``keep`` bytes of the next ``count`` status packets."""
        with self.lock:  # type: ignore[attr-defined]
            self._faults.truncate, self._faults.truncate_keep = count, keep

    def corrupt_instructions(self, count: int = 1) -> None:
        """The next ``count`` instruction packets arrive with a bad CRC: ignored by every
        servo (no status, no effect; see ``docs/sim.md`` on CRC errors)."""
        with self.lock:  # type: ignore[attr-defined]
            self._faults.corrupt_instructions += count

    def set_fault_rates(self, *, drop: float = 0.0, corrupt: float = 0.0,
                        seed: int = 0) -> None:
        """Drop / corrupt each status packet independently with these probabilities.

        Parameters
        ----------
        drop, corrupt : float
            Probabilities in [0, 1]; 0 turns the random fault off.
        seed : int
            Seed of the draws (reproducible soak tests).
        """
        for name, p in (("drop", drop), ("corrupt", corrupt)):
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{name} rate must be in [0, 1], got {p!r}")
        with self.lock:  # type: ignore[attr-defined]
            self._faults.drop_rate, self._faults.corrupt_rate = float(drop), float(corrupt)
            self._faults.rng = random.Random(seed)

    def raise_hardware_error(self, dxl_id: int, kind: str | int = "overload") -> None:
        """Raise a hardware error (a :data:`~rig.sim.dynamixel.servo.HARDWARE_ERRORS` name or
        raw bits)."""
        if isinstance(kind, str) and kind not in HARDWARE_ERRORS:
            raise ValueError(f"unknown hardware error {kind!r}; one of "
                             f"{', '.join(HARDWARE_ERRORS)}")
        bits = HARDWARE_ERRORS[kind] if isinstance(kind, str) else int(kind)
        with self.lock:  # type: ignore[attr-defined]
            self.servo(dxl_id).raise_error(bits)

    def set_temperature(self, dxl_id: int, celsius: float) -> None:
        """Set a servo's temperature; above its Temperature Limit it reports overheating."""
        with self.lock:  # type: ignore[attr-defined]
            self.servo(dxl_id).set_temperature(celsius)

    def unplug(self, ids: Iterable[int] | None = None, *, adapter: bool = False) -> None:
        """Unplug something; the host sees what it would see on hardware.

        Parameters
        ----------
        ids : iterable of int, optional
            Servos whose cable is pulled: they stop answering (and hearing). ``None``: the bus
            cable between adapter and servos, so nobody answers (timeouts, the port stays open).
        adapter : bool, default False
            Unplug the USB adapter itself instead (:meth:`disconnect`): the pty goes away.
        """
        if adapter:
            self.disconnect()  # type: ignore[attr-defined]
            return
        with self.lock:  # type: ignore[attr-defined]
            if ids is None:
                self._faults.bus_unplugged = True
            else:
                for i in ids:
                    self.servo(i).plugged = False  # type: ignore[attr-defined]

    def schedule_unplug(self, after: int, for_s: float | None = None) -> None:
        """Pull the bus cable once the bus has heard ``after`` more instruction packets (the
        next one goes unheard) and plug it back ``for_s`` seconds of simulated time later
        (None: never): a leader arm's cable pulled mid-run, at a point of the host's own
        sequence (a loop reading once a cycle: ``after`` cycles plus its set-up), whatever
        process drives the bus and however long the host took to start (``unplug_after=`` /
        ``unplug_for=`` of a ``sim://dynamixel`` URL)."""
        with self.lock:  # type: ignore[attr-defined]
            f = self._faults
            f.unplug_after = self.instructions_seen + int(after)  # type: ignore[attr-defined]
            f.unplug_for = math.inf if for_s is None else float(for_s)
            f.unplug_window = None

    def replug(self, ids: Iterable[int] | None = None, *, adapter: bool = False) -> str:
        """Undo :meth:`unplug` (``ids`` None: the bus cable and every servo).

        With ``adapter=True`` the adapter is plugged back (:meth:`reconnect`): a new pty.
        Returns the port path, which changes only after an adapter replug.
        """
        if adapter:
            return self.reconnect()  # type: ignore[attr-defined]
        with self.lock:  # type: ignore[attr-defined]
            if ids is None:
                self._faults.bus_unplugged = False
                self._faults.unplug_window = None
                self._faults.unplug_after = None
                ids = [s.id for s in self.servos.values()]  # type: ignore[attr-defined]
                for s in self.servos.values():  # type: ignore[attr-defined]
                    s.plugged = True
                return self.port  # type: ignore[attr-defined]
            for i in ids:
                self.servo(i).plugged = True  # type: ignore[attr-defined]
            return self.port  # type: ignore[attr-defined]
