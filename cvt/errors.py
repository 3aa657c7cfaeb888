"""Errors the user can act on.

Every problem with user input raises :class:`InputError` with one line that names the
bad value; the CLI prints it and exits with status 2, without a traceback.
"""


class InputError(ValueError):
    """Bad user input: a message that names the offending value."""


class BackendUnavailable(RuntimeError):
    """A backend whose runtime is missing (no OpenCL platform, no EGL, ...)."""
