"""bench/: the sweep engine (resume, interrupt, failures) and the reports (aggregation by
hand, the committed files complete); the regression guard is tested in test_regress.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from compact_distributions.bench import sweep
from compact_distributions.bench.commands.cli import main
from compact_distributions.bench.report import git_commit
from compact_distributions.bench.runs import RunSpec, effect_picture
from compact_distributions.bench.sweep import run_sweep

ROOT = Path(__file__).resolve().parent.parent
REPORTS = ROOT / "reports"


def tiny(seed=0, suite="t", method="ours", element="square", picture=False):
    return RunSpec(suite, method, "numpy", element, 64, 64, 20, 3, seed, picture=picture)


# ---------------------------------------------------------------------------------------
# the sweep engine


def test_run_row_has_coverage_from_placement(tmp_path):
    rows = run_sweep([tiny(picture=True)], tmp_path, quiet=True)
    (row,) = rows
    assert row["status"] == "ok", row
    assert 0.3 < row["coverage"] <= 1.0 and row["placed"] + row["skipped"] == 20
    raw = json.loads(sweep.raw_path(tmp_path, tiny()).read_text())
    assert raw["row"]["coverage"] == row["coverage"] and len(raw["sites"]) == 20
    assert sweep.picture_path(tmp_path, tiny()).exists()


def test_sweep_resumes_and_force_reruns(tmp_path, monkeypatch):
    specs = [tiny(0), tiny(1)]
    first = run_sweep(specs, tmp_path, quiet=True)
    calls = []
    real = sweep.execute
    monkeypatch.setattr(sweep, "execute", lambda *a, **k: calls.append(1) or real(*a, **k))
    again = run_sweep(specs, tmp_path, quiet=True)
    assert calls == [] and all(r.get("cached") for r in again)
    assert [r["coverage"] for r in again] == [r["coverage"] for r in first]
    run_sweep(specs, tmp_path, force=True, quiet=True)
    assert len(calls) == 2


def test_runs_stored_by_other_code_or_host_are_recomputed(tmp_path, monkeypatch):
    spec = tiny(0)
    run_sweep([spec], tmp_path, quiet=True)
    path = sweep.raw_path(tmp_path, spec)
    stored = json.loads(path.read_text())
    assert stored["made_by"] == sweep.made_by()
    stored["made_by"] = {"code": "0123456789abcdef", "host": stored["made_by"]["host"]}
    path.write_text(json.dumps(stored))
    calls = []
    real = sweep.execute
    monkeypatch.setattr(sweep, "execute", lambda *a, **k: calls.append(1) or real(*a, **k))
    (row,) = run_sweep([spec], tmp_path, quiet=True)
    assert calls == [1] and not row.get("cached")
    assert json.loads(path.read_text())["made_by"] == sweep.made_by()


def test_interrupt_keeps_finished_runs_only(tmp_path, monkeypatch):
    real = sweep.execute
    done = []

    def flaky(spec, *a, **k):
        if done:
            raise KeyboardInterrupt
        done.append(spec.key)
        return real(spec, *a, **k)

    monkeypatch.setattr(sweep, "execute", flaky)
    with pytest.raises(KeyboardInterrupt):
        run_sweep([tiny(0), tiny(1)], tmp_path, quiet=True)
    files = sorted(p.name for p in (tmp_path / "raw" / "t").iterdir())
    assert files == [f"{tiny(0).key}.json"]  # no temp file, no json of the interrupted run


def test_unavailable_and_failing_runs_become_rows(tmp_path, monkeypatch):
    rows = run_sweep([tiny(0)], tmp_path, quiet=True, unavailable={"numpy": "no reason at all"})
    assert rows[0]["status"] == "skipped" and rows[0]["reason"] == "no reason at all"

    def broken(*a, **k):
        raise RuntimeError("kaputt")

    monkeypatch.setattr(RunSpec, "execute", broken)
    rows = run_sweep([tiny(1)], tmp_path, quiet=True)
    assert rows[0]["status"] == "failed" and "kaputt" in rows[0]["reason"]
    assert not sweep.raw_path(tmp_path, tiny(1)).exists()  # retried next time


def test_git_commit_outside_a_repository(tmp_path):
    assert git_commit(tmp_path) == "unknown"
    here = git_commit()
    assert here == "unknown" or len(here.split()[0]) == 40


# ---------------------------------------------------------------------------------------
# committed reports are the output of the committed code


def _committed(name):
    path = REPORTS / name
    if not path.exists():
        pytest.fail(f"{path} is not committed; run `cvtbench reproduce` (and --quick)")
    return pd.read_csv(path)


def test_table2_aggregates_seeds_by_hand(tmp_path):
    from compact_distributions.bench.table2 import aggregate

    rows = [
        {
            **tiny(seed).params(),
            "key": tiny(seed).key,
            "status": "ok",
            "reason": "",
            "device": "cpu",
            "coverage": c,
            "overlap": o,
            "method_seconds": t,
            "lloyd_seconds": t / 2,
            "ms_per_iteration": 1.0,
            "placed": 20,
            "empty_cells": 0,
        }
        for seed, (c, o, t) in enumerate([(0.70, 0.0, 1.0), (0.80, 0.02, 3.0)])
    ]
    rows.append({**tiny(2).params(), "key": tiny(2).key, "status": "failed", "reason": "boom"})
    (line,) = aggregate(rows).to_dict("records")
    assert line["coverage_mean"] == pytest.approx(0.75) and line["overlap_mean"] == pytest.approx(0.01)
    assert line["coverage_sd"] == pytest.approx(np.sqrt(0.005))  # sample sd of 0.70, 0.80
    assert line["method_seconds_mean"] == pytest.approx(2.0)
    assert line["lloyd_seconds_mean"] == pytest.approx(1.0)
    assert (
        line["runs"] == 2 and line["seeds"] == 3 and line["status"] == "partial" and "boom" in line["reason"]
    )


def test_table2_quick_writes_its_report(tmp_path):
    code = main(
        [
            "table2",
            "--quick",
            "--methods",
            "ours",
            "--backends",
            "numpy",
            "--shapes",
            "square,circle",
            "--seeds",
            "1",
            "--out",
            str(tmp_path),
            "--quiet",
        ]
    )
    assert code == 0
    new = pd.read_csv(tmp_path / "table2.csv")
    assert list(new.columns) == list(_committed("quick/table2.csv").columns)
    assert sorted(new.element) == ["circle", "square"] and (new.runs == 1).all()
    assert (tmp_path / "table2.md").read_text().count("QUICK") >= 1 and (tmp_path / "table2.png").exists()


def test_committed_table2_covers_every_method_and_backend():
    from compact_distributions.baselines import method_names
    from compact_distributions.bench.table2 import problem_set, sweep_backends, variant_backend

    variants, _ = sweep_backends(None)
    for name, quick in (("table2.csv", False), ("quick/table2.csv", True)):
        table = _committed(name)
        # ours' variants ran on OpenCL where the reports were made if it ran there (its
        # rows are "ok"), whether or not it runs here
        ran = bool(((table.backend == "opencl") & (table.status == "ok")).any())
        where = variant_backend({} if ran else {"opencl": "it did not run where the reports were made"})
        expected = {
            (s.label, s.backend, s.element)
            for s in problem_set(quick, 1, method_names(), variants, variant_backend=where)
        }
        have = set(zip(table.method, table.backend, table.element, strict=True))
        assert expected <= have, f"reports/{name} lacks {sorted(expected - have)}: regenerate it"
        ok = table[table.status == "ok"]
        assert ((ok.coverage_mean > 0) & (ok.coverage_mean <= 1)).all()


def test_backends_quick_rerun_matches_committed_columns(tmp_path):
    code = main(
        [
            "backends",
            "--quick",
            "--backends",
            "numpy,ckdtree",
            "--metrics",
            "l2",
            "--elements",
            "300",
            "--sizes",
            "96",
            "--repeats",
            "1",
            "--out",
            str(tmp_path),
            "--quiet",
        ]
    )
    assert code == 0
    new = pd.read_csv(tmp_path / "backends.csv")
    assert list(new.columns) == list(_committed("quick/backends.csv").columns)
    assert set(new.backend) == {"numpy", "ckdtree"} and (new.ms_per_iteration > 0).all()
    assert new.loc[new.backend == "numpy", "x_numpy"].iloc[0] == pytest.approx(1.0)
    full = _committed("backends.csv")
    assert {1000, 4000, 16000} <= set(full.n_elements) and {512, 1024, 2048} <= set(full["size"])
    assert set(full.metric) == {"l2", "l1", "linf", "linf-axial", "l2-axial", "triangle"}


@pytest.mark.parametrize(
    "argv, text",
    [
        (["table2", "--seeds", "0"], "--seeds"),
        (["table2", "--backends", "cuda"], "cuda"),
        (["table2", "--shapes", "heptagon"], "heptagon"),
        (["backends", "--sizes", "big"], "--sizes"),
        (["regress", "--quick", "--methods", "magic"], "magic"),
    ],
)
def test_bad_bench_options_are_one_line_errors(argv, text, capsys, tmp_path):
    assert main(argv + ["--out", str(tmp_path)] if argv[0] != "regress" else argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and text in err


def test_reproduce_hands_each_part_a_typed_request(tmp_path):
    import argparse

    from compact_distributions.bench.commands.backends import BackendsRequest, backends
    from compact_distributions.bench.commands.converge import ConvergeRequest
    from compact_distributions.bench.commands.figures import FiguresRequest
    from compact_distributions.bench.commands.pipeline import PipelineRequest
    from compact_distributions.bench.commands.reproduce import requests
    from compact_distributions.bench.table2 import Table2Request, table2
    from compact_distributions.bench.table3 import Table3Request

    args = argparse.Namespace(
        quick=True, force=False, quiet=True, memory_limit="2G", seeds="3", exclusive=True
    )
    parts = requests(args, tmp_path, "tcp://127.0.0.1:1")
    assert [(name, type(req)) for name, _, req in parts] == [
        ("table2", Table2Request),
        ("table3", Table3Request),
        ("backends", BackendsRequest),
        ("pipeline", PipelineRequest),
        ("converge", ConvergeRequest),
        ("figures", FiguresRequest),
    ]
    t2, t3, bk, _, cv, fig = (req for _, _, req in parts)
    assert (cv.out, cv.quick, cv.memory_limit) == (tmp_path, True, "2G")
    assert (t3.seeds, t3.quick, t3.scheduler) == (3, True, "tcp://127.0.0.1:1")
    assert parts[0][1] is table2 and parts[2][1] is backends
    assert (t2.out, t2.seeds, t2.exclusive, t2.scheduler, t2.memory_limit) == (
        tmp_path,
        3,
        True,
        "tcp://127.0.0.1:1",
        "2G",
    )
    assert (bk.out, bk.quick, bk.exclusive, bk.scheduler) == (tmp_path, True, False, "tcp://127.0.0.1:1")
    assert fig.out == tmp_path / "figures" and fig.quick
    assert t2.command == f"cvtbench table2 --quick --out {tmp_path}"


def test_a_typed_request_is_checked_like_the_command_line(tmp_path):
    from compact_distributions.bench.table2 import Table2Request, prepare
    from compact_distributions.cvt.errors import InputError

    with pytest.raises(InputError, match="--methods"):
        prepare(Table2Request(out=tmp_path, quick=True, methods=("nosuch",)))
    with pytest.raises(InputError, match="--delta is an option of none of --methods ours"):
        prepare(Table2Request(out=tmp_path, quick=True, methods=("ours",), method_options={"delta": 0.9}))
    plan = prepare(
        Table2Request(
            out=tmp_path,
            quick=True,
            seeds=1,
            methods=("ours", "hausner2001"),
            backends=("numpy",),
            shapes=("square",),
        )
    )
    assert [(s.label, s.backend, s.element) for s in plan["specs"]] == [
        ("ours", "numpy", "square"),
        ("hausner2001", "numpy", "square"),
        ("hausner2001 δ=0.85", "numpy", "square"),
        ("hausner2001 δ=0.8", "numpy", "square"),
    ]


def test_effect_picture_draws_elements():
    import shapely

    from compact_distributions.cvt.problem import Grid

    img = effect_picture([shapely.box(0, 0, 16, 16), None], Grid(32, 32), side=64, crop=1.0)
    a = np.asarray(img)
    assert a.shape == (64, 64, 3)
    assert a[5, 5].sum() > a[50, 50].sum()  # the box is drawn, the rest is background


def test_backend_timings_are_read_back_only_when_this_code_made_them(tmp_path, monkeypatch):
    from compact_distributions.bench.commands import backends as backends_cmd

    spec = backends_cmd.TimingSpec("t", "numpy", "l2", 40, 64, 0, 1)
    calls = []
    real = backends_cmd.time_lloyd
    monkeypatch.setattr(backends_cmd, "time_lloyd", lambda *a, **k: calls.append(1) or real(*a, **k))
    run_sweep([spec], tmp_path, quiet=True)
    (again,) = run_sweep([spec], tmp_path, quiet=True)
    assert calls == [1] and again.get("cached")
    path = tmp_path / "raw" / "t" / f"{spec.key}.json"
    stored = json.loads(path.read_text())
    stored["made_by"] = {"code": "0123456789abcdef", "host": "elsewhere"}
    path.write_text(json.dumps(stored))
    (fresh,) = run_sweep([spec], tmp_path, quiet=True)
    assert calls == [1, 1] and not fresh.get("cached")
