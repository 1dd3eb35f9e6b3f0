"""Rig configuration files for tests: the shipped ``sim-imu`` rig, re-pointed or extended."""

from __future__ import annotations

from pathlib import Path

from rig.record.rigio import load_config

#: A manual-clock test's packet timeout where every read is to succeed, ms (the SDK's timeout is
#: wall-clock: generous, so a stalled, loaded host — a CI run with both cores busy — never turns
#: such a read into a timeout, and the run into another one).
LOADED_HOST_MS = 1000.0


def sim_imu_yaml(tmp_path: Path, *, port: str | None = None, port_suffix: str = "",
                 extra: str = "", name: str = "test-imu") -> Path:
    """Write ``tmp_path/rig.yaml``: the shipped ``sim-imu`` rig named ``name``, its port
    replaced by ``port`` (default: the shipped one) plus ``port_suffix`` (e.g.
    ``"&time_scale=4"``), and ``extra`` YAML lines appended."""
    cfg = load_config("sim-imu")
    port = (port if port is not None else cfg.sensors.port) + port_suffix
    p = tmp_path / "rig.yaml"
    p.write_text(f"""
name: {name}
joint: {{name: shoulder, side: right, parent: thorax, child: humerus}}
sensors:
  port: "{port}"
  protocol: stream
  rate_hz: {cfg.sensors.rate_hz}
  segments: {{thorax: 0, humerus: 1}}
{extra}""")
    return p


def reap(proc) -> None:
    """Kill ``proc`` (a :class:`subprocess.Popen` with piped stdout/stderr) if it still runs,
    wait for it and close its pipes: the ``finally`` of every subprocess test."""
    if proc.poll() is None:
        proc.kill()
    proc.wait()
    proc.stdout.close()
    proc.stderr.close()
