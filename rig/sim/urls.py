"""``sim://`` port strings: the simulators they name, and the one parser of their query.

``sim://<device>?key=value&key=value`` — the device (URL host) chooses the simulator
(:data:`SIM_DEVICES`, the one table of them), the query its settings. Every key is checked: an
unknown key, a key given twice or a bad value raises :class:`~rig.errors.RigConfigError`
naming the key and what it accepts (:class:`SimUrl`, used by every simulator and by the port
backends of :mod:`rig.devices`). :func:`with_keys` edits a port string's query (the demo
re-points shipped rig configurations with it).

Keys every simulator accepts (time):

``clock``
    ``real`` (default: ``time.monotonic``) or ``manual`` (a
    :class:`~rig.sim.clock.ManualClock` starting at 0, reachable as ``simulator.clock``; time
    then moves only when the caller advances it).
``time_scale``
    Simulated seconds per real second (a :class:`~rig.sim.clock.ScaledClock`); excludes
    ``clock=manual``.
"""

from __future__ import annotations

import importlib
import math
import time
import urllib.parse
from collections.abc import Iterable
from dataclasses import dataclass

from rig.errors import RigConfigError
from rig.sim.clock import Clock, ManualClock, ScaledClock

__all__ = ["SIM_DEVICES", "TIME_KEYS", "SimDevice", "SimUrl", "query_keys", "sim_device",
           "sim_device_of", "with_keys", "without_keys"]

TIME_KEYS = frozenset({"clock", "time_scale"})

_TRUE = {"1", "on", "true", "yes"}
_FALSE = {"0", "off", "false", "no"}


@dataclass(frozen=True)
class SimDevice:
    """A simulator a ``sim://`` port string can name.

    Attributes
    ----------
    name : str
        The URL host (``dynamixel``, ``bno055``, ``imu-stream``).
    aliases : tuple of str
        Other hosts naming it (``dxl``, ``stream``).
    entry : str
        ``module:function`` starting it from a URL (imported only when used).
    """

    name: str
    aliases: tuple[str, ...]
    entry: str

    @property
    def kind(self) -> str:
        """:attr:`rig.devices.ports.Port.kind` of its ports: ``sim-<name>``."""
        return f"sim-{self.name}"

    def start(self, url: str, **overrides: object):
        """Start the simulator ``url`` describes (``overrides`` win over the URL)."""
        module, func = self.entry.split(":")
        return getattr(importlib.import_module(module), func)(url, **overrides)


_DEVICES = (
    SimDevice("dynamixel", ("dxl",), "rig.sim.dynamixel:bus_from_url"),
    SimDevice("bno055", (), "rig.sim.imu:bno055_from_url"),
    SimDevice("imu-stream", ("stream",), "rig.sim.imu:stream_from_url"),
)
SIM_DEVICES: dict[str, SimDevice] = {host: d for d in _DEVICES for host in (d.name, *d.aliases)}
"""``sim://<host>`` -> the simulator it names (aliases included)."""


def sim_device_of(url: str) -> SimDevice:
    """The simulator a ``sim://`` URL names.

    Raises
    ------
    RigConfigError
        Not ``sim://`` one of :data:`SIM_DEVICES`.
    """
    parts = urllib.parse.urlsplit(url)
    device = SIM_DEVICES.get(parts.netloc) if parts.scheme == "sim" else None
    if device is None:
        raise RigConfigError(f"port {url!r} names no simulator: unknown simulated device "
                             f"{parts.netloc!r}; known: "
                             f"{', '.join(f'sim://{k}' for k in SIM_DEVICES)}")
    return device


def _pieces(query: str) -> list[str]:
    """The ``key=value`` pieces of a query, as written (empty ones dropped)."""
    return [p for p in query.split("&") if p]


def _decode(piece: str) -> tuple[str, str]:
    """Key and value of a query piece, percent- and ``+``-decoded (a key without ``=`` has the
    value ``""``) — as :func:`urllib.parse.parse_qsl` with ``keep_blank_values``."""
    key, _, value = piece.partition("=")
    return urllib.parse.unquote_plus(key), urllib.parse.unquote_plus(value)


def query_keys(url: str) -> frozenset[str]:
    """The keys ``url``'s query gives (not checked)."""
    return frozenset(_decode(p)[0] for p in _pieces(urllib.parse.urlsplit(url).query))


def with_keys(url: str, **keys: object) -> str:
    """``url`` with query keys replaced (in place) or added (at the end).

    Each value is ``str(value)`` percent-quoted with ``/`` kept (a file path stays readable);
    the rest of the URL, the other keys included, is kept as written.

    Examples
    --------
    >>> with_keys("sim://imu-stream?sensors=2&seed=1", seed=7, patient="/tmp/p q.yaml")
    'sim://imu-stream?sensors=2&seed=7&patient=/tmp/p%20q.yaml'
    """
    head, _, query = url.partition("?")
    pieces = _pieces(query)
    names = [p.partition("=")[0] for p in pieces]
    for key, value in keys.items():
        item = f"{key}={urllib.parse.quote(str(value), safe='/')}"
        if key in names:
            pieces[names.index(key)] = item
        else:
            pieces.append(item)
            names.append(key)
    return head + "?" + "&".join(pieces)


def without_keys(url: str, *keys: str) -> str:
    """``url`` without the query keys ``keys`` (the rest kept as written).

    Examples
    --------
    >>> without_keys("sim://dynamixel?ids=1,2&process=on&seed=3", "process")
    'sim://dynamixel?ids=1,2&seed=3'
    """
    head, _, query = url.partition("?")
    drop = set(keys)
    kept = [p for p in _pieces(query) if _decode(p)[0] not in drop]
    return head + ("?" + "&".join(kept) if kept else "")


def sim_device(url: str, devices: Iterable[str], example: str, what: str | None = None) -> str:
    """The device (URL host) of ``url``, a ``sim://`` URL naming one of ``devices``.

    Raises
    ------
    RigConfigError
        Anything else: ``'<url>' is not a simulated <what> URL (expected e.g. <example>)``;
        ``what`` defaults to the first device.
    """
    devices = tuple(devices)
    parts = urllib.parse.urlsplit(url)
    if parts.scheme != "sim" or parts.netloc not in devices or parts.path not in ("", "/"):
        raise RigConfigError(f"{url!r} is not a simulated {what or devices[0]} URL "
                             f"(expected e.g. {example})")
    return parts.netloc


class SimUrl:
    """A parsed ``sim://`` URL whose every key must be consumed by a typed getter.

    Parameters
    ----------
    url : str
    devices : iterable of str
        URL hosts this simulator answers to (``"dynamixel"``, ``"dxl"``).
    known : iterable of str
        The keys it accepts (:data:`TIME_KEYS` are added).
    example : str
        A valid URL, quoted in the error for a foreign URL.

    Raises
    ------
    RigConfigError
        Not ``sim://`` one of ``devices``, an unknown key or a key given twice.
    """

    def __init__(self, url: str, devices: Iterable[str], known: Iterable[str],
                 example: str) -> None:
        self.url = url
        self.device = sim_device(url, devices, example)
        pairs = [_decode(p) for p in _pieces(urllib.parse.urlsplit(url).query)]
        known_set = set(known) | TIME_KEYS
        self._values: dict[str, str] = {}
        for key, value in pairs:
            if key not in known_set:
                raise RigConfigError(f"{url}: unknown key {key!r}; known keys: "
                                     f"{', '.join(sorted(known_set))}")
            if key in self._values:
                raise RigConfigError(f"{url}: key {key!r} given twice")
            self._values[key] = value

    def __contains__(self, key: str) -> bool:
        return key in self._values

    def _bad(self, key: str, what: str) -> RigConfigError:
        return RigConfigError(f"{self.url}: {key}={self._values[key]!r}: {what}")

    def text(self, key: str, default: str | None = None) -> str | None:
        """The raw value of ``key`` (``default`` when absent)."""
        return self._values.get(key, default)

    def integer(self, key: str, default: int | None, lo: int | None = None,
                hi: int | None = None) -> int | None:
        """An integer in ``[lo, hi]``."""
        if key not in self._values:
            return default
        try:
            value = int(self._values[key])
        except ValueError:
            raise self._bad(key, "must be an integer") from None
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self._bad(key, f"must be {lo if lo is not None else '-inf'}.."
                                 f"{hi if hi is not None else 'inf'}")
        return value

    def number(self, key: str, default: float | None, lo: float | None = None,
               hi: float | None = None, *, none_ok: bool = False,
               open_lo: bool = False) -> float | None:
        """A finite number in ``[lo, hi]`` (``(lo, hi]`` with ``open_lo``); ``none`` gives None
        when ``none_ok``."""
        if key not in self._values:
            return default
        raw = self._values[key]
        if none_ok and raw.lower() == "none":
            return None
        try:
            value = float(raw)
        except ValueError:
            raise self._bad(key, "must be a number" + (" or 'none'" if none_ok else "")) \
                from None
        too_low = lo is not None and (value <= lo if open_lo else value < lo)
        if not math.isfinite(value) or too_low or (hi is not None and value > hi):
            rng = f"{'(' if open_lo else '['}{lo if lo is not None else '-inf'}, " \
                  f"{hi if hi is not None else 'inf'}]"
            raise self._bad(key, f"must be a finite number in {rng}")
        return value

    def flag(self, key: str, default: bool) -> bool:
        """``on/off``, ``true/false``, ``yes/no``, ``1/0``."""
        if key not in self._values:
            return default
        raw = self._values[key].lower()
        if raw in _TRUE:
            return True
        if raw in _FALSE:
            return False
        raise self._bad(key, "must be on or off")

    def choice(self, key: str, default: str, choices: Iterable[str]) -> str:
        """One of ``choices``."""
        choices = tuple(choices)
        value = self._values.get(key, default)
        if value not in choices:
            raise self._bad(key, f"must be one of {', '.join(choices)}")
        return value

    def int_list(self, key: str, default: list[int]) -> list[int]:
        """Comma-separated integers (``1,2,3``; ranges ``1-3`` allowed)."""
        if key not in self._values:
            return list(default)
        out: list[int] = []
        try:
            for part in self._values[key].split(","):
                part = part.strip()
                if "-" in part[1:]:
                    lo, hi = (int(p) for p in part.split("-", 1))
                    out.extend(range(lo, hi + 1))
                else:
                    out.append(int(part))
        except ValueError:
            raise self._bad(key, "must be a list of integers such as 1,2,3") from None
        if not out:
            raise self._bad(key, "must not be empty")
        return out

    def clock(self) -> Clock:
        """The simulator's clock from ``clock`` / ``time_scale``."""
        kind = self.choice("clock", "real", ("real", "manual"))
        scale = self.number("time_scale", None, 0.0, open_lo=True)
        if kind == "manual":
            if scale is not None:
                raise RigConfigError(f"{self.url}: time_scale and clock=manual exclude each "
                                     f"other")
            return ManualClock()
        if scale is not None and scale != 1.0:
            return ScaledClock(scale)
        return time.monotonic
