"""The one error type users see.

Every reader raises :class:`InputError` with the file and the problem; the CLI turns it
into one line on stderr and exit code 2 (:data:`EXIT_BAD_INPUT`). No traceback reaches a user.
"""

from __future__ import annotations

EXIT_BAD_INPUT = 2
"""Exit status for bad input (file unreadable, malformed, inconsistent)."""

EXIT_INVERTED = 3
"""Exit status when a placed mesh has inverted (folded) quads."""

EXIT_UNMATCHABLE = 4
"""Exit status when no catalogue mesh can be matched to the shape."""


class InputError(Exception):
    """Bad user input. ``str(err)`` is one line: ``"<where>: <problem>"``.

    where: a file path, optionally with a location (``"shape.json"``, ``"fine.toml:12"``).
    """

    def __init__(self, problem: str, where: str | None = None):
        self.problem = " ".join(str(problem).split())  # always one line
        self.where = None if where is None else " ".join(str(where).split())
        super().__init__(self.problem if self.where is None else f"{self.where}: {self.problem}")


class UnmatchableError(Exception):
    """No mesh of the requested catalogue part has a finite matching with the shape."""


class InputWarning(UserWarning):
    """Input that is read, with something ignored (e.g. unknown JSON keys). ``str(w)`` is one
    line, ``"<where>: <what>"``; the CLI prints it on stderr as ``warning: ...``."""

    def __init__(self, problem: str, where: str | None = None):
        self.problem = " ".join(str(problem).split())
        self.where = None if where is None else " ".join(str(where).split())
        super().__init__(self.problem if self.where is None else f"{self.where}: {self.problem}")


class SolverError(Exception):
    """The integer-program solver (HiGHS through :func:`scipy.optimize.milp`) failed for a
    reason other than infeasibility (``status``: scipy's code, e.g. 4 "other"; 3 unbounded).
    Not a verdict on the request: the caller retries another way or falls back to another
    candidate; an infeasible request raises :class:`InputError` instead."""

    def __init__(self, message: str, status: int):
        self.status = int(status)
        super().__init__(" ".join(str(message).split()))
