"""A click group whose sub-commands are imported only when used (python-can's lazy backend
table habit): ``rig --help`` stays fast, and a broken optional piece cannot stop the others."""

from __future__ import annotations

import importlib

import click

#: name -> (module, attribute, one-line help)
CommandTable = dict[str, tuple[str, str, str]]


def lazy_group_class(table: CommandTable, section: str = "Commands") -> type[click.Group]:
    """A :class:`click.Group` subclass serving the commands listed in ``table``."""

    class LazyGroup(click.Group):
        def list_commands(self, ctx):
            return sorted(table)

        def get_command(self, ctx, name):
            if name not in table:
                return None
            module, attr, _ = table[name]
            return getattr(importlib.import_module(module), attr)

        def format_commands(self, ctx, formatter):
            with formatter.section(section):
                formatter.write_dl([(n, table[n][2]) for n in self.list_commands(ctx)])

    return LazyGroup
