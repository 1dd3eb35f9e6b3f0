"""Patients: a pseudonym each, and nothing that names the person.

The store has no name, birth-date or contact fields; the mapping from pseudonym to person stays
with the clinic. What a pseudonym must not look like is :mod:`rig.store.pseudonyms`' to say.
"""

from __future__ import annotations

import time

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError

from rig.errors import RigConfigError
from rig.store import schema as S
from rig.store.rows import SIDES, Repository, check_choice, check_text


class PatientRepository(Repository):
    """The ``patients`` table: ``store.patients``."""

    table = S.patients
    what = "patient"

    def add(self, pseudonym: str, *, side: str | None = None,
            notes: str | None = None) -> int:
        """Register a patient under a pseudonym and return its id.

        Only a pseudonym is stored -- the store has no name, birth-date or contact fields, and
        the mapping from pseudonym to person stays with the clinic. ``notes`` must not identify
        the patient either.
        """
        pseudonym = check_text("pseudonym", pseudonym, 64)
        side = check_choice("side", side, SIDES)
        try:
            return self._insert(pseudonym=pseudonym, side=side, notes=notes,
                                created_at=time.time())
        except IntegrityError as err:
            raise RigConfigError(f"patient {pseudonym!r} already exists in {self.db.url}") from err

    def ensure(self, pseudonym: str, *, side: str | None = None) -> int:
        """The id of patient ``pseudonym``, registering it first if it is new."""
        found = self.find(pseudonym)
        if found is not None:
            return int(found["id"])
        try:
            return self.add(pseudonym, side=side)
        except RigConfigError:  # created concurrently
            found = self.find(pseudonym)
            if found is None:
                raise
            return int(found["id"])

    def find(self, pseudonym: str) -> dict | None:
        """The patient row with this pseudonym, or ``None``."""
        rows = self._list(select(S.patients).where(S.patients.c.pseudonym == pseudonym))
        return rows[0] if rows else None

    def get(self, patient_id: int) -> dict:
        """The patient row ``patient_id`` (``id``, ``pseudonym``, ``side``, ``notes``...)."""
        return self._get(patient_id)

    def list(self) -> list[dict]:
        """Every patient, by id."""
        return self._list(select(S.patients).order_by(S.patients.c.id))
