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
def c_stdout_silenced():
    """File descriptor 1 (what C libraries print to) points at /dev/null inside the block."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError, AttributeError):  # no descriptor 1 (closed, or a captured stream)
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def quiet_highs():
    """A ``highspy.Highs`` solver that prints nothing (no banner, no log)."""
    import highspy

    with c_stdout_silenced():
        h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    return h


__all__ = ["configure", "c_stdout_silenced", "quiet_highs"]
