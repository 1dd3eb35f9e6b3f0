"""Exceptions raised by :mod:`firmware_protocol`.

Hierarchy::

    ProtocolError (ValueError)
     +-- FramingError            no complete, well-formed frame (bad header, length, stuffing)
     +-- ChecksumError           CRC mismatch; carries ``received`` and ``computed``
     +-- PacketError             well-framed but wrong content; carries ``actual``, ``expected``

Parsers raise only these types, whatever bytes they are fed. A Dynamixel status packet's alert
bit is *not* an exception (the instruction still ran): it is a flag on the decoded status.
"""

from __future__ import annotations


class ProtocolError(ValueError):
    """Base class of every error raised by :mod:`firmware_protocol`."""


class FramingError(ProtocolError):
    """The bytes do not form a complete, well-formed frame."""


class ChecksumError(ProtocolError):
    """The frame's checksum does not match its content."""

    def __init__(self, received: int, computed: int, what: str = "CRC"):
        self.received = received
        self.computed = computed
        super().__init__(f"{what} mismatch: received 0x{received:04X}, computed 0x{computed:04X}")


class PacketError(ProtocolError):
    """A well-framed packet whose content is not what was expected."""

    def __init__(self, message: str, actual=None, expected=None):
        self.actual = actual
        self.expected = expected
        if actual is not None or expected is not None:
            message = f"{message} (got {actual!r}, expected {expected!r})"
        super().__init__(message)
