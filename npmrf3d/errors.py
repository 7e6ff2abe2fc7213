"""The one exception type for user mistakes.

Every check that a user can trip (bad shapes, NaN, unknown names, unreadable files,
an output folder that already holds a run) raises :class:`ParameterError`. The CLI turns it
into one line on stderr and exit code 2; library callers can catch it like a ``ValueError``.
"""

from __future__ import annotations

__all__ = ["ParameterError"]


class ParameterError(ValueError):
    """A user-facing error: the message names the parameter, the rule and the value received."""
