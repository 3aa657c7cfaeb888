"""Warnings tell the truth: third-party ones are silenced by their origin, the suite's own
numerical ones show with ``--verbose`` and are errors in the tests."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

from compact_distributions.cvt import quiet
from compact_distributions.cvt.evaluate import size_fidelity


def _shown(message: str, category: type[Warning], module: str) -> bool:
    """Whether a warning raised in ``module`` passes the current filters (an error counts)."""
    try:
        with warnings.catch_warnings(record=True) as seen:
            warnings.warn_explicit(message, category, f"{module.replace('.', '/')}.py", 1, module=module)
    except Warning:
        return True
    return bool(seen)


def test_the_suites_numerical_warnings_are_errors_in_the_tests():
    # log2(1 / 0): NumPy's divide-by-zero warning, raised in cvt.evaluate's own line
    with pytest.raises(RuntimeWarning, match="divide by zero"):
        size_fidelity([1.0, 2.0], [0.0, 1.0])
    # and in NumPy's reductions that the suite's modules call
    with pytest.raises(RuntimeWarning, match="Mean of empty slice"):
        np.mean(np.zeros(0))


def test_configure_keeps_the_tests_filters():
    # its defaults come after a filter set before (pytest's, python -W): errors stay errors
    with warnings.catch_warnings():
        warnings.resetwarnings()
        warnings.filterwarnings("error", category=RuntimeWarning, module="compact_distributions")
        quiet.configure(verbose=False)
        with pytest.raises(RuntimeWarning):
            warnings.warn_explicit("nan", RuntimeWarning, "x.py", 1, module="compact_distributions.cvt.lloyd")


def test_configure_silences_by_origin_not_by_category():
    with warnings.catch_warnings():
        warnings.resetwarnings()
        quiet.configure(verbose=False)
        # third-party warnings of any category, raised in their own modules: hidden
        assert not _shown("deprecated thing", FutureWarning, "pandas.core.frame")
        assert not _shown("overflow", RuntimeWarning, "scipy.optimize._linprog")
        assert not _shown("a note", UserWarning, "shapely.predicates")
        # a RuntimeWarning or FutureWarning of a module that is not a known library: shown
        assert _shown("overflow", RuntimeWarning, "someone_elses_plugin")
        assert _shown("will change", FutureWarning, "compact_distributions.cvt.lloyd")
        # the suite's own numerical warnings: hidden by default ...
        assert not _shown("invalid value", RuntimeWarning, "compact_distributions.cvt.lloyd")
        # ... but a module whose name only starts like a library's is not that library
        assert _shown("a note", UserWarning, "numpyish")


def test_verbose_shows_the_suites_numerical_warnings():
    with warnings.catch_warnings():
        warnings.resetwarnings()
        quiet.configure(verbose=True)
        assert _shown("invalid value", RuntimeWarning, "compact_distributions.cvt.lloyd")
        assert _shown("overflow", RuntimeWarning, "scipy.optimize._linprog")


@pytest.mark.parametrize(("verbose", "shown"), [(False, False), (True, True)])
def test_the_command_line_shows_them_with_verbose(verbose, shown):
    # a fresh interpreter, as cvtbench starts: no pytest filters
    code = (
        "from compact_distributions.cvt import quiet\n"
        "from compact_distributions.cvt.evaluate import size_fidelity\n"
        f"quiet.configure(verbose={verbose})\n"
        "size_fidelity([1.0, 2.0], [0.0, 1.0])\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert ("RuntimeWarning: divide by zero" in run.stderr) is shown, run.stderr
