"""Other people's methods and backends, plugged in through entry points.

A tiny external distribution is written here (its own ``pyproject.toml`` and one
module): a method record with one declared option, a plain callable, a backend (a
brute-force float64 labelling), and an entry point that cannot be loaded.  It is built
and installed by pip into a temporary folder, which the commands then see on their
``PYTHONPATH``: the suite's own environment is not touched.  The checks run the real
command line in subprocesses, as a user would.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

PYPROJECT = """
[build-system]
requires = ["setuptools>=61"]
build-backend = "setuptools.build_meta"

[project]
name = "cvt-plugin-example"
version = "0.0.1"
requires-python = ">=3.10"

[project.entry-points."compact_distributions.methods"]
shrunk = "cvt_plugin_example:METHOD"
plain-ours = "cvt_plugin_extra:plain_ours"
broken = "cvt_plugin_example_missing:METHOD"

[project.entry-points."compact_distributions.backends"]
brute = "cvt_plugin_example:BruteBackend"

[tool.setuptools]
py-modules = ["cvt_plugin_example", "cvt_plugin_extra"]
"""

# The Extending guide's example module, installed as it is documented; the test adds a
# second module of its own for what the guide only describes (a plain callable)
EXAMPLE = ROOT / "docs" / "extending" / "cvt_plugin_example.py"
EXTRA_MODULE = '''
"""A plain callable of the same distribution, registered as a method."""
from compact_distributions.cvt.placement.ours import run_ours


def plain_ours(problem, backend, **options):
    """The paper's method, as a plain callable."""
    return run_ours(problem, backend, **options)
'''


@pytest.fixture(scope="module")
def plugin_env(tmp_path_factory):
    """Environment variables under which the example distribution is installed."""
    src = tmp_path_factory.mktemp("plugin-src")
    (src / "pyproject.toml").write_text(textwrap.dedent(PYPROJECT))
    (src / "cvt_plugin_example.py").write_text(EXAMPLE.read_text())
    (src / "cvt_plugin_extra.py").write_text(textwrap.dedent(EXTRA_MODULE))
    target = tmp_path_factory.mktemp("plugin-site")
    done = subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(target), str(src)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    if done.returncode != 0:
        pytest.fail(f"pip could not install the example plug-in: {done.stderr[-2000:]}")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(target), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def cvtbench(env, *args, timeout=600):
    return subprocess.run(
        [sys.executable, "-m", "compact_distributions.bench.commands.cli", *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )


def test_info_lists_the_plugins_and_the_broken_one(plugin_env):
    done = cvtbench(plugin_env, "info")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert any(line.split()[:3] == ["brute", "available", "CPU,"] for line in lines), done.stdout
    methods_line = next(line for line in lines if line.startswith("methods:"))
    assert "shrunk" in methods_line and "plain-ours" in methods_line
    assert any("shrunk" in line and "--shrink" in line for line in lines)
    broken = [line for line in lines if line.split()[:2] == ["broken", "unavailable"]]
    assert broken and "cvt_plugin_example_missing" in broken[0]


def test_run_records_the_option_and_the_option_acts(plugin_env, tmp_path):
    common = [
        "run",
        "--method",
        "shrunk",
        "--element",
        "square",
        "--elements",
        "64",
        "--size",
        "96",
        "--iterations",
        "5",
        "--backend",
        "brute",
        "--quiet",
    ]
    whole = cvtbench(plugin_env, *common, "--out", str(tmp_path / "a"))
    half = cvtbench(plugin_env, *common, "--shrink", "0.5", "--out", str(tmp_path / "b"))
    assert whole.returncode == 0 and half.returncode == 0, whole.stderr + half.stderr
    a = json.loads((tmp_path / "a" / "result.json").read_text())
    b = json.loads((tmp_path / "b" / "result.json").read_text())
    assert (a["method"], a["backend"], a["method_options"]) == ("shrunk", "brute", {})
    assert (b["method"], b["method_options"]) == ("shrunk", {"shrink": 0.5})
    # the same cells, each element scaled by 1/2 about its centre: a quarter of its area
    # (exact geometry from the written outlines, not the code's figures), and halved
    # elements of cells that do not overlap cannot overlap
    import numpy as np
    import shapely

    assert a["sites"] == b["sites"]
    area_a = np.array([shapely.Polygon(e).area for e in a["elements"] if e is not None])
    area_b = np.array([shapely.Polygon(e).area for e in b["elements"] if e is not None])
    assert len(area_a) == len(area_b) > 50
    np.testing.assert_allclose(area_b, area_a / 4, atol=0.05)  # outlines are written to 0.001 px
    assert b["overlap"] == pytest.approx(0.0, abs=1e-12)
    assert b["coverage"] == pytest.approx(area_b.sum() / (96 * 96), rel=1e-3)


def test_bad_option_value_and_option_of_another_method(plugin_env, tmp_path):
    bad = cvtbench(plugin_env, "run", "--method", "shrunk", "--shrink", "2", "--out", str(tmp_path / "x"))
    assert bad.returncode == 2 and "--shrink" in bad.stderr and "Traceback" not in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1 and not (tmp_path / "x").exists()
    other = cvtbench(plugin_env, "run", "--method", "ours", "--shrink", "0.5", "--out", str(tmp_path / "y"))
    assert other.returncode == 2 and "--shrink is not an option of --method ours" in other.stderr


def test_table2_runs_the_plugin_with_its_option(plugin_env, tmp_path):
    done = cvtbench(
        plugin_env,
        "table2",
        "--quick",
        "--methods",
        "shrunk,plain-ours",
        "--shapes",
        "square",
        "--backends",
        "numpy",
        "--seeds",
        "1",
        "--shrink",
        "0.5",
        "--quiet",
        "--out",
        str(tmp_path),
    )
    assert done.returncode == 0, done.stderr
    import pandas as pd

    table = pd.read_csv(tmp_path / "table2.csv")
    assert set(table["method"]) == {"shrunk shrink=0.5", "plain-ours"}
    assert (table["status"] == "ok").all()
    raw = json.loads(next((tmp_path / "raw" / "table2-quick").glob("shrunk__*.json")).read_text())
    assert raw["row"]["options"] == {"shrink": 0.5} and raw["row"]["label"] == "shrunk shrink=0.5"
    assert "shrunk shrink=0.5" in (tmp_path / "table2.md").read_text()


def test_the_conformance_suite_runs_the_plugin_backend(plugin_env):
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            str(ROOT / "tests" / "test_backend_conformance.py"),
            "-k",
            "brute",
        ],
        env=plugin_env,
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stdout[-3000:]
    summary = done.stdout.strip().splitlines()[-1]
    passed = int(summary.split(" passed")[0].split()[-1])
    assert passed >= 20 and "failed" not in summary, summary
