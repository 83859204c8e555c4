"""Exceptions that carry a message meant for people.

Convention: a message says what was expected, what arrived and where
(``knot vector for u has 17 knots; degree 3 with 14 control points needs 18``).
The command line prints these as one line on stderr, never as a traceback.
"""


class NurbskitError(ValueError):
    """A user-facing error: bad input data, a bad option, an unreadable file."""


class InputError(NurbskitError):
    """A file or array that cannot be used as given (names the file and the problem)."""


class OptionError(NurbskitError):
    """A command-line option or function argument out of its allowed range."""
