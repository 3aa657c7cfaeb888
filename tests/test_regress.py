"""`cvtbench regress`: its logic on fabricated figures, and end to end on small problems
with a baseline measured now by ``--update`` and then edited by hand.  The truth each
check is held to is the edit (a baseline made better than today must fail, one made
worse must pass), not the figures themselves."""

from __future__ import annotations

import copy
import json
import math
import sys
import xml.etree.ElementTree as ET
from types import SimpleNamespace

import numpy as np
import pytest

from compact_distributions.bench.commands import regress as regress_cmd
from compact_distributions.bench.commands.cli import main
from compact_distributions.cvt.evaluate import MEASURES

from .cli_errors import one_error

R = regress_cmd

# ---------------------------------------------------------------------------------------
# the logic, on fabricated figures


def measure_fig(mean, tol=0.01, better="higher", unit="share"):
    return {"mean": mean, "tolerance": tol, "better": better, "unit": unit}


def test_a_measure_fails_only_when_worse_by_more_than_its_tolerance():
    b = measure_fig(0.80, tol=0.01)
    assert R.judge_measure("measures", "g", "coverage", b, {"mean": 0.795}).status == "pass"
    worse = R.judge_measure("measures", "g", "coverage", b, {"mean": 0.785})
    assert worse.status == "fail" and "1.50 pp worse" in worse.message
    better = R.judge_measure("measures", "g", "coverage", b, {"mean": 0.9})
    assert better.status == "pass" and "run --update" in better.message
    # lower is better: an error that grew fails, one that fell passes
    e = measure_fig(0.40, tol=0.05, better="lower", unit="log2")
    assert R.judge_measure("measures", "g", "size_fidelity", e, {"mean": 0.46}).status == "fail"
    assert R.judge_measure("measures", "g", "size_fidelity", e, {"mean": 0.10}).status == "pass"
    # fail closed: a measurement that is not a number never passes
    assert R.judge_measure("measures", "g", "coverage", b, {"mean": math.nan}).status == "fail"


def test_whole_method_speed_is_machine_independent_and_catches_a_slower_stage():
    base = R.speed_figure([1.3], 1.0, "its Lloyd time")  # Lloyd 1 s, the rest 0.3 s
    # a machine 10x slower: Lloyd 10 s, the rest 3 s: the same ratio
    assert R.judge_speed("speed", "g", R.WHOLE, base, {"ratio": 13.0 / 10.0}).status == "pass"
    # compaction 3x slower on the same machine: the rest 0.9 s
    slow = R.judge_speed("speed", "g", R.WHOLE, base, {"ratio": 1.9})
    assert slow.status == "fail" and "slower" in slow.message
    assert slow.limit == pytest.approx(1 + 2 * 0.3 + R.SPEED_SLACK)
    # noise under the slack on a method with little beyond Lloyd is no regression
    small = R.speed_figure([1.02], 1.0, "its Lloyd time")
    assert R.judge_speed("speed", "g", R.WHOLE, small, {"ratio": 1.06 + R.SPEED_SLACK / 2}).status == "pass"
    # a Lloyd step pair: the plain ratio, 2x
    pair = R.speed_figure([0.1], 0.0, "numpy's step", slack=0.0)
    assert R.judge_speed("speed", "g", R.LLOYD_STEP, pair, {"ratio": 0.19}).status == "pass"
    assert R.judge_speed("speed", "g", R.LLOYD_STEP, pair, {"ratio": 0.21}).status == "fail"


def test_stage_figures_keep_the_fastest_check_and_the_median_baseline():
    samples = [
        {"whole": 1.3, "lloyd": 1.0, "stages": {"fit": 0.1, "compaction": 0.2, "lloyd": 1.0}},
        {"whole": 2.6, "lloyd": 2.0, "stages": {"fit": 0.3, "compaction": 0.4}},
        {"whole": 5.0, "lloyd": 4.0, "stages": {"fit": 0.8, "compaction": 1.2}},
    ]
    check = R.timing_figures(samples, R.WHOLE, spread=False)
    assert set(check) == {R.WHOLE, "fit time", "compaction time"}  # lloyd is the denominator
    assert check["fit time"]["ratio"] == pytest.approx(0.1) and check["compaction time"]["floor"] == 0.0
    assert check[R.WHOLE]["ratio"] == pytest.approx(1.25) and check[R.WHOLE]["floor"] == 1.0
    base = R.timing_figures(samples, R.WHOLE, spread=True)
    assert base["fit time"]["ratio"] == pytest.approx(0.15) and base[R.WHOLE]["ratio"] == pytest.approx(1.3)
    # a fit three times slower fails, the same fit on a machine twice as slow does not
    assert R.judge_speed("speed", "g", "fit time", base["fit time"], {"ratio": 0.45}).status == "fail"
    assert R.judge_speed("speed", "g", "fit time", base["fit time"], {"ratio": 0.30 / 2.0}).status == "pass"


def test_compare_reports_new_and_unmeasured_groups_without_failing():
    base = {
        "measures": {
            "a": {"figures": {"coverage": measure_fig(0.8)}},
            "gone": {"figures": {"coverage": measure_fig(0.8)}},
        }
    }
    cur = {
        "measures": {
            "a": {"figures": {"coverage": {"mean": 0.8}, "overlap": {"mean": 0.0}}},
            "plugin": {"figures": {"coverage": {"mean": 0.5}}},
        },
        "unavailable": {"gone": "no EGL"},
    }
    checks = {c.name: c for c in R.compare(base, cur)}
    assert checks["a: coverage"].status == "pass"
    assert checks["a: overlap"].status == "new" and checks["plugin: coverage"].status == "new"
    assert checks["gone: coverage"].status == "not checked" and checks["gone: coverage"].message == "no EGL"
    failed = R.compare(base, {"measures": {"a": {"failed": "ValueError: x", "figures": {}}}})
    assert [c.status for c in failed if c.group == "a"] == ["fail"]


def test_merge_keeps_groups_not_measured_now_and_those_that_failed():
    base = {"measures": {"a": {"figures": {"coverage": measure_fig(0.8)}}, "b": {"figures": {}}}, "speed": {}}
    cur = {
        "measures": {"a": {"figures": {"coverage": measure_fig(0.9)}}, "b": {"failed": "x", "figures": {}}}
    }
    merged = R.merge(base, cur)
    assert merged["measures"]["a"]["figures"]["coverage"]["mean"] == 0.9
    assert merged["measures"]["b"] == {"figures": {}}


def test_tolerance_comes_from_the_spread_over_seeds():
    by_seed = {0: 0.70, 1: 0.72, 2: 0.74, 3: 0.71, 4: 0.73}
    fig = R.figure_of(by_seed, [0, 1], "share", "higher", spread=True)
    sd = float(np.std(list(by_seed.values()), ddof=1))
    assert fig["mean"] == pytest.approx(0.71) and fig["sd"] == pytest.approx(sd)
    assert fig["tolerance"] == pytest.approx(R.SPREAD_Z * sd / math.sqrt(2))
    flat = R.figure_of({0: 0.0, 1: 0.0, 2: 0.0}, [0, 1], "share", "lower", spread=True)
    assert flat["tolerance"] == R.RESOLUTION["share"]  # never 0: rounding is no regression
    assert R.figure_of({0: math.nan, 1: math.nan}, [0], "degrees", "lower", True) is None  # circles


def test_every_guarded_measure_is_one_of_the_measures():
    assert set(R.GUARDED) <= set(MEASURES)
    assert all(MEASURES[m][1] in R.RESOLUTION for m in R.GUARDED)


def test_junit_of_fabricated_checks_parses():
    checks = [
        R.Check("measures", "m/numpy/square/s", "coverage", "pass", "ok <&>", 0.8, 0.8, 0.79),
        R.Check("measures", "m/numpy/square/s", "overlap", "fail", "worse", 0.1, 0.0, 0.002),
        R.Check("speed", "p/numpy/square/s", R.WHOLE, "new", "not in the baseline"),
    ]
    root = ET.fromstring(R.junit_xml(checks, "quick", 1.0))
    suite = root.find("testsuite")
    assert suite.get("tests") == "3" and suite.get("failures") == "1" and suite.get("skipped") == "1"
    assert [c.get("name") for c in suite.iter("testcase")] == [c.name for c in checks]
    assert "worse" in suite.find("testcase/failure").get("message")


# ---------------------------------------------------------------------------------------
# end to end on small problems


# 45 elements (28 in the ring): with 40, ours-compact's size error on the 25 in the ring
# spread so over seeds 0-2 (0.48, 0.26, 0.44) that its tolerance exceeded a 1.5x edit
TINY = {
    "runs": {
        "scene": "combined",
        "size": 96,
        "n_elements": 45,
        "iterations": 8,
        "seeds": [0, 1],
        "spread_seeds": 3,
    },
    "mosaic": {"picture": "small.png", "n_elements": 60, "iterations": 8, "seeds": [0], "spread_seeds": 3},
    "speed": {"size": 128, "n_elements": 200, "metrics": ["l2"], "warmup": 1, "repeats": 2},
}
SUBSET = ["--methods", "ours-compact", "--shapes", "square", "--backends", "numpy", "--quiet"]
RUN = "ours-compact/numpy/square/combined"
MOSAIC = "mosaic small.png/ours-compact/numpy/square"


@pytest.fixture
def tiny(monkeypatch):
    monkeypatch.setitem(R.SETS, "quick", TINY)


@pytest.fixture(scope="module")
def today(tmp_path_factory):
    """A baseline of ours-compact on squares and the mosaic, measured now."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(R.SETS, "quick", TINY)
        path = tmp_path_factory.mktemp("regress") / "today.json"
        assert main(["regress", "--quick", "--update", "--baseline", str(path), *SUBSET]) == 0
    return json.loads(path.read_text())


def edited(today: dict, tmp_path, factor: float, name: str = "edited.json"):
    """``today`` with the five guarded figures of the issue made better (factor < 1) or
    worse (> 1): coverage 5 points, ours-compact's whole-method ratio 3x, its size error
    1.5x, the mosaic's colour error 1.5x and its whole time 3x.  Every other speed
    figure is made 10x slower, so that timing noise cannot add a failure."""
    data = copy.deepcopy(today)
    q = data["quick"]
    for group in q["speed"].values():
        for fig in group["figures"].values():
            fig["ratio"] *= 10
    better = factor < 1
    q["measures"][RUN]["figures"]["coverage"]["mean"] += 0.05 if better else -0.05
    q["measures"][RUN]["figures"]["size_fidelity"]["mean"] *= 1 / 1.5 if better else 1.5
    q["measures"][MOSAIC]["figures"]["colour_error"]["mean"] *= 1 / 1.5 if better else 1.5
    for group, measure in ((RUN, R.WHOLE), (MOSAIC, R.MOSAIC_WHOLE)):
        fig = q["speed"][group]["figures"][measure]
        fig["ratio"] = today["quick"]["speed"][group]["figures"][measure]["ratio"] * (1 / 3 if better else 3)
    path = tmp_path / name
    path.write_text(json.dumps(data))
    return path


EDITED = [
    f"{RUN}: coverage",
    f"{RUN}: size_fidelity",
    f"{RUN}: {R.WHOLE}",
    f"{MOSAIC}: colour_error",
    f"{MOSAIC}: {R.MOSAIC_WHOLE}",
]


def test_the_premises_of_the_edits(today):
    """The edits are larger than the tolerances the spread over seeds gave (else the
    test below would say nothing)."""
    figs = today["quick"]["measures"]
    assert figs[RUN]["figures"]["coverage"]["tolerance"] < 0.05
    size = figs[RUN]["figures"]["size_fidelity"]
    assert size["mean"] / 3 > size["tolerance"]
    colour = figs[MOSAIC]["figures"]["colour_error"]
    assert colour["mean"] / 3 > colour["tolerance"]


def test_a_better_baseline_fails_once_per_edited_check(today, tmp_path, tiny, capsys, monkeypatch):
    path = edited(today, tmp_path, factor=0.5)
    junit, report, summary = (
        tmp_path / "r" / "regress.xml",
        tmp_path / "r" / "regress.json",
        tmp_path / "summary.md",
    )
    summary.write_text("earlier step\n")
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(summary))
    argv = [
        "regress",
        "--quick",
        "--baseline",
        str(path),
        *SUBSET,
        "--junit",
        str(junit),
        "--json",
        str(report),
    ]
    assert main(argv) == 1
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("REGRESSION: ")]
    assert len(lines) == len(EDITED), err
    for name in EDITED:  # one line per check, naming ours-compact and the measure
        assert sum(line.startswith(f"REGRESSION: {name}: ") for line in lines) == 1, (name, err)
    assert all("ours-compact" in line for line in lines)

    # JUnit: every check a test case, the five failures with their figures
    root = ET.parse(junit).getroot()
    cases = list(root.iter("testcase"))
    failed = {c.get("name"): c.find("failure") for c in cases if c.find("failure") is not None}
    doc = json.loads(report.read_text())
    assert len(cases) == doc["counts"]["checks"] == len(doc["checks"]) >= 20
    assert int(root.find("testsuite").get("tests")) == len(cases)
    assert sorted(failed) == sorted(EDITED) and int(root.find("testsuite").get("failures")) == 5
    assert all("current" in f.text and "baseline" in f.text for f in failed.values())
    assert {c["name"] for c in doc["checks"] if c["status"] == "fail"} == set(EDITED) and not doc["passed"]
    # GitHub's job summary: appended, the verdict and the failures
    md = summary.read_text()
    assert md.startswith("earlier step\n") and "FAIL" in md and f"{RUN}: coverage" in md


def test_a_worse_baseline_passes(today, tmp_path, tiny, capsys):
    path = edited(today, tmp_path, factor=2)
    junit = tmp_path / "regress.xml"
    assert main(["regress", "--quick", "--baseline", str(path), *SUBSET, "--junit", str(junit)]) == 0
    assert "no regression" in capsys.readouterr().out
    root = ET.parse(junit).getroot()
    assert root.find("testsuite").get("failures") == "0" and len(list(root.iter("testcase"))) >= 20


def test_regress_without_the_mosaic_or_speed_leaves_their_checks_out(today, tmp_path, tiny, capsys):
    path = edited(today, tmp_path, factor=0.5)
    report = tmp_path / "r.json"
    argv = [
        "regress",
        "--quick",
        "--baseline",
        str(path),
        *SUBSET,
        "--no-mosaic",
        "--no-speed",
        "--json",
        str(report),
    ]
    assert main(argv) == 1
    failing = {c["name"] for c in json.loads(report.read_text())["checks"] if c["status"] == "fail"}
    assert failing == {f"{RUN}: coverage", f"{RUN}: size_fidelity"}


# ---------------------------------------------------------------------------------------
# a plug-in method installed beside the suite

PLUGIN = '''
"""A method of another distribution: ours, every element shrunk to 90 %."""
import shapely

from compact_distributions.cvt.methods import Method
from compact_distributions.cvt.placement.ours import run_ours


def run(problem, backend, **options):
    dist = run_ours(problem, backend, **options)
    dist.elements = [None if p is None else shapely.affinity.scale(p, 0.9, 0.9, origin="centroid")
                     for p in dist.elements]
    dist.method = "regress-plugin"
    return dist


METHOD = Method("regress-plugin", run, summary="ours, shrunk")
'''


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """The plug-in installed in a folder on sys.path (its module and the .dist-info that
    declares its entry point, as pip leaves them), the registry made to look again."""
    from compact_distributions.cvt import registry

    site = tmp_path / "site"
    info = site / "cvt_regress_plugin-0.0.1.dist-info"
    info.mkdir(parents=True)
    (site / "cvt_regress_plugin.py").write_text(PLUGIN)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: cvt-regress-plugin\nVersion: 0.0.1\n")
    (info / "entry_points.txt").write_text(
        "[compact_distributions.methods]\nregress-plugin = cvt_regress_plugin:METHOD\n"
    )
    monkeypatch.syspath_prepend(str(site))
    registry.reload()
    assert "regress-plugin" in registry.method_names()

    def uninstall():
        if str(site) in sys.path:
            sys.path.remove(str(site))
        registry.reload()

    yield SimpleNamespace(name="regress-plugin", uninstall=uninstall)
    uninstall()


def test_a_plugin_is_new_until_update_then_guarded(today, plugin, tmp_path, tiny, capsys):
    name = plugin.name
    path = tmp_path / "b.json"
    path.write_text(json.dumps(today))
    report = tmp_path / "r.json"
    argv = ["regress", "--quick", "--baseline", str(path), "--methods", name, "--backends", "numpy"]
    argv += ["--no-mosaic", "--no-speed", "--quiet", "--json", str(report)]
    group = f"{name}/numpy/square/combined"

    def statuses():
        return {
            c["name"]: c["status"] for c in json.loads(report.read_text())["checks"] if c["group"] == group
        }

    assert main(argv) == 0
    assert f"note: new: {group}: coverage" in capsys.readouterr().out
    assert set(statuses().values()) == {"new"} and len(statuses()) == 4
    assert main([*argv[:-2], "--update"]) == 0
    stored = json.loads(path.read_text())["quick"]["measures"]
    assert group in stored and RUN in stored  # the built-in groups are kept
    assert main(argv) == 0
    assert set(statuses().values()) == {"pass"}
    data = json.loads(path.read_text())
    data["quick"]["measures"][group]["figures"]["coverage"]["mean"] += 0.05
    path.write_text(json.dumps(data))
    capsys.readouterr()
    assert main(argv) == 1
    assert f"REGRESSION: {group}: coverage" in capsys.readouterr().err
    # uninstalled: its checks are reported as not checked, with the reason
    plugin.uninstall()
    argv = ["regress", "--quick", "--baseline", str(path), "--backends", "numpy", "--shapes", "square"]
    assert main([*argv, "--no-mosaic", "--no-speed", "--quiet", "--json", str(report)]) == 0
    assert set(statuses().values()) == {"not checked"}
    assert all(name in c["message"] for c in json.loads(report.read_text())["checks"] if c["group"] == group)


# ---------------------------------------------------------------------------------------
# the committed baseline and its file (fail closed)


def committed() -> dict:
    return json.loads(R.BASELINE_FILE.read_text())


def test_the_committed_baseline_names_every_check_of_the_quick_set():
    from compact_distributions.baselines import method_names

    quick = committed()["quick"]
    cfg = R.SETS["quick"]
    specs = R.method_specs(cfg["runs"], method_names(), ["numpy"], "numpy", [0])
    groups = {R.group_of(s) for s in specs}
    assert groups <= set(quick["measures"]) and groups <= set(quick["speed"])
    kinds = {g["kind"] for g in quick["measures"].values()} | {g["kind"] for g in quick["speed"].values()}
    assert kinds == {"method", "mosaic", "lloyd"}
    assert any(k.startswith(f"mosaic {cfg['mosaic']['picture']}/") for k in quick["measures"])


def test_the_committed_tolerances_follow_the_rule_from_their_values():
    data = committed()
    assert data["tolerances"] == R.tolerance_rule() and data["format"] == R.FORMAT
    for mode in ("quick", "full"):
        section = data.get(mode)
        if section is None:
            continue
        for group, entry in section["measures"].items():
            checked = len(section["set"]["mosaic" if entry["kind"] == "mosaic" else "runs"]["seeds"])
            for measure, fig in entry["figures"].items():
                sd = float(np.std(fig["values"], ddof=1))
                want = max(R.RESOLUTION[fig["unit"]], R.SPREAD_Z * sd / math.sqrt(checked))
                assert fig["tolerance"] == pytest.approx(want, rel=1e-4, abs=1e-6), (group, measure)
                assert fig["spread_seeds"] == len(fig["values"]) > checked


def test_the_committed_baseline_passes_the_check():
    R.load_baseline(R.BASELINE_FILE)  # raises if broken


def _mutations(baseline: dict):
    """(what, group, mutated copy): each figure of each group gets one broken number (NaN,
    inf, a string, gone), the fields and the kinds taken in turn."""
    kinds = (("nan", math.nan), ("inf", math.inf), ("string", "0.9"), ("missing", None))
    k = 0
    for mode in ("quick", "full"):
        for section, required in R.REQUIRED_FIGURES.items():
            for group, entry in baseline.get(mode, {}).get(section, {}).items():
                for measure in entry["figures"]:
                    field = list(required)[k % len(required)]
                    label, value = kinds[k % len(kinds)]
                    k += 1
                    b = copy.deepcopy(baseline)
                    fig = b[mode][section][group]["figures"][measure]
                    if value is None:
                        del fig[field]
                    else:
                        fig[field] = value
                    yield f"{mode}/{section}/{group}/{measure}/{field}={label}", group, b


def test_every_broken_figure_of_the_baseline_fails():
    baseline = committed()
    cases = list(_mutations(baseline))
    assert len(cases) >= sum(len(g["figures"]) for g in baseline["quick"]["measures"].values())
    for what, group, mutated in cases:
        for mode in ("quick", "full"):
            if mode not in mutated:
                continue
            try:
                R.check_figures(mutated[mode], mode)
            except R.InputError as err:
                assert group in str(err), what
                break
        else:
            pytest.fail(f"{what} was not refused")


def test_regress_exits_2_on_a_nan_baseline_before_measuring(tmp_path, capsys):
    baseline = committed()
    group = next(iter(baseline["quick"]["measures"]))
    baseline["quick"]["measures"][group]["figures"]["coverage"]["mean"] = math.nan
    path = tmp_path / "nan.json"
    path.write_text(json.dumps(baseline))
    line = one_error(["regress", "--quick", "--baseline", path, "--quiet"], capsys)
    assert group in line and "'mean' is nan, not a finite number" in line


def test_a_baseline_of_the_old_format_is_refused(tmp_path, capsys):
    path = tmp_path / "old.json"
    path.write_text(json.dumps({"quick": {"coverage": {}, "speed": {}}}))
    assert "regress --quick --update" in one_error(["regress", "--quick", "--baseline", path], capsys)


def test_regress_without_baseline_is_an_input_error(tmp_path, capsys):
    assert main(["regress", "--quick", "--baseline", str(tmp_path / "none.json")]) == 2
    assert "regress --update" in capsys.readouterr().err


def test_a_report_path_that_cannot_be_written_is_refused_before_measuring(tmp_path, capsys):
    folder = tmp_path / "folder"
    folder.mkdir()
    assert "--junit" in one_error(["regress", "--quick", "--junit", folder], capsys)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert "--json" in one_error(["regress", "--quick", "--json", blocker / "r.json"], capsys)
