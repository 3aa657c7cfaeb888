"""cvtbench table3: the problem set, the aggregation by hand, a small sweep end to end,
the committed reports, and bad input (one line, exit 2, nothing written)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from compact_distributions.baselines import method_names
from compact_distributions.bench.scenes import SCENES, radial_gradient, scene_problem
from compact_distributions.bench.table3 import (
    COLUMNS,
    aggregate,
    problem_set,
    run_table3,
)
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.evaluate import MEASURES
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.shapes import ELEMENT_SHAPES, PAPER_SHAPES

from .cli_errors import one_error

REPORTS = Path(__file__).resolve().parent.parent / "reports"


def test_the_density_has_the_contrast_it_says_and_regions_hold_their_share():
    d = radial_gradient(200)
    raw = d.values  # normalised to a maximum of 1
    assert raw.max() / raw.min() == pytest.approx(3.0, rel=0.02)
    star = scene_problem("region", 200, 400, make_metric("linf"), 0)
    assert star.n_elements == round(400 * star.grid.pixel_count / 200**2) < 400
    both = scene_problem("combined", 200, 400, make_metric("linf"), 0)
    assert both.density is not None and both.field is not None and both.grid.mask is not None


def test_problem_set_runs_every_method_on_squares_and_the_listed_ones_on_every_shape():
    from compact_distributions.cvt.registry import get_method

    every_shape = [m for m in method_names() if get_method(m).compared_on is None]
    assert {"ours", "ours-compact"} <= set(every_shape)
    specs = problem_set(True, 2, method_names(), list(ELEMENT_SHAPES), list(SCENES), "numpy")
    combos = {(s.scene, s.method, s.element) for s in specs}
    for scene in SCENES:
        assert {(scene, m, "square") for m in method_names()} <= combos
        for shape in ELEMENT_SHAPES:
            assert {(scene, m, shape) for m in every_shape} <= combos
    assert len(combos) == len(SCENES) * (len(method_names()) + len(every_shape) * (len(ELEMENT_SHAPES) - 1))
    assert len(specs) == 2 * len(combos) and len({s.key for s in specs}) == len(specs)
    assert all(s.measures and s.curve for s in specs)


def test_aggregate_by_hand():
    specs = problem_set(True, 3, ["ours"], ["square"], ["density"], "numpy")
    rows = []
    for spec, size_err in zip(specs[:2], (0.2, 0.4), strict=True):
        rows.append(
            {
                "key": spec.key,
                **spec.params(),
                "status": "ok",
                "reason": "",
                "device": "cpu",
                "method_seconds": 1.0,
                "n_elements": 150,
                **{m: 0.5 for m in MEASURES},
                "size_fidelity": size_err,
                "direction_fidelity": None,
            }
        )
    rows.append({"key": specs[2].key, **specs[2].params(), "status": "failed", "reason": "boom"})
    (line,) = aggregate(rows).to_dict("records")
    assert line["size_fidelity_mean"] == pytest.approx(0.3)
    assert line["size_fidelity_sd"] == pytest.approx(np.sqrt(0.02))  # sample sd of 0.2, 0.4
    assert np.isnan(line["direction_fidelity_mean"])  # circles' null stays missing, not 0
    assert (
        line["runs"] == 2 and line["seeds"] == 3 and line["status"] == "partial" and "boom" in line["reason"]
    )


def test_a_small_table3_end_to_end(tmp_path):
    table = run_table3(
        tmp_path,
        quick=True,
        seeds=1,
        methods=["ours", "ours-compact"],
        shapes=["square"],
        scenes=["density", "field"],
        quiet=True,
    )
    assert len(table) == 4 and (table.status == "ok").all()
    csv = pd.read_csv(tmp_path / "table3.csv")
    assert list(csv.columns) == COLUMNS
    text = (tmp_path / "table3.md").read_text()
    assert "QUICK" in text and "size error" in text and (tmp_path / "table3_tradeoff.png").exists()
    field = csv[csv.scene == "field"].set_index("method")
    assert field.loc["ours", "direction_fidelity_mean"] == pytest.approx(0.0, abs=1e-6)
    assert field.loc["ours-compact", "direction_fidelity_mean"] < 2.0
    dens = csv[csv.scene == "density"].set_index("method")
    assert dens.loc["ours-compact", "coverage_mean"] > dens.loc["ours", "coverage_mean"]
    # one Lloyd, so one gap: ours-compact's sites before placement are ours'
    assert 0 < dens.loc["ours", "energy_gap_mean"] == dens.loc["ours-compact", "energy_gap_mean"] < 0.2
    assert "energy above converged" in text


def test_committed_table3_holds_every_run_and_the_compaction_targets():
    for name, quick in (("table3.csv", False), ("quick/table3.csv", True)):
        path = REPORTS / name
        if not path.exists():
            pytest.fail(f"{path} is not committed; run `cvtbench table3` (and --quick)")
        table = pd.read_csv(path)
        expected = {
            (s.scene, s.method, s.element)
            for s in problem_set(quick, 1, method_names(), list(PAPER_SHAPES), list(SCENES), "numpy")
        }
        assert expected <= set(zip(table.scene, table.method, table.element, strict=True))
        assert (table.status == "ok").all()
    full = pd.read_csv(REPORTS / "table3.csv")
    sq = full[full.element == "square"].set_index(["scene", "method"])
    ours, compact = sq.loc[("density", "ours")], sq.loc[("density", "ours-compact")]
    assert compact.size_fidelity_mean <= 1.1 * ours.size_fidelity_mean
    others = sq.loc["density"].drop(index="ours-compact")
    assert compact.coverage_mean > others.coverage_mean.max()
    assert (full[full.method == "ours-compact"].direction_fidelity_mean.dropna() < 2.0).all()


@pytest.mark.parametrize(
    "argv, text",
    [
        (["--seeds", "0"], "--seeds"),
        (["--seeds", "many"], "--seeds"),
        (["--methods", "magic"], "magic"),
        (["--shapes", "heptagon"], "heptagon"),
        (["--scenes", "moon"], "moon"),
        (["--scenes", ","], "--scenes"),
        (["--memory-limit", "1K"], "memory"),
        (["--workers", "0"], "--workers"),
        (["--tolerance", "2"], "--tolerance"),
        (["--methods", "hu2016", "--accelerate"], "--accelerate is an option of none of --methods hu2016"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(argv, text, capsys, tmp_path):
    out = tmp_path / "out"
    line = one_error(["table3", "--quick", "--out", out, *argv], capsys)
    assert text in line
    assert not out.exists()


def test_an_output_that_is_a_file_is_refused(capsys, tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    assert "--out" in one_error(["table3", "--quick", "--out", f], capsys)
    assert f.read_text() == "x"


def test_the_typed_function_checks_its_arguments(tmp_path):
    with pytest.raises(InputError, match="heptagon"):
        run_table3(tmp_path / "t", quick=True, shapes=["heptagon"])
    assert not (tmp_path / "t").exists()


def test_a_dask_sweep_gives_the_same_table(tmp_path):
    pytest.importorskip("distributed")
    subset = {
        "quick": True,
        "seeds": 1,
        "methods": ["ours", "hausner2001"],
        "shapes": ["square"],
        "scenes": ["combined"],
        "quiet": True,
    }
    here = run_table3(tmp_path / "here", **subset)
    there = run_table3(tmp_path / "there", workers=1, **subset)
    cols = [f"{m}_mean" for m in MEASURES]
    pd.testing.assert_frame_equal(here[cols], there[cols])
    assert (tmp_path / "there" / "table3.md").exists()


def test_table3_takes_the_lloyd_options_as_table2_does(tmp_path):
    """--tolerance and --accelerate go to the methods that declare them (their runs are
    keyed and labelled by them), not to the others; the command line offers them."""
    from compact_distributions.bench.commands.cli import build_parser
    from compact_distributions.bench.options import given_method_options
    from compact_distributions.bench.table3 import Table3Request, check

    args = build_parser().parse_args(["table3", "--quick", "--tolerance", "1e-4", "--accelerate"])
    assert given_method_options(args) == {"tolerance": "1e-4", "accelerate": True}
    plan = check(
        Table3Request(
            out=tmp_path,
            quick=True,
            seeds=1,
            methods=("ours", "hu2016"),
            shapes=("square",),
            scenes=("density",),
            method_options={"tolerance": "1e-4", "accelerate": True},
        )
    )
    by_method = {s.method: s for s in plan["specs"]}
    assert by_method["ours"].options == (("accelerate", True), ("tolerance", 1e-4))
    assert by_method["ours"].label == "ours tol=0.0001 accelerated"
    assert by_method["ours"].key.endswith("__tol0.0001__acc")
    assert by_method["hu2016"].options == ()
    plain = problem_set(True, 1, ["ours"], ["square"], ["density"], "numpy")
    assert plain[0].options == () and plain[0].key != by_method["ours"].key
