"""The one exception type for user mistakes, and the one warning about inputs.

Every check that a user can trip (bad shapes, NaN, unknown names, unreadable files,
an output folder that already holds a run) raises :class:`ParameterError`. The CLI turns it
into one line on stderr and exit code 2; library callers can catch it like a ``ValueError``.
An input the library adjusted without loss (a fully opaque alpha channel dropped) is reported by
the warning :class:`InputNote`, which the CLI prints as one line ``npmrf3d: note: ...``.
"""

from __future__ import annotations

__all__ = ["InputNote", "ParameterError"]


class ParameterError(ValueError):
    """A user-facing error: the message names the parameter, the rule and the value received."""


class InputNote(UserWarning):
    """An input was adjusted without changing what it shows: the message says what and why."""
