"""The CLI entry point itself (rig.cli.main)."""

from __future__ import annotations

import pytest


def test_a_command_exit_code_is_the_process_exit_status(monkeypatch):
    # click in non-standalone mode returns an Exit's code instead of raising: rig.cli.main must
    # still make it the process status (a safe-state exit of 1 must not become 0)
    import sys
    import types

    import click

    from rig import cli

    @click.command()
    def stop():
        raise click.exceptions.Exit(3)

    mod = types.ModuleType("rig_test_exit_command")
    mod.stop = stop
    monkeypatch.setitem(sys.modules, "rig_test_exit_command", mod)
    monkeypatch.setitem(cli._COMMANDS, "stop", ("rig_test_exit_command", "stop", "test only"))
    with pytest.raises(SystemExit) as exc:
        cli.main(["stop"])
    assert exc.value.code == 3
