"""Exceptions raised for bad user input.

Every error a user can fix is a :class:`ZendarError`; the command-line tools
print its message without a traceback and exit with status 2.
"""

from __future__ import annotations


class ZendarError(ValueError):
    """Base class for problems in user-supplied files or arguments.

    Parameters
    ----------
    message : str
        One line naming what is wrong and where.
    problems : list of str, optional
        Every problem found when several were collected at once (default: ``[message]``), so that a
        user who fixes a file sees them all.
    """

    def __init__(self, message: str, problems: list[str] | None = None) -> None:
        super().__init__(message)
        self.problems: list[str] = list(problems) if problems else [message]


class ZendarFormatError(ZendarError):
    """A dataset violates format v1.

    The message names the scene, the path inside it and what was expected.
    ``problems`` holds every violation found when several were collected at once.
    """


class PredictionsError(ZendarError):
    """A predictions or ground-truth file for the evaluator is invalid.

    ``problems`` lists every violation, each naming its frame and detection index.
    """
