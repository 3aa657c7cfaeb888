"""Fail closed wherever a result is judged: the regression guard, stored runs read back,
and Table 2's aggregation never pass or report a figure that is missing or not finite."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from compact_distributions.bench.commands import regress as regress_cmd

from .cli_errors import one_error


def _mutations(baseline: dict):
    """(description, mutated copy) for each figure of each entry: NaN, inf, a string, gone."""
    for mode in ("quick", "full"):
        for kind, figure in (("coverage", "mean"), ("speed", "ratio")):
            for key in baseline[mode][kind]:
                for label, value in (
                    ("nan", math.nan),
                    ("inf", math.inf),
                    ("string", "0.9"),
                    ("missing", None),
                ):
                    b = copy.deepcopy(baseline)
                    if value is None:
                        del b[mode][kind][key][figure]
                    else:
                        b[mode][kind][key][figure] = value
                    yield f"{mode}/{kind}/{key}/{figure}={label}", key, b


def test_every_broken_figure_of_the_baseline_fails(tmp_path):
    baseline = json.loads(regress_cmd.BASELINE_FILE.read_text())
    cases = list(_mutations(baseline))
    assert len(cases) >= 4 * (len(baseline["quick"]["coverage"]) + len(baseline["quick"]["speed"]))
    for what, key, mutated in cases:
        path = tmp_path / "b.json"
        # json.dumps writes NaN and Infinity as json.loads reads them back
        path.write_text(json.dumps(mutated))
        with pytest.raises(regress_cmd.InputError) as err:
            regress_cmd.load_baseline(path)
        assert key in str(err.value), what


def test_the_committed_baseline_passes_the_check():
    regress_cmd.load_baseline(regress_cmd.BASELINE_FILE)  # raises if broken


def test_regress_exits_2_on_a_nan_baseline_before_measuring(tmp_path, capsys):
    baseline = json.loads(regress_cmd.BASELINE_FILE.read_text())
    key = next(iter(baseline["quick"]["coverage"]))
    baseline["quick"]["coverage"][key]["mean"] = math.nan
    path = tmp_path / "nan.json"
    path.write_text(json.dumps(baseline))
    line = one_error(["regress", "--quick", "--baseline", path, "--quiet"], capsys)
    assert key in line and "'mean' is nan, not a finite number" in line


def test_a_nan_measurement_is_refused():
    with pytest.raises(regress_cmd.InputError, match="'ours/numpy/square'.*'mean' is nan"):
        regress_cmd.check_figures({"coverage": {"ours/numpy/square": {"mean": math.nan}}}, "measured")
    with pytest.raises(regress_cmd.InputError, match="'ratio' is missing"):
        regress_cmd.check_figures({"speed": {"a vs b": {"ms": 1.0}}}, "measured")
    regress_cmd.check_figures({"coverage": {"k": {"mean": 0.5, "values": [0.5]}}, "speed": {}}, "ok")


def test_a_stored_run_with_a_nan_figure_is_not_read_back(tmp_path):
    from compact_distributions.bench.sweep import made_by, read_stored

    path = tmp_path / "run.json"
    good = {"row": {"coverage": 0.7, "overlap": 0.0, "final_energy": None}, "made_by": made_by()}
    path.write_text(json.dumps(good))
    assert read_stored(path) == good["row"]
    for bad in (math.nan, math.inf):
        path.write_text(json.dumps({**good, "row": {**good["row"], "coverage": bad}}))
        assert read_stored(path) is None


def test_table2_never_makes_a_row_of_a_nan_coverage():
    from compact_distributions.bench.runs import RunSpec
    from compact_distributions.bench.table2 import aggregate

    spec = RunSpec("t", "ours", "numpy", "square", 32, 32, 8, 1, 0)
    ok = {
        "key": spec.key,
        **spec.params(),
        "status": "ok",
        "reason": "",
        "device": "cpu",
        "coverage": 0.8,
        "overlap": 0.0,
        "method_seconds": 1.0,
        "lloyd_seconds": 0.5,
        "ms_per_iteration": 1.0,
        "placed": 8,
        "empty_cells": 0,
    }
    line = aggregate([ok, {**ok, "seed": 1, "coverage": np.nan}]).iloc[0]
    assert line["coverage_mean"] == pytest.approx(0.8) and line["runs"] == 1 and line["status"] == "partial"
    assert "not a finite number" in line["reason"]
    only_nan = aggregate([{**ok, "coverage": np.nan}]).iloc[0]
    assert only_nan["status"] == "failed" and np.isnan(only_nan["coverage_mean"])


@pytest.mark.slow
def test_an_oversized_init_file_is_refused_in_seconds_and_little_memory(tmp_path):
    """Ten million sites under a 3 GB limit: the raster fits, the sites do not.  The file
    is sized by a streamed row count and refused before any row is parsed."""
    from compact_distributions.bench.commands.pipeline import run_measured

    path = tmp_path / "big.csv"
    rows = 10_000_000
    with open(path, "wb") as fh:
        fh.write(b"x,y\n")
        block = b"1.5,2.5\n" * 100_000
        for _ in range(rows // 100_000):
            fh.write(block)
    out = tmp_path / "o"
    code, err, seconds, peak = run_measured(
        [
            "-m",
            "compact_distributions.bench.commands.cli",
            "run",
            "--size",
            "4096",
            "--init",
            str(path),
            "--memory-limit",
            "3G",
            "--out",
            str(out),
        ]
    )
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert "more than the limit --memory-limit sets (3 GiB)" in lines[0], lines[0]
    assert seconds < 5 and peak < 300 * 2**20, (seconds, peak / 2**20)
    assert not out.exists()


def test_json_inputs_are_sized_before_they_are_parsed(tmp_path, monkeypatch):
    from compact_distributions.bench import sweep
    from compact_distributions.cvt import validate

    path = tmp_path / "b.json"
    path.write_text(json.dumps({"quick": {"coverage": {}, "speed": {}}, "pad": "x" * 4000}))
    assert regress_cmd.load_baseline(path)["quick"] == {"coverage": {}, "speed": {}}
    with pytest.raises(validate.InputError, match="more than the 0 MiB"):
        validate.json_object(path, "regression baseline", max_bytes=1000)
    stored = tmp_path / "run.json"
    stored.write_text(json.dumps({"row": {"coverage": 0.5}, "made_by": sweep.made_by()}))
    assert sweep.read_stored(stored) == {"coverage": 0.5}
    monkeypatch.setattr(sweep, "STORED_MAX_BYTES", 10)
    assert sweep.read_stored(stored) is None
