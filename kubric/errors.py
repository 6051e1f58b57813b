"""The one base class of the errors kubric expects (bad input, a failure it can explain).

Every such error is a :class:`KubricError` carrying the exit status the ``kubric`` command ends
with when it is not caught: 2 for a usage error (a bad option or flag: :class:`UsageError`), 1 for
a failure (bad input data, a missing file, an unreachable source). Its message is one line that
names the bad value and what is allowed. The concrete classes also derive from the builtin type
callers caught before (``ValueError``, ``RuntimeError``), so ``except ValueError`` keeps working.

The command line (:mod:`kubric.cli`) prints a :class:`KubricError` or an ``OSError`` (a path and
its reason) as one line; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations


class KubricError(Exception):
    """An expected error; ``exit_code`` is what the ``kubric`` command exits with."""

    exit_code = 1


class UsageError(KubricError):
    """A bad option, flag or combination of them (exit status 2)."""

    exit_code = 2


class InputError(KubricError, ValueError):
    """Input data that cannot be used (a malformed file, a scene off its contract, ...)."""


__all__ = ["InputError", "KubricError", "UsageError"]
