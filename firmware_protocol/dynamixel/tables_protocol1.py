"""Control tables of Protocol 1.0 servos (AX-12A, AX-18A, MX-28 on 1.0 firmware, ...).

The SDK ships no ``.model`` file for them: typed from the e-Manual (to be filled, issue 40).
"""

from __future__ import annotations

from firmware_protocol.dynamixel.control_table import ControlTable


def load(model: str | int) -> ControlTable | None:
    """The Protocol 1.0 table of ``model`` (name or model number), or None when ``model`` has
    no table of its own for Protocol 1.0 (an X-series servo switched to 1.0 keeps its table)."""
    return None
