"""Fail closed wherever a result is judged: stored runs read back and Table 2's
aggregation never pass or report a figure that is missing or not finite (the regression
guard's baseline: tests/test_regress.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from compact_distributions.bench.commands import regress as regress_cmd


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
    empty = {"measures": {}, "speed": {}}
    path.write_text(json.dumps({"format": regress_cmd.FORMAT, "quick": empty, "pad": "x" * 4000}))
    assert regress_cmd.load_baseline(path)["quick"] == empty
    with pytest.raises(validate.InputError, match="more than the 0 MiB"):
        validate.json_object(path, "regression baseline", max_bytes=1000)
    stored = tmp_path / "run.json"
    stored.write_text(json.dumps({"row": {"coverage": 0.5}, "made_by": sweep.made_by()}))
    assert sweep.read_stored(stored) == {"coverage": 0.5}
    monkeypatch.setattr(sweep, "STORED_MAX_BYTES", 10)
    assert sweep.read_stored(stored) is None
