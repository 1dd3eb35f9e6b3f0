"""Every golden case, by name: :data:`CASES` (filled by importing the ``cases_*`` modules).

Each case is a function ``case_<name>() -> dict`` in a ``cases_*.py`` module, registered with
``@case("joint")`` or ``@case("limb")`` (:func:`tests.golden.harness.case`). A renamed API is
followed by editing the case code, never the stored data (``tests/golden/data``).
"""

from __future__ import annotations

from tests.golden import (  # noqa: F401  (they register their cases)
    cases_cli,
    cases_clinical,
    cases_demo,
    cases_loop,
    cases_models,
    cases_services,
    cases_sim,
    cases_store,
    cases_train,
)
from tests.golden.harness import REGISTRY

#: name -> :class:`tests.golden.harness.Case`
CASES = REGISTRY
