"""The rules of every name and text the leaderboard shows: team names and the submitted meta.

A shown string must look like what it is. Refused: control characters (escape codes, newlines
except in multi-line text), format characters (Unicode category Cf: zero-width spaces and joiners,
the bidirectional overrides and isolates U+202A–U+202E and U+2066–U+2069 that reverse the text
around them), line and paragraph separators, surrogates, private-use characters (drawn as anything
a font likes), and more than :data:`MAX_MARKS_PER_BASE` combining marks on one character (dozens
of stacked marks draw over the rows above and below). Names are normalised: NFKC (full-width and
compatibility forms become their plain letters), whitespace runs become one space, none at either
end. Two team names collide when their :func:`skeleton` is equal: case, accents, whitespace
variants and the common Cyrillic and Greek look-alikes of Latin letters do not tell teams apart.
"""

from __future__ import annotations

import unicodedata
from collections.abc import Iterable

from zendar_dataset.errors import ZendarError

#: Combining marks allowed on one base character (decomposed Vietnamese needs two, scripts that
#: stack vowel signs and tone marks up to three).
MAX_MARKS_PER_BASE = 3

MAX_TEAM_NAME_CHARS = 100

# Unicode categories refused anywhere, with the words a problem uses for them.
_REFUSED_CATEGORIES = {
    "Cc": "control characters",
    "Cf": "invisible formatting characters",
    "Zl": "line separators",
    "Zp": "paragraph separators",
    "Cs": "surrogate code points",
    "Co": "private-use characters",
}

# Multi-line text (a description) keeps its line breaks and tabs.
_MULTILINE_ALLOWED = frozenset("\n\t")

# Latin look-alikes in Cyrillic and Greek (upper and lower case), and dashes that look like "-".
# Deliberately small: the letters a font draws the same, not every similar shape.
_LOOKALIKES = str.maketrans({
    **dict.fromkeys("АаΑα", "a"), **dict.fromkeys("ВΒ", "b"), **dict.fromkeys("СсϹϲ", "c"),
    **dict.fromkeys("ЕеЁёΕ", "e"), **dict.fromkeys("НҺһΗ", "h"), **dict.fromkeys("ІіӀΙι", "i"),
    **dict.fromkeys("Јјϳ", "j"), **dict.fromkeys("КкΚκ", "k"), **dict.fromkeys("ӏ", "l"),
    **dict.fromkeys("МΜ", "m"), **dict.fromkeys("Ν", "n"), **dict.fromkeys("ОоΟο", "o"),
    **dict.fromkeys("РрΡρ", "p"), **dict.fromkeys("Ԛԛ", "q"), **dict.fromkeys("Ѕѕ", "s"),
    **dict.fromkeys("ТΤ", "t"), **dict.fromkeys("υ", "u"), **dict.fromkeys("Ѵѵν", "v"),
    **dict.fromkeys("Ԝԝω", "w"), **dict.fromkeys("ХхΧχ", "x"), **dict.fromkeys("УуҮΥ", "y"),
    **dict.fromkeys("Ζ", "z"),
    **dict.fromkeys("\u2010\u2011\u2012\u2013\u2014\u2015\u2212\ufe58\ufe63\uff0d", "-"),
})


class NameRefused(ZendarError):
    """A name or text breaks the rules of this module (a user error)."""


def _code_point(char: str) -> str:
    return f"U+{ord(char):04X}"


def character_problem(text: str, *, multiline: bool = False) -> str | None:
    """What is wrong with the characters of ``text``, or None when it may be shown.

    Parameters
    ----------
    text
        The text as given (before :func:`normalised`).
    multiline
        Allow line breaks and tabs (a description).

    Returns
    -------
    str or None
        A phrase that follows the field's name, e.g. ``"contains invisible formatting characters
        (U+202E)"``; it names code points, never quotes the text.
    """
    for position, char in enumerate(text):
        category = unicodedata.category(char)
        if category in _REFUSED_CATEGORIES and not (multiline and char in _MULTILINE_ALLOWED):
            return f"contains {_REFUSED_CATEGORIES[category]} ({_code_point(char)} at character {position + 1})"
    if text and unicodedata.category(text[0]).startswith("M"):
        # It would be drawn on whatever the page shows before the text.
        return f"starts with a combining mark ({_code_point(text[0])})"
    longest_run = marks_in_run = 0
    for char in text:
        marks_in_run = marks_in_run + 1 if unicodedata.category(char).startswith("M") else 0
        longest_run = max(longest_run, marks_in_run)
    if longest_run > MAX_MARKS_PER_BASE:
        return f"has {longest_run} combining marks on one character (at most {MAX_MARKS_PER_BASE})"
    return None


def normalised(text: str) -> str:
    """``text`` as a name is stored and shown: NFKC, whitespace runs as one space, stripped.

    Examples
    --------
    >>> normalised("  Radar\\u00a0 Lab ")
    'Radar Lab'
    >>> normalised("\\uff32adar")  # a full-width R
    'Radar'
    """
    return " ".join(unicodedata.normalize("NFKC", text).split())


def skeleton(name: str) -> str:
    """What a name looks like, for telling whether two names would be mistaken for each other.

    Casefolded, accents removed (NFKD without combining marks), Cyrillic and Greek look-alikes
    mapped to their Latin letters, whitespace collapsed.

    Examples
    --------
    >>> skeleton("Radar Lab") == skeleton("R\\u0410dar lab") == skeleton("Rádar  LAB")
    True
    """
    decomposed = unicodedata.normalize("NFKD", name)
    bare = "".join(char for char in decomposed if not unicodedata.category(char).startswith("M"))
    # Mapped before and after casefolding: upper-case look-alikes fold to lower-case ones that may
    # not be in the table themselves (and the other way round).
    folded = bare.translate(_LOOKALIKES).casefold().translate(_LOOKALIKES)
    return " ".join(folded.split())


def team_name(name: str, existing: Iterable[str]) -> str:
    """The normalised name of a new team, checked against the rules and the existing teams.

    Parameters
    ----------
    name
        The name the administrator typed.
    existing
        The names of the teams already registered.

    Raises
    ------
    NameRefused
        When the name has refused characters, is empty or too long once normalised, or looks like
        an existing team's name (the message names that team).
    """
    problem = character_problem(name)
    if problem is not None:
        raise NameRefused(f"team name {problem}")
    clean = normalised(name)
    if not 1 <= len(clean) <= MAX_TEAM_NAME_CHARS:
        raise NameRefused(f"team name must be 1 to {MAX_TEAM_NAME_CHARS} characters, got {len(clean)}")
    looks = skeleton(clean)
    for other in existing:
        if other == clean:
            raise NameRefused(f"a team named {clean!r} already exists")
        if skeleton(other) == looks:
            raise NameRefused(f"team name {clean!r} looks the same as the existing team {other!r}")
    return clean
