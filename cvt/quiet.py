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


def configure(verbose: bool = False) -> None:
    """How much of the third-party libraries' output a command shows: by default only
    their errors (warnings and log records are theirs, not the suite's result); with
    ``verbose`` their warnings and info records too, on standard error."""
    level = logging.INFO if verbose else logging.ERROR
    for name in THIRD_PARTY_LOGGERS:
        logging.getLogger(name).setLevel(level)
    if verbose:
        logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s", stream=sys.stderr)
        warnings.simplefilter("default")
    else:
        for module in (
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
        ):
            warnings.filterwarnings("ignore", module=module)
        warnings.filterwarnings("ignore", category=RuntimeWarning)
        warnings.filterwarnings("ignore", category=FutureWarning)
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


__all__ = ["configure", "c_output_silenced", "quiet_highs"]
