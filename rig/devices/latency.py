"""USB-serial latency timer: the most common cause of slow Dynamixel loops.

FTDI-based adapters (the U2D2 among them) hold received bytes for up to the *latency timer*
(default 16 ms) before passing a short packet to the host, so each status packet can arrive up
to 16 ms late: a read → write loop then runs at ~30-60 Hz instead of ~1 kHz. Linux exposes the
timer as ``/sys/bus/usb-serial/devices/<ttyUSBn>/latency_timer`` (ms); 1 ms is the fix.

``dynamixel_sdk`` has its own constant, ``dynamixel_sdk.port_handler.LATENCY_TIMER`` (16 ms):
it does **not** change the adapter; it only sets the SDK's packet timeout,
``tx_time × bytes + 2 × LATENCY_TIMER + 2 ms``. :class:`rig.devices.dynamixel.DynamixelBus`
uses that formula with the adapter's detected timer instead (at least 1 ms), so a lost packet
costs ~4 ms at a 1 ms timer, not 34 ms.
"""

from __future__ import annotations

import glob
import os
from pathlib import Path

from dynamixel_sdk import port_handler

__all__ = ["SDK_LATENCY_MS", "latency_advice", "usb_latency_timer_ms", "usb_latency_timers"]

SYSFS = "/sys/bus/usb-serial/devices"


def _sdk_latency() -> int:
    try:
        return int(port_handler.LATENCY_TIMER)
    except (AttributeError, ValueError):  # pragma: no cover
        return 16


SDK_LATENCY_MS = _sdk_latency()
"""``dynamixel_sdk.port_handler.LATENCY_TIMER`` (ms): the SDK's timeout constant."""


def usb_latency_timer_ms(port_path: str, sysfs: str = SYSFS) -> int | None:
    """Latency timer (ms) of the USB-serial adapter behind ``port_path``; None if it has none
    (not Linux, not a usb-serial device such as a pty or ttyACM, or unreadable)."""
    try:
        name = os.path.basename(os.path.realpath(port_path))
        text = (Path(sysfs) / name / "latency_timer").read_text().strip()
        return int(text)
    except (OSError, ValueError):
        return None


def usb_latency_timers(sysfs: str = SYSFS) -> dict[str, int]:
    """Every usb-serial device's latency timer, ``{"ttyUSB0": 16, ...}``."""
    out = {}
    for path in sorted(glob.glob(os.path.join(sysfs, "*", "latency_timer"))):
        try:
            out[Path(path).parent.name] = int(Path(path).read_text().strip())
        except (OSError, ValueError):
            continue
    return out


def latency_advice(port_path: str, sysfs: str = SYSFS) -> str | None:
    """One line of advice if the adapter's latency timer is above 1 ms, else None."""
    timer = usb_latency_timer_ms(port_path, sysfs)
    if timer is None or timer <= 1:
        return None
    name = os.path.basename(os.path.realpath(port_path))
    return (f"{port_path}: USB latency timer is {timer} ms (replies wait up to {timer} ms; "
            f"loops crawl): `echo 1 | sudo tee {sysfs}/{name}/latency_timer`, or permanently a "
            f"udev rule ATTR{{latency_timer}}=\"1\" (docs/devices.md); dynamixel_sdk's "
            f"LATENCY_TIMER={SDK_LATENCY_MS} only sets its timeout, not the adapter")
