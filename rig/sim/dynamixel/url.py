"""``sim://dynamixel?...``: the port string that starts a simulated servo bus.

``sim://dynamixel?ids=1,2,3&model=XM430-W350&baud=57600&return_delay_us=0&noise=0.5&seed=1``

==================  ==============================================  =====================
key                 meaning                                         default
==================  ==============================================  =====================
``ids``             servo IDs, ``1,2,3`` or ``1-3``; for a mixed    ``1``
                    bus ``ID:MODEL`` or ``ID:MODEL:PROTOCOL``
                    entries (``1:AX-12A,2:XM430-W350,3:MX-28:1``)
``model``           e-Manual model name of every servo (AX-12A,     ``XM430-W350``
                    AX-18A speak Protocol 1.0)
``protocol``        1: MX-28/64/106 get their 1.0 firmware's        each model's own
                    table, X-series servos Protocol Type 1; 2: 2.0  (AX 1, others 2)
``baud``            line speed of every servo, bit/s                ``1000000``
``return_delay_us`` Return Delay Time, µs (even, 0..508)            500 (e-Manual)
``noise``           encoder noise standard deviation, ticks         0
``seed``            seed of the encoder noise                       0
``wire_time``       model the time bytes take on the wire (on/off)  on
``usb_latency_ms``  the USB adapter's latency timer, ms: replies    1 (0 with
                    reach the host at its ticks (0: at once)        ``wire_time=off``)
``boot``            servos power on booting: silent for their boot  off
                    time (0.4 s; off: already booted)
``unplug_after``    the bus cable pulled once the bus has heard     never
                    this many instruction packets: no servo answers
                    or hears from the next one on (fault injection
                    in a run the host cannot reach into, e.g.
                    ``process=on``: a loop reading once a cycle
                    loses the bus about this many cycles in)
``unplug_for``      ... and plugged back after this many seconds    for good
                    of simulated time
``process``         serve the bus from a process of its own         off
                    (``on``: as hardware is, outside the host
                    process; :mod:`rig.devices._sim_backends`)
``clock``,          simulated time (:mod:`rig.sim.urls`)            real time
``time_scale``
==================  ==============================================  =====================

``sim://dxl`` is accepted as a short form.
"""

from __future__ import annotations

from rig.errors import RigConfigError
from rig.sim.dynamixel.bus import DynamixelBus, start_servo_bus
from rig.sim.urls import SimUrl

__all__ = ["DEVICES", "EXAMPLE", "KEYS", "bus_from_query", "bus_from_url"]

DEVICES = ("dynamixel", "dxl")
EXAMPLE = "sim://dynamixel?ids=1,2,3&model=XM430-W350"
KEYS = ("ids", "model", "protocol", "baud", "return_delay_us", "noise", "seed", "wire_time",
        "usb_latency_ms", "boot", "unplug_after", "unplug_for")
"""The bus's own keys (:data:`rig.sim.urls.TIME_KEYS` too)."""


def bus_from_url(url: str, *, also_known: tuple[str, ...] = (),
                 **overrides: object) -> DynamixelBus:
    """Start a simulated servo bus described by a port string (every key optional).

    Parameters
    ----------
    url : str
        ``sim://dynamixel`` URL (keys in the module docstring).
    also_known : tuple of str
        Further keys a caller handles itself (the back-driving patient keys of
        :mod:`rig.devices._sim_backends`): accepted and listed as known, ignored here.
    **overrides
        Keyword arguments of :func:`~rig.sim.dynamixel.bus.start_servo_bus` that win over the
        URL (e.g. ``clock``).

    Returns
    -------
    DynamixelBus
        Serving; close it (or use it as a context manager).

    Raises
    ------
    RigConfigError
        Not a ``sim://dynamixel`` URL, unknown key, bad value (the message names the key), or
        a configuration the bus refuses (unknown model, duplicate IDs, ...).
    """
    return bus_from_query(SimUrl(url, DEVICES, (*KEYS, *also_known), EXAMPLE), **overrides)


def bus_from_query(q: SimUrl, **overrides: object) -> DynamixelBus:
    """Start the simulated servo bus of a parsed ``sim://dynamixel`` URL (its bus keys, above;
    other keys the URL may carry are the caller's). ``overrides`` as :func:`bus_from_url`."""
    protocol = q.choice("protocol", "", ("", "1", "2", "1.0", "2.0"))
    kwargs: dict[str, object] = {
        "ids": _ids(q),
        "model": q.text("model", "XM430-W350"),
        "protocol": float(protocol) if protocol else None,
        "baud_rate": q.integer("baud", 1_000_000, 1),
        "return_delay_us": q.integer("return_delay_us", None, 0, 508),
        "noise_ticks": q.number("noise", 0.0, 0.0),
        "seed": q.integer("seed", 0),
        "model_wire_time": q.flag("wire_time", True),
        "boot": q.flag("boot", False),
        "clock": q.clock(),
    }
    wire = kwargs["model_wire_time"]
    latency = q.number("usb_latency_ms", 1.0 if wire else 0.0, 0.0, 255.0)
    if latency and not wire:
        raise RigConfigError(f"{q.url}: usb_latency_ms={latency:g} needs wire_time=on (without "
                             f"wire time, replies reach the host at once)")
    kwargs["usb_latency_ms"] = latency
    unplug_after = q.integer("unplug_after", None, 0)
    unplug_for = q.number("unplug_for", None, 0.0, open_lo=True)
    if unplug_for is not None and unplug_after is None:
        raise RigConfigError(f"{q.url}: unplug_for needs unplug_after (when the cable is "
                             f"pulled)")
    kwargs.update(overrides)
    bus = start_servo_bus(**kwargs)  # type: ignore[arg-type]
    if unplug_after is not None:
        bus.schedule_unplug(unplug_after, unplug_for)
    return bus


def _ids(q: SimUrl) -> list:
    """``ids``: plain IDs (``1,2,3``, ``1-3``) or ``ID:MODEL[:PROTOCOL]`` entries."""
    raw = q.text("ids")
    if raw is None or ":" not in raw:
        return q.int_list("ids", [1])
    out: list = []
    for part in raw.split(","):
        pieces = part.strip().split(":")
        try:
            dxl_id = int(pieces[0])
            if len(pieces) == 1:
                out.append(dxl_id)
            elif len(pieces) == 2 and pieces[1]:
                out.append((dxl_id, pieces[1]))
            elif len(pieces) == 3 and pieces[1] and pieces[2] in ("1", "2", "1.0", "2.0"):
                out.append((dxl_id, pieces[1], float(pieces[2])))
            else:
                raise ValueError(part)
        except ValueError:
            raise RigConfigError(f"{q.url}: ids={raw!r}: entry {part.strip()!r} must be ID, "
                                 f"ID:MODEL or ID:MODEL:PROTOCOL (protocol 1 or 2)") from None
    return out
