"""The rig application: drivers, simulated backends, the live control loop and the CLI.

``rig`` is the only package that depends on all the others (``firmware_protocol``,
``calibration``, ``models``). The CLI in :mod:`rig.cli` is a thin layer over functions that the
tests call directly.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("jointlimits-rig")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
