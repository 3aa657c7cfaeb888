"""Third-party libraries kept quiet: their banners and logs are not the suite's output.

HiGHS prints its banner on the C library's standard output when a ``highspy.Highs`` is
made, before any option can be set (``output_flag`` only silences what comes after), so
the one place that makes a solver does it with file descriptor 1 pointed at /dev/null.
"""

from __future__ import annotations

import contextlib
import os
import sys


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


__all__ = ["c_stdout_silenced", "quiet_highs"]
