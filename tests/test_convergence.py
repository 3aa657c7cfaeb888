"""Convergence: the tolerance (cvt.lloyd.settled), the accelerated step (cvt.accelerate),
plain Lloyd unchanged, and the options through the API and the command line.

The digests below were computed from main's code (before the tolerance and the
accelerated step existed) by running ``lloyd`` and ``cd.run`` on NumPy with these
problems: plain Lloyd must still give those sites and energies bit for bit."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

import compact_distributions as cd
from compact_distributions.bench.commands.cli import main
from compact_distributions.bench.scenes import scene_problem
from compact_distributions.cvt.accelerate import (
    MAX_RELAXATION,
    SLACK,
    AcceleratedState,
    accelerated_step,
    relaxations,
)
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.lloyd import (
    TOLERANCE_WINDOW,
    LloydSetup,
    convergence_gap,
    final_energy,
    iterate,
    lloyd,
    settled,
)
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.problem import Grid
from compact_distributions.cvt.seeding import initial_sites

from .cli_errors import one_error


def digest(values) -> str:
    return hashlib.sha1(np.ascontiguousarray(values, dtype=np.float64).tobytes()).hexdigest()


# (sites, energies) of main's plain Lloyd, 15 iterations (the first five) or the method
# records with 10 iterations (the last two), NumPy
MAIN = {
    "square": ("198f3a26d828720b1b906da319f2d02989b0cd98", "1b788628f85431d469dc47d0597dc73765346904"),
    "circle": ("29ff7086c8bc138824ac3e1e6abfd52377bb8fcd", "8c10817d933d1d201f02719747a3012763bdbc2f"),
    "triangle": ("e57ad6723681ad69d998744de1c7e24e561b37a9", "a1f8ffdd6e452e2395414f042486732658bc0793"),
    "density": ("e696e10eee1f307f857d72da2b770cc3923a35a3", "5de2d7d4886795fa4028cd17f4bb3c167fcfea89"),
    "combined": ("610805291fbf2a855b0182f1d3a540f881d2ee10", "03a84967b315b6239e9fc13a38912847620dcf85"),
    "ours": ("bea5bb84723d6ac5b355a68d0377173c6abb6a9e", "746db5faceb0e85a76cabbe59a0f432abc0b2f9c"),
    "ours-compact-alternate": (
        "cfcfda91c508114300c42cea4835ebfafb8e604c",
        "f4ba1a9e2a6b1a5feb5eb900bb943beab3bae7a2",
    ),
}
PROBLEMS = {
    "square": lambda: cd.problem(80, 128, element="square", seed=3),
    "circle": lambda: cd.problem(80, 128, element="circle", seed=5),
    "triangle": lambda: cd.problem(50, 96, element="triangle", seed=1),
    "density": lambda: scene_problem("density", 96, 60, make_metric("linf"), 2),
    "combined": lambda: scene_problem("combined", 96, 60, make_metric("l2"), 4),
}


# ------------------------------------------------------------------ plain Lloyd unchanged
@pytest.mark.parametrize("name", list(PROBLEMS))
def test_plain_lloyd_gives_mains_sites_and_energies(name, reference):
    res = lloyd(PROBLEMS[name](), reference, 15)
    assert (digest(res.sites), digest(res.energy)) == MAIN[name]
    assert res.stopped_by == "iterations" and res.evaluations == 15 and not res.accelerated


@pytest.mark.parametrize(
    "name,method,element,options",
    [
        ("ours", "ours", "square", {}),
        ("ours-compact-alternate", "ours-compact", "triangle", {"alternate": True}),
    ],
)
def test_method_records_give_mains_sites(name, method, element, options, reference):
    res = cd.run(
        cd.problem(60, 96, element=element, seed=7), method, backend=reference, iterations=10, **options
    )
    assert (digest(res.distribution.sites), digest(res.distribution.energy)) == MAIN[name]
    assert res.distribution.extra["stopped_by"] == "iterations"


def test_plain_lloyd_is_the_hand_written_loop(reference):
    """Independent of the digests: lloyd() is moments -> centroids, nothing else."""
    problem = PROBLEMS["density"]()
    setup = LloydSetup.of(problem)
    x = initial_sites(problem)
    energies = []
    for _ in range(6):
        mom = reference.moments(
            x, angles=setup.cell_angles(x), scales=setup.scales_at(x), metric=setup.metric, grid=setup.grid
        )
        energies.append(mom.energy(x))
        x = mom.centroids(x)
    res = lloyd(problem, reference, 6)
    assert np.array_equal(res.sites, x) and res.energy == energies


# ------------------------------------------------------------------ the tolerance
def test_settled_on_a_geometric_decay():
    """E_k = 1 + 0.5^k: over a window of W the lowest energy improves by
    0.5^(k-W) - 0.5^k; the first k where that is at most 1e-4 x E_k is the stop."""
    energy = [1 + 0.5**k for k in range(60)]
    lowest = np.minimum.accumulate(energy).tolist()
    expected = next(
        k
        for k in range(TOLERANCE_WINDOW, 60)
        if (0.5 ** (k - TOLERANCE_WINDOW) - 0.5**k) <= 1e-4 * (1 + 0.5**k)
    )
    stops = [k for k in range(60) if settled(lowest[: k + 1], 1e-4)]
    assert stops[0] == expected


def test_a_wandering_energy_stops_and_a_falling_one_runs_to_the_cap():
    """A loop whose energy wanders (no new low for a window) stops; one that keeps
    falling by more than the tolerance per window runs to its cap: never for ever."""
    rng = np.random.default_rng(0)
    wander = 100 + rng.uniform(-0.5, 0.5, 5000)

    def step_of(values):
        def step(k):
            return k + 1, values[k], np.zeros(3, bool)

        return step

    _, log = iterate(0, step_of(wander), 5000, tolerance=1e-4)
    assert log.stopped_by == "tolerance" and log.iterations < 5000
    lowest = np.minimum.accumulate(log.energy)
    # it stopped at the first window without a new low below 1e-4 (relative)
    k = log.iterations - 1
    assert lowest[k - TOLERANCE_WINDOW] - lowest[k] <= 1e-4 * lowest[k]
    falling = 100 - 0.01 * np.arange(3000)  # 0.2 per window: 2e-3 relative
    _, log = iterate(0, step_of(falling), 2000, tolerance=1e-4)
    assert (log.stopped_by, log.iterations) == ("iterations", 2000)


def test_a_tolerance_stops_the_same_trajectory_early(reference):
    problem = PROBLEMS["square"]()
    res = lloyd(problem, reference, 2000, tolerance=1e-4)
    assert res.stopped_by == "tolerance" and TOLERANCE_WINDOW < res.iterations < 2000
    same = lloyd(problem, reference, res.iterations)
    assert np.array_equal(res.sites, same.sites) and res.energy == same.energy


@pytest.mark.parametrize("bad", [0, -1e-3, 1, 2, float("nan"), "x", True])
def test_bad_tolerance(bad, reference):
    with pytest.raises(InputError, match="tolerance must be a finite number > 0 and < 1"):
        lloyd(PROBLEMS["square"](), reference, 5, tolerance=bad)


# ------------------------------------------------------------------ the accelerated step
def test_relaxations_by_hand():
    previous = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    step = np.array([[2.0, 0.1], [-1.0, 0.0], [1.0, 0.0], [1.0, 0.0]])
    w = np.array([1.0, 2.0, 2.9, 2.5])
    # kept (grows), turned (shrinks), perpendicular (shrinks, at least 1), kept (at most 3)
    assert np.allclose(relaxations(w, step, previous), [1.5, 1.4, max(1.0, 2.9 * 0.7), MAX_RELAXATION])
    assert np.array_equal(relaxations(None, step, None), np.ones(4))


def _toy(grid, target, penalty_above=None):
    """evaluate(x) of a toy fixed point: centroids halfway to ``target``, energy the
    squared distance to it (+ a penalty for any coordinate above ``penalty_above``)."""
    calls = []

    def evaluate(x):
        calls.append(x.copy())
        energy = float(np.sum((x - target) ** 2))
        if penalty_above is not None and (x > penalty_above).any():
            energy += 1e6
        return x + 0.5 * (target - x), energy, np.zeros(len(x), bool)

    return evaluate, calls


def test_accelerated_step_over_relaxes_and_ends_with_measured_sites():
    grid = Grid(100, 100)
    target = np.array([[60.0, 60.0], [30.0, 70.0]])
    evaluate, calls = _toy(grid, target)
    state, log = iterate(
        AcceleratedState(np.array([[10.0, 10.0], [10.0, 10.0]])), accelerated_step(evaluate, grid), 6
    )
    assert state.evaluations == len(calls) == 7  # the start, then one per iteration
    # each recorded energy is that of the sites the iteration ended with
    assert log.energy[-1] == np.sum((state.sites - target) ** 2)
    # plain halving would leave 0.5^6 of the way; over-relaxed, much less
    assert np.abs(state.sites - target).max() < 0.5**6 * 60


def test_safeguard_falls_back_to_the_plain_step():
    grid = Grid(100, 100)
    target = np.array([[50.0, 50.0]])
    evaluate, calls = _toy(grid, target, penalty_above=50.0)  # overshooting the target is punished
    state, log = iterate(AcceleratedState(np.array([[10.0, 10.0]])), accelerated_step(evaluate, grid), 8)
    assert state.fallbacks > 0 and state.evaluations == 1 + 8 + state.fallbacks
    # a refused step never enters the log: each energy at most the last one x (1 + SLACK)
    assert all(b <= a * (1 + SLACK) for a, b in zip(log.energy, log.energy[1:], strict=False))
    assert (state.sites <= 50.0).all()


def test_proposals_outside_the_region_take_the_plain_step():
    mask = np.zeros((100, 100), bool)
    mask[:, :55] = True  # the region: x < 55
    grid = Grid(100, 100, mask)
    target = np.array([[54.0, 50.0]])
    evaluate, calls = _toy(grid, target)
    iterate(AcceleratedState(np.array([[5.0, 50.0]])), accelerated_step(evaluate, grid), 10)
    assert all((c[:, 0] < 55).all() for c in calls)


def test_accelerated_lloyd_energy_is_that_of_its_final_sites(reference):
    problem = PROBLEMS["density"]()
    res = lloyd(problem, reference, 12, accelerate=True)
    assert res.accelerated and res.evaluations == 13 + res.fallbacks
    assert res.energy[-1] == final_energy(reference, LloydSetup.of(problem), res.sites)


@pytest.mark.parametrize("element", ["square", "circle"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_accelerated_lloyd_is_ahead_of_plain(element, seed, reference):
    """20 accelerated iterations end lower than 40 plain ones (energy, not time)."""
    problem = cd.problem(100, 160, element=element, seed=seed)
    plain = lloyd(problem, reference, 41)
    fast = lloyd(problem, reference, 20, accelerate=True)
    assert fast.energy[-1] < plain.energy[40]


def test_accelerated_lloyd_on_opencl_matches_its_own_energy(ocl):
    problem = PROBLEMS["combined"]()
    res = lloyd(problem, ocl, 10, accelerate=True, tolerance=1e-3)
    assert res.energy[-1] == pytest.approx(final_energy(ocl, LloydSetup.of(problem), res.sites), rel=1e-12)
    assert res.stopped_by in ("iterations", "tolerance")


def test_convergence_gap(reference):
    problem = PROBLEMS["circle"]()
    early = convergence_gap(problem, reference, 2)
    late = convergence_gap(problem, reference, 60)
    assert early["converged_energy"] == late["converged_energy"]
    assert early["excess"] > late["excess"] and early["excess"] > 0.05
    assert late["energy"] == final_energy(
        reference, LloydSetup.of(problem), lloyd(problem, reference, 60).sites
    )
    assert early["stopped_by"] == "tolerance"


# ------------------------------------------------------------------ API and command line
def test_api_takes_both_options(reference):
    problem = cd.problem(80, 128, element="square", seed=3)
    res = cd.run(problem, "ours-fit", backend=reference, iterations=500, tolerance=1e-4, accelerate=True)
    extra = res.distribution.extra
    assert extra["stopped_by"] == "tolerance" and extra["accelerate"] and res.distribution.iterations < 500
    assert res.method_options == {"tolerance": 1e-4, "accelerate": True}
    with pytest.raises(InputError, match="method 'hu2016' has no option 'tolerance'"):
        cd.run(problem, "hu2016", backend=reference, tolerance=1e-4)


def test_run_command_records_why_it_stopped(tmp_path):
    from jsonschema import validate

    from compact_distributions.bench.results import schema

    out = tmp_path / "run"
    argv = ["run", "--elements", "60", "--size", "96", "--iterations", "2000", "--tolerance", "1e-4"]
    assert main([*argv, "--accelerate", "--out", str(out), "--quiet"]) == 0
    result = json.loads((out / "result.json").read_text())
    validate(result, schema())
    assert result["stopped_by"] == "tolerance" and result["iterations"] < 2000
    assert result["method_options"] == {"tolerance": 1e-4, "accelerate": True}
    assert (
        result["extra"]["lloyd_evaluations"]
        == result["iterations"] + 1 + result["extra"]["accelerate_fallbacks"]
    )


@pytest.mark.parametrize(
    "argv,message",
    [
        (["run", "--tolerance", "0"], "--tolerance must be a finite number > 0 and < 1, got '0'"),
        (
            ["run", "--method", "smith2005", "--accelerate"],
            "--accelerate is not an option of --method smith2005",
        ),
        (["converge", "--backend", "nosuch"], "unknown --backend 'nosuch'"),
    ],
)
def test_bad_options_are_one_line_errors(argv, message, tmp_path, capsys):
    assert message in one_error([*argv, "--out", str(tmp_path / "o")], capsys)


# ------------------------------------------------------------------ cvtbench converge
def test_summary_by_hand():
    from types import SimpleNamespace

    from compact_distributions.bench.commands.converge import summary

    # plain: energies of x_0..x_4, one second per iteration; accelerated: 1.5 s each
    plain = SimpleNamespace(energy=[10.0, 8.0, 7.0, 6.5, 6.2], seconds=[1.0] * 5)
    fast = SimpleNamespace(energy=[7.5, 6.6, 6.1, 6.0], seconds=[1.5] * 4, evaluations=6, fallbacks=1)
    s = summary(plain, fast, 4)  # plain's energy after 4 iterations: 6.2, in 4 s
    assert (s["plain_energy_k"], s["plain_seconds_k"]) == (6.2, 4.0)
    assert (s["fast_reach_iterations"], s["fast_reach_seconds"], s["time_ratio"]) == (3, 4.5, 4.5 / 4.0)
    never = SimpleNamespace(energy=[9.0, 8.0], seconds=[1.0, 1.0], evaluations=3, fallbacks=0)
    assert np.isnan(summary(plain, never, 4)["time_ratio"])


def test_converge_command_writes_its_report(tmp_path, monkeypatch):
    import pandas as pd

    from compact_distributions.bench.commands import converge as cmd

    tiny = cmd.Settings(48, 12, 8, 60, None, False)  # a smoke test: the same code, a smaller problem
    monkeypatch.setattr(cmd, "QUICK", tiny)
    out = tmp_path / "rep"
    assert cmd.converge(cmd.ConvergeRequest(out=out, quick=True, quiet=True, backend="numpy")) == 0
    table = pd.read_csv(out / "converge.csv")
    assert len(table) == 7 and (table["status"] == "ok").all() and (table["iterations"] == 8).all()
    assert set(table["plain_tol_stopped_by"]) | set(table["fast_tol_stopped_by"]) <= {
        "tolerance",
        "iterations",
    }
    curves = pd.read_csv(out / "converge_curves.csv")
    assert len(curves) == 7 * ((8 + 1) + 8)
    text = (out / "converge.md").read_text()
    assert "Table 2's problems: accelerated Lloyd reaches" in text and "density picture scene.jpg" in text
    assert (out / "converge.png").stat().st_size > 0


# ------------------------------------------------------------------ the tables' energy column
def _run(method="ours", seed=0, element="square", options=(), iterations=20):
    from compact_distributions.bench.runs import RunSpec

    return RunSpec("t", method, "numpy", element, 96, 96, 40, iterations, seed, options=options)


def _reference(end, converged, digest_="abc", status="ok"):
    return {
        "status": status,
        "reason": "boom" if status != "ok" else "",
        "backend": "numpy",
        "replay_sites_sha1": digest_,
        "end_energy": end,
        "converged_energy": converged,
    }


def test_energy_gap_by_hand():
    """A run whose digest its problem's replay repeats: (end / converged - 1), computed
    here by hand; every other case (another method, other sites, a NaN, a missing or a
    zero energy, a failed reference) has no gap and says why."""
    from compact_distributions.bench.converged import NO_LLOYD, gap_of

    ok = {"status": "ok", "sites_sha1": "abc"}
    assert gap_of(_run(), ok, _reference(110.0, 100.0)) == (pytest.approx(0.1, abs=1e-15), "")
    assert gap_of(_run(), ok, _reference(99.0, 100.0))[0] == pytest.approx(-0.01, abs=1e-15)
    assert gap_of(_run("hu2016"), ok, _reference(110.0, 100.0)) == (
        pytest.approx(np.nan, nan_ok=True),
        NO_LLOYD,
    )
    for reference, why in [
        (_reference(110.0, 100.0, digest_="other"), "not those of Lloyd"),
        (_reference(float("nan"), 100.0), "not finite"),
        (_reference(110.0, float("nan")), "not finite"),
        (_reference(None, 100.0), "not finite"),
        (_reference(110.0, 0.0), "not finite"),
        (_reference(110.0, float("inf")), "not finite"),
        (_reference(110.0, 100.0, status="failed"), "boom"),
        (None, "not measured"),
    ]:
        gap, note = gap_of(_run(), ok, reference)
        assert np.isnan(gap) and why in note, (reference, note)
    assert np.isnan(gap_of(_run(), {"status": "failed"}, _reference(110.0, 100.0))[0])


def test_one_converged_run_per_problem_and_lloyd_options():
    """Runs of one problem share one converged run whatever their method or backend;
    Lloyd options make another, and so do seeds where more than seed 0 are measured;
    methods without a Lloyd energy make none."""
    from compact_distributions.bench.converged import converged_specs, problem_key

    specs = [
        _run(),
        _run("ours-compact"),
        _run("ours-compact", options={"alternate": True}),
        _run(seed=1),
        _run(options={"accelerate": True}),
        _run("hu2016", seed=2),
    ]
    made = converged_specs(specs, "numpy", "t-converged")
    assert [c.problem_key for c in made] == [problem_key(specs[k]) for k in (0, 4)]
    assert made[1].lloyd == (("accelerate", True),) and made[0].lloyd == ()
    more = converged_specs(specs, "numpy", "t-converged", seeds=3)
    assert [c.problem_key for c in more] == [problem_key(specs[k]) for k in (0, 3, 4)]
    assert len({c.key for c in more}) == 3


def _gap_by_definition(problem, backend, iterations):
    """The gap written out from cvt.lloyd's parts: the run's final sites and their
    energy, then the run continued, accelerated, to the tight tolerance."""
    from compact_distributions.cvt.lloyd import TIGHT_CAP, TIGHT_TOLERANCE

    run = lloyd(problem, backend, iterations)
    end = final_energy(backend, LloydSetup.of(problem), run.sites)
    more = lloyd(problem, backend, TIGHT_CAP, sites=run.sites, tolerance=TIGHT_TOLERANCE, accelerate=True)
    return run, end, min(end, *more.energy)


def test_a_converged_run_measures_the_run_continued_to_convergence(reference):
    """The stored replay and continuation give the gap of its definition, the replay's
    digest is that of the method's own run of the problem (so the table attaches the gap
    to it), fewer iterations leave a larger gap, and convergence_gap (which starts again
    from the seeding) agrees within a fraction of a percent."""
    from compact_distributions.bench.converged import ConvergedSpec, attach_gaps

    spec = _run()
    row = spec.execute(reference)["row"]
    conv = ConvergedSpec("t-converged", "numpy", spec).execute(reference)["row"]
    run, end, converged = _gap_by_definition(spec.problem(), reference, spec.iterations)
    assert (conv["end_energy"], conv["converged_energy"]) == (end, converged)
    assert conv["replay_sites_sha1"] == row["sites_sha1"] == digest(run.sites)
    rows = [row, {"status": "ok", "sites_sha1": row["sites_sha1"]}]
    attach_gaps([spec, _run(seed=1)], rows, [conv])
    assert rows[0]["energy_gap"] == pytest.approx(end / converged - 1, rel=1e-12)
    assert 0.001 < rows[0]["energy_gap"] < 0.2 and np.isnan(rows[1]["energy_gap"])
    early_row = ConvergedSpec("t-converged", "numpy", _run(iterations=3)).execute(reference)["row"]
    assert early_row["end_energy"] / early_row["converged_energy"] - 1 > rows[0]["energy_gap"]
    truth = convergence_gap(spec.problem(), reference, spec.iterations)
    assert truth["energy"] == end and abs(truth["excess"] - rows[0]["energy_gap"]) < 0.005


def test_tables_aggregate_the_gap_by_hand():
    """Table 2 and Table 3 average the gaps of a row's seeds; a row without one shows —
    and its reason in the notes."""
    from compact_distributions.bench import table2, table3
    from compact_distributions.bench.converged import gap_notes
    from compact_distributions.cvt.evaluate import MEASURES

    def rows(method, gaps, note="", **extra):
        return [
            {
                **_run(method, seed).params(),
                "key": _run(method, seed).key,
                "status": "ok",
                "reason": "",
                "device": "cpu",
                "coverage": 0.7,
                "overlap": 0.0,
                "method_seconds": 1.0,
                "lloyd_seconds": 0.5,
                "ms_per_iteration": 1.0,
                "placed": 40,
                "empty_cells": 0,
                "energy_gap": gap,
                "energy_gap_note": note,
                "n_elements": 40,
                "scene": "density",
                **{m: 0.5 for m in MEASURES},
                **extra,
            }
            for seed, gap in enumerate(gaps)
        ]

    hand = rows("ours", [0.01, 0.03]) + rows("hu2016", [np.nan, np.nan], "no Lloyd energy: its own loop")
    for module in (table2, table3):
        table = module.aggregate(hand).set_index("method")
        assert table.loc["ours", "energy_gap_mean"] == pytest.approx(0.02)
        assert np.isnan(table.loc["hu2016", "energy_gap_mean"])
        notes = gap_notes(table.reset_index(), ["method", "backend"])
        assert notes[1] == "energy above converged — for hu2016 numpy: no Lloyd energy: its own loop"
    # one seed's NaN does not turn the row's mean into NaN, nor pass for a figure
    part = table2.aggregate(rows("ours", [0.04, np.nan], "sites differ")).iloc[0]
    assert part["energy_gap_mean"] == pytest.approx(0.04)


def test_table2_end_to_end_has_the_gap_of_its_problems(tmp_path, reference):
    """A small Table 2: ours' figure is convergence_gap's excess of its problem; the
    baseline's row shows — and the notes say why; the converged runs are stored and read
    back (not run again) the next time."""
    import pandas as pd

    argv = ["table2", "--quick", "--methods", "ours,hu2016", "--backends", "numpy", "--shapes", "square"]
    assert main([*argv, "--seeds", "1", "--out", str(tmp_path), "--quiet"]) == 0
    table = pd.read_csv(tmp_path / "table2.csv").set_index("method")
    from compact_distributions.bench.runs import RunSpec

    spec = RunSpec("x", "ours", "numpy", "square", 256, 256, 250, 20, 0)
    _, end, converged = _gap_by_definition(spec.problem(), reference, 20)
    assert table.loc["ours", "energy_gap_mean"] == pytest.approx(
        end / converged - 1, rel=1e-5
    )  # csv: 6 digits
    assert np.isnan(table.loc["hu2016", "energy_gap_mean"])
    text = (tmp_path / "table2.md").read_text()
    assert "energy above converged — for hu2016 numpy: no Lloyd energy" in text
    stored = list((tmp_path / "raw" / "table2-quick-converged").glob("*.json"))
    assert len(stored) == 1
    before = stored[0].stat().st_mtime_ns
    assert main([*argv, "--seeds", "1", "--out", str(tmp_path), "--quiet"]) == 0
    assert stored[0].stat().st_mtime_ns == before
