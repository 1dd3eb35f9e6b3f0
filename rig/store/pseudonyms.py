"""The pseudonym policy: the store keeps pseudonyms only, and a command warns when the one it
is given looks like it identifies a person (a birth date, a name, an e-mail address, a phone
number). The store itself keeps whatever it is given; the warning is the command line's.
"""

from __future__ import annotations

import re

#: a date in any of the usual spellings (``1961-04-12``, ``12.4.61``, ``19610412``)
DATE = re.compile(r"(?<!\d)(\d{4}[-./]\d{1,2}[-./]\d{1,2}|\d{1,2}[-./]\d{1,2}[-./]\d{2,4}"
                  r"|(19|20)\d{2}(0[1-9]|1[0-2])(0[1-9]|[12]\d|3[01]))(?!\d)")


def pseudonym_concerns(pseudonym: str) -> list[str]:
    """What in a pseudonym looks like it identifies a person (empty when nothing does): a date
    (a birth date), two or more capitalised words (a name), an e-mail address or a phone
    number. Used to warn at the command line; the store keeps whatever it is given."""
    out = []
    if DATE.search(pseudonym):
        out.append("a date (a birth date identifies a person)")
    words = [w for w in re.split(r"[\s,;_]+", pseudonym) if w]
    if sum(name_like(w) for w in words) >= 2:
        out.append("a person's name")
    if re.search(r"[^@\s]+@[^@\s]+\.[a-z]{2,}", pseudonym, re.I):
        out.append("an e-mail address")
    if re.search(r"(\+|00)\d[\d ./-]{7,}", pseudonym) or re.search(r"\d{3}[ .-]\d{3,4}[ .-]\d{3,4}",
                                                                 pseudonym):
        out.append("a phone number")
    return out


def pseudonym_warning(pseudonym: str | None) -> str | None:
    """The warning a command prints for a pseudonym that looks like it identifies the person
    (:func:`pseudonym_concerns`), or None."""
    concerns = pseudonym_concerns(pseudonym) if pseudonym else []
    if not concerns:
        return None
    return (f"--patient {pseudonym!r} looks like it holds {' and '.join(concerns)}: the store "
            "is meant for pseudonyms only (e.g. P-0042); keep the link to the person outside it")


def name_like(word: str) -> bool:
    """Whether ``word`` looks like part of a person's name: a capitalised word of letters
    (hyphenated parts too: Anna-Lena, O'Brien)."""
    parts = re.split(r"[-'’]", word)
    return len(word) >= 2 and parts[0] != "" and all(
        p.isalpha() and p[:1].isupper() and (len(p) == 1 or p[1:].islower())
        for p in parts if p)
