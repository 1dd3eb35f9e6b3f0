"""Exceptions raised by :mod:`rig`.

Hierarchy::

    RigError
     +-- RigConfigError (ValueError)        a configuration file or option is invalid
     +-- RigConnectionError (OSError)       a port is missing, busy or went away
     +-- RigTimeoutError (TimeoutError)     a device did not answer in time
     +-- SafetyError                        the supervisor refused or stopped motion

The CLI turns any of these (and the packages' own user-facing errors) into one line on stderr
and a non-zero exit status.
"""

from __future__ import annotations


class RigError(Exception):
    """Base class of every error raised by :mod:`rig`."""


class RigConfigError(RigError, ValueError):
    """A configuration file or command-line option is invalid."""


class RigConnectionError(RigError, OSError):
    """A port is missing, busy or disconnected."""


class RigTimeoutError(RigError, TimeoutError):
    """A device did not answer before the deadline."""


class SafetyError(RigError):
    """The safety supervisor refused a command or stopped motion."""
