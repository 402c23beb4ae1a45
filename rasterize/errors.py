"""User-facing input errors.

Every mistake a user can make (a missing file, an unknown environment, a scene with NaN in it, a
dataset collected with another raster configuration) raises an :class:`InputError` whose message
names the input and says how to fix it. Command-line entry points print that message on one line
and exit non-zero; library callers can catch it like any ``ValueError``.
"""


class InputError(ValueError):
    """Bad input from a user: the message names the input and the fix."""
