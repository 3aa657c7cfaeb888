"""Third-party libraries kept quiet: their banners and logs are not the suite's output.

HiGHS prints its banner on the C library's standard output when a ``highspy.Highs`` is
made, before any option can be set (``output_flag`` only silences what comes after), so
the one place that makes a solver does it with file descriptor 1 pointed at /dev/null.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import warnings

# the loggers of the libraries the suite drives: their records are for their developers
THIRD_PARTY_LOGGERS = (
    "distributed",
    "dask",
    "tornado",
    "asyncio",
    "matplotlib",
    "PIL",
    "pyopencl",
    "pytools",
    "moderngl",
    "numexpr",
    "fsspec",
    "bokeh",
)


# the libraries whose own warnings (raised in their modules) are theirs, not the suite's
THIRD_PARTY_MODULES = (
    "numpy",
    "scipy",
    "shapely",
    "matplotlib",
    "PIL",
    "pyopencl",
    "pytools",
    "moderngl",
    "pandas",
    "distributed",
    "dask",
    "highspy",
    "tornado",
    "bokeh",
)
# the suite's own modules: their numerical warnings (NaN, division by zero) show with
# --verbose and are errors in the tests
OWN_MODULES = r"compact_distributions(\.|$)"


def configure(verbose: bool = False) -> None:
    """How much of the third-party libraries' output a command shows.

    By default only their errors: their warnings (by the module that raised them) and
    log records are theirs, not the suite's result; the suite's own numerical warnings (NaN, division by zero) are
    hidden too.  These filters are appended last, so that any filter set before
    (``python -W``, ``PYTHONWARNINGS``, pytest's ``filterwarnings``, which make the
    suite's own warnings errors) wins.  With ``verbose``, every warning shows (once per
    place) and the libraries' info records go to standard error.

    Parameters
    ----------
    verbose : bool, optional
        Show warnings and info records (``--verbose``).
    """
    level = logging.INFO if verbose else logging.ERROR
    for name in THIRD_PARTY_LOGGERS:
        logging.getLogger(name).setLevel(level)
    if verbose:
        logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s", stream=sys.stderr)
        warnings.simplefilter("default")
        return
    # appended last: a filter set before (python -W, PYTHONWARNINGS, pytest's
    # filterwarnings) wins over these defaults
    for module in THIRD_PARTY_MODULES:
        warnings.filterwarnings("ignore", module=rf"{module}(\.|$)", append=True)
    warnings.filterwarnings("ignore", category=RuntimeWarning, module=OWN_MODULES, append=True)
    os.environ.setdefault("PYOPENCL_COMPILER_OUTPUT", "0")


@contextlib.contextmanager
def c_output_silenced(*fds: int):
    """File descriptors ``fds`` (default 1: what C libraries print to) point at /dev/null
    inside the block; a descriptor that is closed or captured is left as it is."""
    saved = []
    try:
        for fd in fds or (1,):
            (sys.stdout if fd == 1 else sys.stderr).flush()
            try:
                saved.append((fd, os.dup(fd)))
            except (OSError, ValueError, AttributeError):  # no such descriptor
                continue
            with open(os.devnull, "wb") as null:
                os.dup2(null.fileno(), fd)
        yield
    finally:
        for fd, copy in saved:
            os.dup2(copy, fd)
            os.close(copy)


def quiet_highs():
    """A ``highspy.Highs`` solver that prints nothing (no banner, no log)."""
    import highspy

    with c_output_silenced(1):
        h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    return h


__all__ = [
    "THIRD_PARTY_LOGGERS",
    "THIRD_PARTY_MODULES",
    "OWN_MODULES",
    "configure",
    "c_output_silenced",
    "quiet_highs",
]
