"""A distribution of misbehaving plug-ins, installed for a test by writing its module and
its ``.dist-info`` folder (METADATA and entry_points.txt: what pip would leave) into a
temporary folder that the commands then see on their ``PYTHONPATH``.  Each method and
backend does one wrong thing, named by its entry point; ``plain-ours`` delegates to the
suite's own method, as a user's wrapper would."""

from __future__ import annotations

import os
import textwrap
from pathlib import Path

DISTRIBUTION = "cvt-hostile-plugins"
VERSION = "0.3.1"
MODULE = "cvt_hostile_plugins"

# entry point name -> (what it does, as the one line must say it)
METHODS = {
    "raises": "raised RuntimeError: the plug-in's own bug",
    "returns-none": "returned None, not a Distribution",
    "returns-dict": "returned a dict, not a Distribution",
    "nan-sites": "returned sites that are NaN or infinite",
    "inf-element": "returned element 3 with NaN or infinite vertices",
    "bad-labels": "returned labels from 0 to 99",
    "small-labels": "returned labels of shape (8, 8)",
    "exits": "raised SystemExit: 0",
    "input-error": "raised InputError: ",
}
BACKENDS = {
    "ctor-fails": "could not start: RuntimeError: no device for you",
    "wrong-size": "returned labels of shape (10, 12)",
    "past-sites": "returned labels from 5 to 24 for 20 sites (-1 .. 19)",
    "float-labels": "returned labels that are float64 values",
    "label-raises": "raised ZeroDivisionError: integer division or modulo by zero while labelling",
    "bad-moments": "returned moments whose count is",
    "no-device": "could not start: AttributeError: no such device",
}
CRASHERS = {"aborts": "SIGABRT", "segfaults": "SIGSEGV"}  # methods that take their process down

SOURCE = '''
"""Plug-ins that misbehave, one way each."""
import ctypes
import os
import sys

import numpy as np

from compact_distributions.backends.numpy_backend import NumpyBackend
from compact_distributions.cvt.distribution import Distribution
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.moments import Moments
from compact_distributions.cvt.placement.ours import run_ours


def ours(problem, backend, **options):
    return run_ours(problem, backend, **options)


def plain_ours(problem, backend, **options):
    """The paper's method, as a plain callable (recorded under its entry point's name)."""
    return run_ours(problem, backend, **options)


def raises(problem, backend, **options):
    raise RuntimeError("the plug-in's own bug")


def returns_none(problem, backend, **options):
    return None


def returns_dict(problem, backend, **options):
    return {"sites": [[1, 2]]}


def nan_sites(problem, backend, **options):
    dist = ours(problem, backend, **options)
    dist.sites[0, 0] = np.nan
    return dist


def inf_element(problem, backend, **options):
    import shapely

    dist = ours(problem, backend, **options)
    dist.elements[3] = shapely.Polygon([(0, 0), (np.inf, 0), (1, 1)])
    return dist


def bad_labels(problem, backend, **options):
    dist = ours(problem, backend, **options)
    dist.labels = np.full_like(dist.labels, 99)
    dist.labels[0, 0] = 0
    return dist


def small_labels(problem, backend, **options):
    dist = ours(problem, backend, **options)
    dist.labels = np.zeros((8, 8), dtype=np.int32)
    return dist


def exits(problem, backend, **options):
    sys.exit(0)


def input_error(problem, backend, **options):
    raise InputError("not the user's fault")


def aborts(problem, backend, **options):
    os.abort()


def segfaults(problem, backend, **options):
    ctypes.string_at(0)


class Reference(NumpyBackend):
    """The NumPy reference under another name (the base of the backends below); each
    start is one line in the file $HOSTILE_STARTS, with its process id."""

    name = "hostile"

    def __init__(self):
        super().__init__()
        if os.environ.get("HOSTILE_STARTS"):
            with open(os.environ["HOSTILE_STARTS"], "a") as fh:
                fh.write(f"{os.getpid()}\\n")

    def device(self):
        return "CPU, a hostile plug-in"


class CtorFails(Reference):
    def __init__(self):
        raise RuntimeError("no device for you")


class WrongSize(Reference):
    def _label(self, sites, angles, scales, metric, grid):
        return np.zeros((10, 12), dtype=np.int32)


class PastSites(Reference):
    def _label(self, sites, angles, scales, metric, grid):
        return super()._label(sites, angles, scales, metric, grid) + 5


class FloatLabels(Reference):
    def _label(self, sites, angles, scales, metric, grid):
        return super()._label(sites, angles, scales, metric, grid).astype(float)


class LabelRaises(Reference):
    def _label(self, sites, angles, scales, metric, grid):
        return 1 // 0


class BadMoments(Reference):
    def _moments(self, sites, angles, scales, metric, grid):
        z = np.zeros(len(sites) + 1, dtype=np.int64)
        return Moments(z, z, z, z, z)


class NoDevice(Reference):
    def device(self):
        raise AttributeError("no such device")


class Aborts(Reference):
    def _label(self, sites, angles, scales, metric, grid):
        os.abort()
'''


def _entry(name: str) -> str:
    return name.replace("-", "_")


BACKEND_CLASSES = {
    "ctor-fails": "CtorFails",
    "wrong-size": "WrongSize",
    "past-sites": "PastSites",
    "float-labels": "FloatLabels",
    "label-raises": "LabelRaises",
    "bad-moments": "BadMoments",
    "no-device": "NoDevice",
    "aborting": "Aborts",
    "hostile-ok": "Reference",
}


def install(folder: Path) -> dict:
    """Write the distribution into ``folder``; the environment that sees it."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{MODULE}.py").write_text(textwrap.dedent(SOURCE))
    info = folder / f"{DISTRIBUTION.replace('-', '_')}-{VERSION}.dist-info"
    info.mkdir(exist_ok=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {DISTRIBUTION}\nVersion: {VERSION}\n")
    methods = ["plain-ours", *METHODS, *CRASHERS]
    lines = ["[compact_distributions.methods]"]
    lines += [f"{m} = {MODULE}:{_entry(m)}" for m in methods]
    lines += ["", "[compact_distributions.backends]"]
    lines += [f"{b} = {MODULE}:{cls}" for b, cls in BACKEND_CLASSES.items()]
    (info / "entry_points.txt").write_text("\n".join(lines) + "\n")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(folder), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


__all__ = ["DISTRIBUTION", "VERSION", "METHODS", "BACKENDS", "CRASHERS", "BACKEND_CLASSES", "install"]
