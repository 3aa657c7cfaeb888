"""Other people's plug-ins fail closed: whatever a method or backend of another
distribution raises or returns, the command ends with one line naming the plug-in, its
distribution and what it did, exit 1, no traceback and no result.json; a sweep survives a
run that takes its process down (an abort, a segfault), stores the others and exits 1
naming what failed; a plug-in's runs are recorded under its entry point's name.  The
misbehaving distribution is :mod:`tests.hostile_plugins`, installed into a temporary
folder; the commands run as real processes.  Also here: the API's type checks and
``polygon:FILE`` in every command that takes an element."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import shapely

import compact_distributions as cd
from compact_distributions.backends.numpy_backend import NumpyBackend
from compact_distributions.bench.commands.cli import main
from compact_distributions.cvt.distribution import Distribution
from compact_distributions.cvt.errors import PluginError
from compact_distributions.cvt.methods import Method, check_distribution
from compact_distributions.cvt.moments import Moments

from . import hostile_plugins as hostile
from .cli_errors import one_error

ROOT = Path(__file__).resolve().parent.parent
NAMED = f"(distribution {hostile.DISTRIBUTION} {hostile.VERSION})"
SMALL = ["--elements", "20", "--size", "48", "--iterations", "2", "--quiet"]


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    return hostile.install(tmp_path_factory.mktemp("hostile-site"))


def cvtbench(env, *args, timeout=600):
    return subprocess.run(
        [sys.executable, "-m", "compact_distributions.bench.commands.cli", *map(str, args)],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )


def assert_one_line(done, *needles):
    """Exit 1, one line on stderr holding every needle, no traceback."""
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 1 and len(lines) == 1, (done.returncode, done.stderr)
    assert "Traceback" not in done.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


# ------------------------------------------------------------------ one run, as a process
@pytest.mark.parametrize("name", list(hostile.METHODS))
def test_a_misbehaving_method_is_one_line_naming_it(env, tmp_path, name):
    out = tmp_path / "out"
    done = cvtbench(env, "run", "--method", name, *SMALL, "--out", out)
    assert_one_line(done, f"method plug-in {name!r} {NAMED}", hostile.METHODS[name])
    assert not out.exists() and not list(tmp_path.glob(".out*"))  # nothing half-written


@pytest.mark.parametrize("name", list(hostile.BACKENDS))
def test_a_misbehaving_backend_is_one_line_naming_it(env, tmp_path, name):
    out = tmp_path / "out"
    done = cvtbench(env, "run", "--backend", name, *SMALL, "--out", out)
    assert_one_line(done, f"backend plug-in {name!r} {NAMED}", hostile.BACKENDS[name])
    assert not out.exists() and not list(tmp_path.glob(".out*"))


@pytest.mark.parametrize(
    "option, name, what",
    [
        ("--method", "returns-none", hostile.METHODS["returns-none"]),
        ("--backend", "wrong-size", "returned labels of shape (10, 12) for a 96x96 grid"),
    ],
)
def test_a_misbehaving_plugin_in_a_mosaic_is_one_line(env, tmp_path, option, name, what):
    out = tmp_path / "m"
    done = cvtbench(
        env, "mosaic", ROOT / "samples" / "rings.png", option, name, "--elements", "50", "--size", "96",
        "--iterations", "2", "--quiet", "--out", out,
    )  # fmt: skip
    kind = "method" if option == "--method" else "backend"
    assert_one_line(done, f"{kind} plug-in {name!r} {NAMED}", what)
    assert not out.exists()


def test_verbose_adds_the_traceback(env, tmp_path):
    done = cvtbench(env, "run", "--method", "raises", *SMALL, "--out", tmp_path / "o", "--verbose")
    assert done.returncode == 1 and "Traceback" in done.stderr
    assert 'raise RuntimeError("the plug-in\'s own bug")' in done.stderr  # the plug-in's own line
    assert done.stderr.strip().splitlines()[-1].startswith("cvtbench: method plug-in 'raises'")


def test_a_delegating_callable_is_recorded_under_its_entry_point(env, tmp_path):
    done = cvtbench(env, "run", "--method", "plain-ours", *SMALL, "--out", tmp_path / "o")
    assert done.returncode == 0, done.stderr
    result = json.loads((tmp_path / "o" / "result.json").read_text())
    assert result["method"] == "plain-ours"
    # the same problem through the built-in: the same sites (it did delegate), another name
    ours = cvtbench(env, "run", "--method", "ours", *SMALL, "--out", tmp_path / "p")
    assert ours.returncode == 0, ours.stderr
    other = json.loads((tmp_path / "p" / "result.json").read_text())
    assert other["method"] == "ours" and other["sites"] == result["sites"]


# ------------------------------------------------------------------ a sweep, as a process
def test_a_sweep_survives_crashing_plugins_and_names_them(env, tmp_path):
    """Plug-ins that abort and segfault their process, one that raises, a backend that
    aborts as it labels: the other runs are stored, the failed rows say why, the command
    exits 1 naming the first; a worker process starts its backend once for its runs."""
    starts = tmp_path / "starts"
    out = tmp_path / "t2"
    methods = "ours,raises,aborts,segfaults,plain-ours"
    done = cvtbench(
        {**env, "HOSTILE_STARTS": str(starts)},
        *("table2", "--quick", "--methods", methods, "--shapes", "square"),
        *("--backends", "numpy,hostile-ok,aborting", "--seeds", "2", "--out", out, "--quiet"),
    )
    line = done.stderr.strip().splitlines()[-1]
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert line.startswith("cvtbench: table2: 8 of 14 runs failed: ours/aborting square"), line
    assert f"backend plug-in 'aborting' {NAMED} took its worker process down (signal SIGABRT)" in line

    import pandas as pd

    table = pd.read_csv(out / "table2.csv").set_index(["method", "backend"])
    ok = [("ours", "numpy"), ("ours", "hostile-ok"), ("plain-ours", "numpy")]
    assert (table.loc[ok, "status"] == "ok").all() and (table.loc[ok, "runs"] == 2).all()
    reasons = table["reason"].fillna("")
    assert (
        f"method plug-in 'aborts' {NAMED} took its worker process down (signal SIGABRT)"
        == (reasons[("aborts", "numpy")])
    )
    assert "(signal SIGSEGV)" in reasons[("segfaults", "numpy")]
    assert "raised RuntimeError: the plug-in's own bug" in reasons[("raises", "numpy")]
    failed = [("aborts", "numpy"), ("segfaults", "numpy"), ("raises", "numpy"), ("ours", "aborting")]
    assert (table.loc[failed, "status"] == "failed").all()
    assert "## Not run, failed or partial" in (out / "table2.md").read_text()
    # the runs that finished are stored (and read back by the next sweep), no failed one is
    raw = out / "raw" / "table2-quick"
    stored = sorted(p.name.split("__")[:2] for p in raw.glob("*.json"))
    assert stored == [["ours", "hostile-ok"]] * 2 + [["ours", "numpy"]] * 2 + [["plain-ours", "numpy"]] * 2
    # both runs on hostile-ok ran in one worker process, which started the backend once
    # (the file also holds the driver's probes and the aborting backend's starts)
    records = [json.loads(p.read_text()) for p in raw.glob("ours__hostile-ok__*.json")]
    (worker,) = {r["worker"] for r in records}
    assert worker.startswith("worker process ")
    assert starts.read_text().split().count(worker.split()[-1]) == 1
    assert {
        r["row"]["method"] for r in map(json.loads, map(Path.read_text, raw.glob("plain-ours*.json")))
    } == {"plain-ours"}


def test_table2_with_a_method_that_raises_in_every_run_exits_1(env, tmp_path):
    done = cvtbench(
        env,
        *("table2", "--quick", "--methods", "ours,raises", "--shapes", "square", "--backends", "numpy"),
        *("--seeds", "1", "--out", tmp_path, "--quiet"),
    )
    assert done.returncode == 1 and "Traceback" not in done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("cvtbench: table2: 1 of 2 runs failed: raises/numpy square")
    assert f"method plug-in 'raises' {NAMED} raised RuntimeError" in last
    assert (tmp_path / "table2.csv").exists()


# ------------------------------------------------------------------ the boundaries, in-process
def _good(problem) -> Distribution:
    return cd.run(problem, "ours", iterations=1).distribution


@pytest.fixture(scope="module")
def small():
    return cd.problem(n_elements=12, size=32, seed=2)


def _broken(dist, **changes):
    import copy

    out = copy.copy(dist)
    for k, v in changes.items():
        setattr(out, k, v)
    return out


def test_check_distribution_accepts_a_good_one_and_refuses_each_defect(small):
    dist = _good(small)
    check_distribution(dist, small, "method 'x'")  # a real run passes
    n = len(dist.sites)
    nan_sites = dist.sites.copy()
    nan_sites[2, 1] = np.inf
    with np.errstate(invalid="ignore"):
        ring = shapely.Polygon([(0, 0), (1, 0), (1, np.nan)])
    cases = {
        "None, not a Distribution": None,
        "a list, not a Distribution": [1, 2],
        "sites that are NaN or infinite": _broken(dist, sites=nan_sites),
        "sites of shape (12, 3), not (N, 2)": _broken(dist, sites=np.zeros((12, 3))),
        f"angles of shape ({n - 1},) for {n} sites": _broken(dist, angles=dist.angles[:-1]),
        "scales that are NaN or infinite": _broken(dist, scales=np.full(n, np.nan)),
        f"{n - 1} elements for {n} sites": _broken(dist, elements=dist.elements[:-1]),
        "element 0 that is a str, not a polygon": _broken(dist, elements=["x", *dist.elements[1:]]),
        "element 1 with NaN or infinite vertices": _broken(dist, elements=[None, ring, *dist.elements[2:]]),
        "labels of shape (31, 32) for a 32x32 grid": _broken(dist, labels=dist.labels[1:]),
        f"to {n}, outside -1 .. {n - 1}": _broken(dist, labels=np.where(dist.labels == 0, n, dist.labels)),
        "labels that are a list, not an integer raster": _broken(dist, labels=[[0]]),
        "seconds that are not a list of finite numbers": _broken(dist, seconds=[np.nan]),
        "lloyd_seconds 'fast', not a finite number": _broken(dist, lloyd_seconds="fast"),
        "extra that is None, not a dict": _broken(dist, extra=None),
    }
    for what, bad in cases.items():
        with pytest.raises(PluginError, match="^method 'x' returned ") as err:
            check_distribution(bad, small, "method 'x'")
        assert what in str(err.value), (what, str(err.value))


def test_a_methods_prepared_elements_are_taken_as_copies(small):
    """GEOS's prepared geometries must not be shared between threads: the run measures
    unprepared copies with exactly the method's vertices, and leaves the method's own
    elements prepared."""
    own = shapely.box([4.0, 16.0], [4.0, 16.0], [12.0, 28.0], [12.0, 28.0])
    shapely.prepare(own)

    def prepared(problem, backend, **options):
        sites = np.array([[8.0, 8.0], [22.0, 22.0]])
        return Distribution("prepared", sites, np.zeros(2), np.ones(2), elements=list(own))

    result = cd.run(small, prepared)
    assert not shapely.is_prepared(result.elements).any() and shapely.is_prepared(own).all()
    assert all(shapely.equals_exact(a, b, 0) for a, b in zip(result.elements, own, strict=True))
    assert result.coverage == pytest.approx((64 + 144) / 1024)


def test_a_method_that_places_no_elements_is_measured_as_such(small):
    def lattice(problem, backend, **options):  # sites only, as the Method example's
        sites = np.array([[8.0, 8.0], [24.0, 24.0]])
        return Distribution("lattice", sites, np.zeros(2), np.ones(2))

    result = cd.run(small, lattice)
    assert result.elements == [None, None] and result.coverage == 0.0 and result.method == "lattice"


def test_a_callable_of_the_api_that_fails_is_named(small):
    def returns_none(problem, backend, **options):
        return None

    def crashes(problem, backend, **options):
        raise KeyError("k")

    with pytest.raises(
        PluginError, match=r"^method 'returns_none' \(a callable of module tests\..*returned None"
    ):
        cd.run(small, returns_none)
    with pytest.raises(PluginError, match=r"method 'crashes' .* raised KeyError: 'k'$") as err:
        cd.run(small, crashes)
    assert isinstance(err.value.__cause__, KeyError)  # the plug-in's own traceback is kept


def test_a_delegating_record_records_its_own_name(small):
    record = Method("mine", lambda problem, backend, **o: cd.get_method("ours")(problem, backend, **o))
    result = cd.run(small, record, iterations=1)
    assert result.method == "mine" and result.distribution.method == "mine"


def test_the_suites_own_errors_pass_the_boundary_unchanged(small):
    from compact_distributions.cvt.registry import get_method

    with pytest.raises(cd.InputError):  # a built-in method's InputError stays the user's
        get_method("ours")(small, NumpyBackend(), iterations=1, element="no-such-shape")


class _Named(NumpyBackend):
    plugin = "backend plug-in 'named' (distribution d 1)"


def test_backend_boundary_checks_labels_and_moments(small):
    grid = small.grid
    n = 5
    backend = _Named()
    good = np.zeros((grid.height, grid.width), dtype=np.int64)
    assert backend.check_labels(good, n, grid).dtype == np.int32
    for bad, what in (
        (good[:, :-1], "labels of shape (32, 31) for a 32x32 grid"),
        (good + n, f"labels from {n} to {n} for {n} sites"),
        (good - 2, "labels from -2 to -2"),
        (good.astype(float), "labels that are float64 values"),
        (None, "labels that are None"),
    ):
        with pytest.raises(
            PluginError, match=r"^backend plug-in 'named' \(distribution d 1\) returned "
        ) as err:
            backend.check_labels(bad, n, grid)
        assert what in str(err.value)
    z = np.zeros(n, dtype=np.int64)
    ok = Moments(z + 4, z + 4 * 31, z, z, z)  # four pixels each in the last column
    assert backend.check_moments(ok, n, grid) is ok
    for bad, what in (
        (Moments(z + 4, z + 4 * 32, z, z, z), "centroid off the raster"),
        (Moments(z - 1, z, z, z, z), "a negative count"),
        (Moments(z[:-1], z, z, z, z), f"count is int64 values of shape ({n - 1},), not {n} integers"),
        (Moments(z, z.astype(float), z, z, z), "sx is float64 values"),
        ((z, z), "moments that are a tuple, not Moments"),
    ):
        with pytest.raises(PluginError) as err:
            backend.check_moments(bad, n, grid)
        assert what in str(err.value), (what, str(err.value))


def test_a_plugin_backend_that_raises_is_named_and_a_builtin_one_is_not(small):
    class Raises(_Named):
        def _label(self, *args):
            raise OSError("device lost")

    metric, grid = small.metric, small.grid
    sites = np.array([[5.0, 5.0], [20.0, 20.0]])
    with pytest.raises(
        PluginError, match=r"^backend plug-in 'named' .* raised OSError: device lost while labelling$"
    ):
        Raises().label(sites, metric=metric, grid=grid)
    with pytest.raises(PluginError, match="raised OSError: device lost while labelling"):
        Raises().moments(sites, metric=metric, grid=grid)  # its moments are its labels' sums

    class MomentsRaise(_Named):
        def _moments(self, *args):
            raise ValueError("no sums")

    with pytest.raises(PluginError, match="raised ValueError: no sums while computing moments$"):
        MomentsRaise().moments(sites, metric=metric, grid=grid)

    class BuiltIn(NumpyBackend):
        def _label(self, *args):
            raise OSError("device lost")

    with pytest.raises(OSError):  # the suite's own bug keeps its traceback
        BuiltIn().label(sites, metric=metric, grid=grid)


def test_which_runs_go_to_a_worker_process():
    from compact_distributions.bench.runs import RunSpec
    from compact_distributions.bench.sweep import runs_apart

    def spec(method, backend):
        return RunSpec("t", method, backend, "square", 32, 32, 4, 1, 0)

    assert not runs_apart(spec("ours", "numpy")) and not runs_apart(spec("hausner2001", "ckdtree"))
    assert runs_apart(spec("ours", "opencl")) and runs_apart(spec("ours", "gl-cone"))


# ------------------------------------------------------------------ the API's types
@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"n_elements": "100"}, "n_elements"),
        ({"n_elements": 100.0}, "n_elements"),
        ({"n_elements": True}, "n_elements"),
        ({"seed": "3"}, "seed"),
        ({"aspect": "0.5", "element": "rectangle"}, "aspect"),
        ({"element": 4}, "element"),
        ({"metric": b"l2"}, "metric"),
        ({"size": 64.0}, "size"),
        ({"size": ("64", 32)}, "size"),
    ],
)
def test_problem_refuses_wrong_types_naming_the_argument(kwargs, name):
    with pytest.raises(cd.InputError, match=f"^{name} must be") as err:
        cd.problem(**{"n_elements": 10, "size": 32, **kwargs})
    assert repr(kwargs[name]) in str(err.value)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"iterations": "2"}, "iterations"),
        ({"gap": "1"}, "gap"),
        ({"element": ["square"]}, "element"),
        ({"progress": "yes"}, "progress"),
        ({"method": "hausner2001", "delta": "0.9"}, "delta"),
    ],
)
def test_run_refuses_wrong_types_naming_the_argument(small, kwargs, name):
    with pytest.raises(cd.InputError, match=f"^{name} must be"):
        cd.run(small, **{"iterations": 1, **kwargs})


def test_the_right_types_still_run(small):
    assert cd.problem(n_elements=np.int64(10), size="32x24", aspect=1, element="rectangle").n_elements == 10
    assert cd.run(small, "hausner2001", iterations=1, delta=np.float32(0.9), gap=1).coverage > 0


def test_mosaic_refuses_wrong_types_naming_the_argument():
    picture = np.linspace(0, 1, 12 * 12 * 3).reshape(12, 12, 3)
    with pytest.raises(cd.InputError, match="^n_elements must be a whole number"):
        cd.mosaic(picture, n_elements="4")
    with pytest.raises(cd.InputError, match="^contrast must be a real number"):
        cd.mosaic(picture, n_elements=4, contrast="1")


# ------------------------------------------------------------------ polygon:FILE everywhere
@pytest.fixture
def kite(tmp_path):
    path = tmp_path / "kite.csv"
    path.write_text("x,y\n0,0\n2,0\n3,1\n1,2\n")
    return f"polygon:{path}"


def _edges(outline) -> np.ndarray:
    """The directions of an outline's sides (closed or not), in degrees mod 180, sorted."""
    ring = np.asarray(outline, dtype=float)
    if np.allclose(ring[0], ring[-1]):
        ring = ring[:-1]
    d = np.roll(ring, -1, axis=0) - ring
    return np.sort(np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 180)


def test_mosaic_takes_a_polygon_file(kite, tmp_path, capsys):
    out = tmp_path / "m"
    code = main(
        ["mosaic", str(ROOT / "samples" / "rings.png"), "--element", kite, "--elements", "60", "--size", "96"]
        + ["--iterations", "3", "--no-cut", "--no-field", "--quiet", "--out", str(out)]
    )
    assert code == 0, capsys.readouterr().err
    result = json.loads((out / "result.json").read_text())
    assert result["element"] == kite and result["placed"] > 30
    # without cutting or a field every element is the kite, scaled and moved: four sides,
    # parallel to the kite's own (0°, 45°, 116.57°, 135° mod 180°)
    kite_sides = _edges([[0, 0], [2, 0], [3, 1], [1, 2]])
    for outline in [e for e in result["elements"] if e is not None]:
        assert len(outline) in (4, 5)
        np.testing.assert_allclose(_edges(outline), kite_sides, atol=0.05)


def test_mosaic_refuses_a_bad_polygon_in_one_line(tmp_path, capsys):
    dent = tmp_path / "dent.csv"
    dent.write_text("x,y\n0,0\n4,0\n2,1\n4,4\n0,4\n")
    line = one_error(
        ["mosaic", ROOT / "samples" / "rings.png", "--element", f"polygon:{dent}", "--out", tmp_path / "m"],
        capsys,
    )
    assert "not convex" in line and str(dent) in line and not (tmp_path / "m").exists()


def test_table2_and_table3_take_a_polygon_file(kite, tmp_path, capsys):
    import pandas as pd

    code = main(
        ["table2", "--quick", "--methods", "ours", "--shapes", f"square,{kite}", "--backends", "numpy"]
        + ["--seeds", "1", "--quiet", "--out", str(tmp_path / "t2")]
    )
    assert code == 0, capsys.readouterr().err
    t2 = pd.read_csv(tmp_path / "t2" / "table2.csv")
    assert set(t2["element"]) == {"square", kite} and (t2["status"] == "ok").all()
    assert all("/" not in p.name for p in (tmp_path / "t2" / "raw").rglob("*.json"))
    code = main(
        ["table3", "--quick", "--methods", "ours", "--shapes", kite, "--scenes", "region"]
        + ["--seeds", "1", "--quiet", "--out", str(tmp_path / "t3")]
    )
    assert code == 0, capsys.readouterr().err
    t3 = pd.read_csv(tmp_path / "t3" / "table3.csv")
    assert list(t3["element"]) == [kite] and (t3["status"] == "ok").all()
    assert 0.3 < float(t3["coverage_mean"].iloc[0]) <= 1.0


@pytest.mark.parametrize("command", ["table2", "table3"])
def test_sweeps_refuse_a_bad_polygon_in_one_line(command, tmp_path, capsys):
    line = one_error(
        [command, "--quick", "--shapes", f"polygon:{tmp_path / 'none.csv'}", "--out", tmp_path / "t"], capsys
    )
    assert "--shapes" in line or "does not exist" in line
    assert not (tmp_path / "t").exists()
