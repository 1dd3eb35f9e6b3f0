"""``rig serve --db DB [--host 127.0.0.1] [--port 8765]``: the clinic's local web application
(click options over :func:`rig.web.server.run_server`); ``rig serve --db DB --add-user NAME``
adds a user who may log in (the password is prompted, never an option).
"""

from __future__ import annotations

import click

from rig.web.settings import DEFAULT_HOST, DEFAULT_PORT


@click.command()
@click.option("--db", required=True, help="Store: a file path, sqlite:///PATH or "
              "postgresql://USER@HOST/DB (a new SQLite file is created).")
@click.option("--host", default=DEFAULT_HOST, show_default=True,
              help="Address to listen on. Any but the loopback needs a user (--add-user) and "
              "makes every page ask for a login.")
@click.option("--port", default=DEFAULT_PORT, show_default=True, type=int,
              help="TCP port (0: a free one, printed).")
@click.option("--users", "users", default=None, metavar="FILE",
              help="Users file (default: beside a SQLite store, DB.users.json; required "
              "for a PostgreSQL store with users).")
@click.option("--login", is_flag=True, help="Ask for a login on the loopback too.")
@click.option("--add-user", "add_user", default=None, metavar="NAME",
              help="Add a user (or change its password) and exit; the password is prompted.")
@click.option("--no-access-log", is_flag=True, help="Do not log each request.")
@click.option("--cache", default=None, metavar="DIR", help="Folder for the rendered reports "
              "and exports (default: a private temporary folder, removed at the end).")
@click.option("--files", default=None, metavar="DIR", help="Folder for the boundaries and "
              "models made in the browser (default: beside a SQLite store, DB.files/).")
@click.option("--rig", "rigs", multiple=True, metavar="FILE", help="A rig configuration to "
              "offer for recording besides the shipped ones (the clinic's hardware); "
              "repeatable; each checked at start.")
def serve(db, host, port, users, login, add_user, no_access_log, cache, files, rigs) -> None:
    """Serve the clinic's web app: patients, sessions, reports, progress."""
    from rig.errors import RigConfigError
    from rig.web.security import UserFile
    from rig.web.server import ServeRequest, default_users_path, run_server

    if add_user is not None:
        path = users or default_users_path(db)
        if path is None:
            raise RigConfigError("--users FILE: a PostgreSQL store keeps no users file "
                                 "beside it; name one")
        password = click.prompt(f"password for {add_user}", hide_input=True,
                                confirmation_prompt=True, err=True)
        UserFile(path).add(add_user, password)
        click.echo(f"user {add_user} saved in {path}")
        return
    run_server(ServeRequest(db, host, port, users, login, access_log=not no_access_log,
                            cache=cache, files=files, rigs=rigs),
               on_ready=click.echo)
