"""Exception types shared by every fdikit module.

Every error says *what* is wrong and *where* (which channel, which sample, which condition,
with the numbers behind it), so that a user can fix the input or the design.
"""

from __future__ import annotations


class FdikitError(Exception):
    """Base class of all fdikit errors."""


class DataError(FdikitError, ValueError):
    """Bad data: NaN or inf, wrong shape, unknown channel, non-monotonic time, ...."""


class ModelError(FdikitError, ValueError):
    """Inconsistent model: wrong matrix dimensions, unknown name, duplicated name, ...."""


class ConditionError(FdikitError):
    """A design whose existence conditions fail (rank, zeros, observability, LMI feasibility).

    Attributes
    ----------
    condition : str
        Short name of the condition that failed (e.g. ``"B1"``, ``"detectability"``).
    details : dict
        The numbers behind the verdict (ranks, zeros, margins).
    """

    def __init__(self, condition: str, message: str, details: dict | None = None):
        self.condition = condition
        self.details = dict(details or {})
        super().__init__(f"condition {condition} fails: {message}")
