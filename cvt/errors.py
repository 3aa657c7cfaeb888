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


class PluginError(RunAborted):
    """A plug-in (a method or backend of another distribution) failed.

    It raised, or returned something the suite cannot use: the message is one line
    naming the plug-in, its distribution and what it did; the command line exits with
    status 1 (``--verbose`` adds the traceback).
    """


def exception_line(exc: BaseException) -> str:
    """``Type: first line of the message`` of an exception (its type alone if it says nothing)."""
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__


def kind_of(value: object) -> str:
    """What an error says a wrong value is: ``None``, ``a str``, ``a dict``, ..."""
    return "None" if value is None else f"a {type(value).__name__}"


__all__ = ["InputError", "BackendUnavailable", "RunAborted", "PluginError", "exception_line", "kind_of"]
