"""What every repository of the store shares: the transaction it runs in, rows as dicts, JSON
columns, and the checks on the values it is given.

A repository (:class:`Repository`) is given the database (anything with ``url`` and
``transaction(write)``, i.e. a :class:`~rig.store.store.Store`) and writes its tables' SQL
once: ``_insert`` (a row, its id back), ``_get`` (one row by id, or the one-line "no ... in"
error), ``_list`` (rows of a query); the JSON columns it names in ``json_columns`` come back
decoded.
"""

from __future__ import annotations

import contextlib
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from sqlalchemy import Table, select
from sqlalchemy.engine import Connection

from rig.errors import RigConfigError
from rig.store import schema as S

SIDES = ("left", "right")


class Database(Protocol):
    """What a repository needs of the store: its name for messages and a transaction."""

    url: str

    def transaction(self, write: bool = True) -> contextlib.AbstractContextManager[Connection]:
        """One transaction (``write=False``: a read-only one)."""
        ...


class Repository:
    """Base of the store's repositories: one concern's tables, on a :class:`Database`.

    Parameters
    ----------
    db : Database
        The store whose transactions the repository uses.
    """

    #: the table whose rows ``_get`` returns, and the name it has in messages
    table: Table
    what: str = "row"
    #: JSON text columns decoded on the way out
    json_columns: tuple[str, ...] = ()

    def __init__(self, db: Database) -> None:
        self.db = db

    def _row(self, row: Mapping[str, Any]) -> dict:
        """A database row as a dict, its JSON columns decoded."""
        out = dict(row)
        for c in self.json_columns:
            out[c] = loads(out[c])
        return out

    def _insert(self, **values: Any) -> int:
        """Insert one row into :attr:`table` in its own transaction; its id."""
        with self.db.transaction() as conn:
            res = conn.execute(self.table.insert().values(**values))
            return int(res.inserted_primary_key[0])

    def _get(self, row_id: int) -> dict:
        """The row ``row_id`` of :attr:`table`, or a one-line error naming it."""
        with self.db.transaction(write=False) as conn:
            row = conn.execute(
                select(self.table).where(self.table.c.id == int(row_id))
            ).mappings().first()
        if row is None:
            raise RigConfigError(f"no {self.what} {row_id} in {self.db.url}")
        return self._row(row)

    def _list(self, query) -> list[dict]:
        """The rows of ``query`` (a SELECT of :attr:`table`) as dicts."""
        with self.db.transaction(write=False) as conn:
            rows = conn.execute(query).mappings().all()
        return [self._row(r) for r in rows]

    def _require(self, table: Table, row_id: int, what: str) -> None:
        """Refuse, in one line, a row ``row_id`` that is not in ``table``."""
        with self.db.transaction(write=False) as conn:
            found = conn.execute(select(table.c.id).where(table.c.id == int(row_id))).first()
        if found is None:
            raise RigConfigError(f"no {what} {row_id} in {self.db.url}")

    def _require_session(self, session_id: int) -> None:
        """Refuse, in one line, a session that is not in the store (the parent of every row
        but patients)."""
        self._require(S.sessions, session_id, "session")

    def _of_session(self, session_id: int, *order) -> list[dict]:
        """The rows of :attr:`table` belonging to session ``session_id``, ordered by
        ``order`` (default: id)."""
        c = self.table.c
        return self._list(select(self.table).where(c.session_id == int(session_id))
                          .order_by(*(order or (c.id,))))


def dumps(obj: Any) -> str:
    """JSON text of ``obj``; numpy scalars/arrays become numbers/lists; NaN is refused."""

    def default(o: Any) -> Any:
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, Path):
            return str(o)
        raise TypeError(f"{type(o).__name__} is not JSON serialisable")

    try:
        return json.dumps({} if obj is None else obj, default=default, allow_nan=False,
                          sort_keys=True)
    except ValueError as err:
        raise RigConfigError(
            f"cannot store {obj!r:.80}: numbers must be finite (JSON has no NaN/inf)"
        ) from err
    except TypeError as err:
        raise RigConfigError(f"cannot store {obj!r:.80}: {err}") from err


def loads(s: str | None) -> Any:
    """The value of a JSON column (None for SQL NULL)."""
    return None if s is None else json.loads(s)


def check_text(what: str, value: Any, max_len: int) -> str:
    """``value`` if it is a non-empty string of at most ``max_len`` characters."""
    if not isinstance(value, str) or not value.strip():
        raise RigConfigError(f"{what} must be a non-empty string, got {value!r}")
    if len(value) > max_len:
        raise RigConfigError(f"{what} {value[:20]!r}... is longer than {max_len} characters")
    return value


def check_choice(what: str, value: Any, choices: tuple[str, ...]) -> Any:
    """``value`` if it is one of ``choices`` (a ``side`` may also be None)."""
    if value is None and what == "side":
        return None
    if value not in choices:
        raise RigConfigError(f"{what} must be one of {', '.join(choices)}; got {value!r}")
    return value


def finite(what: str, value: Any) -> float:
    """``value`` as a finite float."""
    try:
        v = float(value)
    except (TypeError, ValueError) as err:
        raise RigConfigError(f"{what} must be a number, got {value!r}") from err
    if not math.isfinite(v):
        raise RigConfigError(f"{what} must be finite, got {value!r}")
    return v
