"""Errors the user can act on.

Every problem with user input raises :class:`InputError` with one line that names the
bad value; the CLI prints it and exits with status 2, without a traceback.
"""


class InputError(ValueError):
    """Bad user input: a message that names the offending value."""


class BackendUnavailable(RuntimeError):
    """A backend whose runtime is missing (no OpenCL platform, no EGL, ...)."""


class RunAborted(RuntimeError):
    """A command that could not finish for a reason outside its input (the Dask cluster
    it ran on was lost): the CLI prints its one line and exits with status 1."""


__all__ = ["InputError", "BackendUnavailable", "RunAborted"]
