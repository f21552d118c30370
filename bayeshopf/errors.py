"""Errors that reach the user as one clear line.

Every error raised for bad input derives from :class:`BayesHopfError`. The CLI
prints ``str(err)`` on one line and exits non-zero, without a traceback, so each
message names the file or field, what was expected and what was found.
"""

from __future__ import annotations


class BayesHopfError(Exception):
    """Base class of the errors the CLI reports as one line."""


class DataError(BayesHopfError, ValueError):
    """A recording, manifest or data folder is not what bayeshopf expects.

    Example message: ``"rec3.csv: column 'alpha' expected (manifest names the
    planar pair h, alpha); found columns t, h"``.
    """


class FitError(BayesHopfError, RuntimeError):
    """The model cannot be fitted to the recordings given (for example too few)."""


class OutputError(BayesHopfError, OSError):
    """An output folder or file cannot be written as asked."""
