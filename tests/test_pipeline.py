"""`cvtbench pipeline`: the whole command timed and measured stage by stage."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from compact_distributions.bench.commands.cli import main
from compact_distributions.bench.commands.pipeline import growth_exponent, raster_side, run_measured


def test_growth_exponent_by_hand():
    n = np.array([1000, 4000, 16000])
    assert growth_exponent(n, 3e-4 * n) == pytest.approx(1.0)
    assert growth_exponent(n, 2e-9 * n**2) == pytest.approx(2.0)
    assert np.isnan(growth_exponent(n, [np.nan, 1.0, np.nan]))  # one point has no slope


def test_raster_grows_with_n():
    assert [raster_side(n) for n in (1000, 4000, 16000, 64000)] == [512, 1024, 2048, 4096]


def test_peak_memory_is_the_child_process_own():
    ballast = bytearray(400 * 2**20)  # this process is large: a forked child's rusage would count it
    ballast[::4096] = b"1" * len(ballast[::4096])
    code, _, seconds, peak = run_measured(
        ["-c", "x = bytearray(300 * 2**20); x[::4096] = b'1' * len(x[::4096])"]
    )
    assert code == 0 and seconds > 0
    assert 300 * 2**20 < peak < 360 * 2**20
    code, _, _, small = run_measured(["-c", "pass"])
    assert code == 0 and 0 < small < 60 * 2**20
    assert run_measured(["-c", "raise SystemExit(3)"])[0] == 3
    del ballast


def test_pipeline_report_of_tiny_runs(tmp_path):
    code = main(
        [
            "pipeline",
            "--workloads",
            "ours-compact",
            "--backends",
            "numpy",
            "--elements",
            "64,256",
            "--out",
            str(tmp_path),
            "--quiet",
        ]
    )
    assert code == 0
    table = pd.read_csv(tmp_path / "pipeline.csv")
    assert list(table["n_elements"]) == [64, 256] and (table["status"] == "ok").all()
    stages = table[
        [c for c in table.columns if c.endswith("_seconds") and c not in ("whole_seconds", "method_seconds")]
    ]
    # every stage is part of the whole command, and the method part of it too
    assert (stages.fillna(0).sum(axis=1) <= table["whole_seconds"]).all()
    assert (table["method_seconds"] < table["whole_seconds"]).all() and (table["lloyd_seconds"] > 0).all()
    assert (table["peak_mb"] > 30).all() and (table["coverage"] > 0.8).all()
    assert (tmp_path / "pipeline.png").exists() and "How each stage grows" in (
        tmp_path / "pipeline.md"
    ).read_text()
    assert main(["pipeline", "--elements", "8", "--out", str(tmp_path / "x")]) == 2
    assert not (tmp_path / "x").exists()
