"""How far from converged a table's runs are: Table 2's and Table 3's energy column.

For every problem of a table (scene, shape, raster, N; seed 0, as the table's coverage
at 1 % overlap) whose runs come from a method with a Lloyd energy (its record declares
:data:`cvt.lloyd.LLOYD_OPTIONS`: its loop is :func:`cvt.lloyd.lloyd` on the problem),
one more run, stored and read back like the others: a :class:`ConvergedSpec`.  It
replays the runs' Lloyd (their iterations and Lloyd options) and takes the energy of the
sites it ends with (:func:`cvt.lloyd.final_energy`), then goes on from those sites with
accelerated Lloyd to the tight tolerance :data:`cvt.lloyd.TIGHT_TOLERANCE` (at most
:data:`cvt.lloyd.TIGHT_CAP` iterations): the same run, continued until it has
converged.  E(converged) is the lowest energy of the two.  A table run's gap is

    gap = E(the run's final sites) / E(converged) - 1

(0.02: 2 % above converged; 0: no later iteration went lower).  Going on from the run's
end rather than from its start costs the run's own iterations less and measures what
those iterations left undone (:func:`cvt.lloyd.convergence_gap` starts again from the
seeding: the two agree within the raster Lloyd's wandering).  The replay stands for a run only
where its final sites are the run's, bit for bit (their digests): a run whose Lloyd is
not the problem's own (a method's turned cells) or whose backend's labels differ (the
GL cones) has no gap, and the table says why.  Methods without a Lloyd energy (the
baselines: their loops are their own) have none either.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from compact_distributions.cvt.lloyd import LLOYD_OPTIONS, TIGHT_CAP, TIGHT_TOLERANCE

from .runs import RunSpec, element_key, sites_digest

LLOYD_OPTION_NAMES = tuple(o.name for o in LLOYD_OPTIONS)
GAP = "energy_gap"  # a run row's gap; the tables aggregate it to ``energy_gap_mean``
GAP_NOTE = "energy_gap_note"  # why a run has no gap (empty where it has one)
NO_LLOYD = "no Lloyd energy: its loop is its own, not cvt.lloyd's on the problem"


def has_lloyd_energy(record) -> bool:
    """Whether a method's runs end with a Lloyd energy of their problem: its record
    declares the Lloyd loop's options (:data:`cvt.lloyd.LLOYD_OPTIONS`).

    Parameters
    ----------
    record : Method
        The method's record.

    Returns
    -------
    bool
    """
    return all(record.option(name) is not None for name in LLOYD_OPTION_NAMES)


def lloyd_options(spec: RunSpec) -> tuple:
    """The Lloyd options of a run: what its replay repeats.

    Parameters
    ----------
    spec : RunSpec
        A table's run.

    Returns
    -------
    tuple of (str, object)
        Its options that are the Lloyd loop's, as (name, value) pairs, sorted.
    """
    return tuple((k, v) for k, v in spec.options if k in LLOYD_OPTION_NAMES)


@dataclass(frozen=True)
class ConvergedSpec:
    """One problem of a table, replayed and run to the tight tolerance on ``backend``.

    ``run`` is one of the problem's runs (its problem, iterations and Lloyd options are
    the replay's; its method is not used), ``lloyd`` the Lloyd options replayed.
    """

    suite: str
    backend: str
    run: RunSpec
    lloyd: tuple = ()
    tolerance: float = TIGHT_TOLERANCE
    cap: int = TIGHT_CAP

    @property
    def problem_key(self) -> str:
        """The problem and the replay, as the table runs that it stands for share them."""
        return problem_key(self.run)

    @property
    def key(self) -> str:
        return f"{self.problem_key}__{self.backend}__tol{self.tolerance:g}__cap{self.cap}"

    def describe(self) -> str:
        r = self.run
        scene = f"{r.scene} " if r.scene else ""
        return f"converged {scene}{r.element} {r.width}x{r.height} N={r.n_elements} seed {r.seed} ({self.backend})"

    def params(self) -> dict:
        r = self.run
        return {
            "scene": r.scene,
            "element": r.element,
            "width": r.width,
            "height": r.height,
            "n_elements": r.n_elements,
            "iterations": r.iterations,
            "seed": r.seed,
            "backend": self.backend,
            "lloyd_options": dict(self.lloyd),
            "tolerance": self.tolerance,
            "cap": self.cap,
            "problem_key": self.problem_key,
        }

    def execute(self, backend) -> dict:
        """The replay's final energy and sites digest, and the tight run's lowest energy."""
        from compact_distributions.cvt.lloyd import LloydSetup, final_energy, lloyd

        from .outputs import machine, versions

        problem = self.run.problem()
        setup = LloydSetup.of(problem)
        replay = lloyd(problem, backend, self.run.iterations, setup=setup, **dict(self.lloyd))
        end = final_energy(backend, setup, replay.sites)
        tight = lloyd(
            problem,
            backend,
            self.cap,
            sites=replay.sites,
            setup=setup,
            tolerance=self.tolerance,
            accelerate=True,
        )
        converged = min([end, *tight.energy])
        if not (math.isfinite(end) and math.isfinite(converged) and converged > 0):  # fail closed
            raise ValueError(
                f"{self.describe()}: energies {end!r}, {converged!r} are not finite and positive"
            )
        row = {
            "key": self.key,
            **self.params(),
            "status": "ok",
            "reason": "",
            "device": backend.device(),
            "replay_sites_sha1": sites_digest(replay.sites),
            "end_energy": float(end),
            "converged_energy": float(converged),
            "converged_iterations": tight.iterations,
            "stopped_by": tight.stopped_by,
            "converged_seconds": float(np.sum(tight.seconds)),
        }
        return {"row": row, "spec": asdict(self), "machine": machine(), "versions": versions()}


def problem_key(spec: RunSpec) -> str:
    """What a run shares with the other runs of its problem and Lloyd.

    Parameters
    ----------
    spec : RunSpec
        A table's run.

    Returns
    -------
    str
        Its scene, shape, raster, N, iterations, seed and Lloyd options (not its method
        or backend), as a file name's part.
    """
    scene = f"{spec.scene}__" if spec.scene else ""
    opts = "".join(f"__{k}{v}" for k, v in lloyd_options(spec))
    return (
        f"{scene}{element_key(spec.element)}__{spec.width}x{spec.height}__n{spec.n_elements}"
        f"__it{spec.iterations}__s{spec.seed}{opts}"
    )


def converged_specs(specs: list[RunSpec], backend: str, suite: str, seeds: int = 1) -> list[ConvergedSpec]:
    """One :class:`ConvergedSpec` per problem (and Lloyd options) of ``specs`` that a
    method with a Lloyd energy runs, on ``backend``, stored under ``raw/SUITE/``; only
    for the first ``seeds`` seeds (the tight runs are the costly part).

    Parameters
    ----------
    specs : list of RunSpec
        A table's runs.
    backend : str
        The backend variant of the replays and tight runs.
    suite : str
        Their raw/ sub-folder.
    seeds : int, optional
        Seeds 0..seeds-1 are measured (default: seed 0).

    Returns
    -------
    list of ConvergedSpec
    """
    out: dict[str, ConvergedSpec] = {}
    for spec in specs:
        if spec.seed < seeds and has_lloyd_energy(spec.method_record):
            out.setdefault(problem_key(spec), ConvergedSpec(suite, backend, spec, lloyd_options(spec)))
    return list(out.values())


def attach_gaps(specs: list[RunSpec], rows: list[dict], converged: list[dict]) -> None:
    """Write each run row's :data:`GAP` (NaN where it has none) and :data:`GAP_NOTE`
    (why not), from the rows of its problem's :class:`ConvergedSpec` (``converged``).

    Parameters
    ----------
    specs : list of RunSpec
        The table's runs.
    rows : list of dict
        Their rows, in the same order (changed in place).
    converged : list of dict
        The rows of the converged specs.
    """
    by_problem = {r.get("problem_key"): r for r in converged}
    for spec, row in zip(specs, rows, strict=True):
        row[GAP], row[GAP_NOTE] = gap_of(spec, row, by_problem.get(problem_key(spec)))


def gap_of(spec: RunSpec, row: dict, reference: dict | None) -> tuple[float, str]:
    """A run's gap, or why it has none.

    Parameters
    ----------
    spec : RunSpec
        The run.
    row : dict
        Its row (``status``, ``sites_sha1``).
    reference : dict or None
        The row of its problem's :class:`ConvergedSpec` (None: not measured).

    Returns
    -------
    (float, str)
        (gap, "") where the replay's final sites are the run's; else (NaN, why): the
        run did not finish (no reason: its row says why), the method has no Lloyd
        energy, the problem was not measured or its converged run did not finish, the
        sites differ, or an energy is not finite and positive.
    """
    if row.get("status") != "ok":
        return math.nan, ""
    if not has_lloyd_energy(spec.method_record):
        return math.nan, NO_LLOYD
    if reference is None:
        return math.nan, "not measured (seed 0 only)"
    if reference.get("status") != "ok":
        return math.nan, f"its problem's converged run did not finish: {reference.get('reason') or 'not run'}"
    if row.get("sites_sha1") != reference.get("replay_sites_sha1"):
        return math.nan, (
            f"its final sites are not those of Lloyd on the problem replayed on {reference['backend']}: "
            "its Lloyd turns cells, or its backend's labels differ"
        )
    end, converged = reference.get("end_energy"), reference.get("converged_energy")
    if not all(isinstance(e, (int, float)) and math.isfinite(e) and e > 0 for e in (end, converged)):
        return math.nan, f"an energy is not finite and positive ({end!r}, {converged!r})"
    return float(end) / float(converged) - 1.0, ""


def gap_columns(ok) -> dict:
    """A table row's ``energy_gap_mean`` (the mean gap of its finished runs that have
    one; NaN where none has) and ``energy_gap_note`` (then, why not).

    Parameters
    ----------
    ok : pandas.DataFrame
        The row group's finished runs.

    Returns
    -------
    dict
    """
    values = ok[GAP].astype(float).dropna() if GAP in ok else []
    if len(values):
        return {"energy_gap_mean": float(values.mean()), "energy_gap_note": ""}
    notes = [n for n in (ok[GAP_NOTE] if GAP_NOTE in ok else []) if isinstance(n, str) and n]
    return {"energy_gap_mean": math.nan, "energy_gap_note": notes[0] if notes else "not measured"}


def gap_notes(table, group: list[str]) -> list[str]:
    """The tables' notes: what the column is, and for each reason a row has no gap, the
    rows (their ``group`` columns joined) it applies to.

    Parameters
    ----------
    table : pandas.DataFrame
        The aggregated table, with ``energy_gap_note``.
    group : list of str
        The columns that name a table row.

    Returns
    -------
    list of str
    """
    notes = [
        "energy above converged (seed 0): the Lloyd energy of the run's final sites over the lowest energy "
        f"reached when the run goes on with accelerated Lloyd to --tolerance {TIGHT_TOLERANCE:g} (at most "
        f"{TIGHT_CAP} iterations), minus 1; its Lloyd replayed once per problem on the variant backend and "
        "stored under raw/*-converged/ (bench.converged)"
    ]
    if "energy_gap_note" not in table:
        return notes
    note = table["energy_gap_note"]  # float64 NaN where no row has a note
    missing = table[note.notna() & (note.astype(str) != "")]
    for why, g in missing.groupby("energy_gap_note", sort=False):
        names = list(dict.fromkeys(" ".join(map(str, r)) for r in g[group].itertuples(index=False)))
        notes.append(f"energy above converged — for {', '.join(names)}: {why}")
    return notes


def run_converged(
    specs: list[RunSpec], rows: list[dict], out, backend: str, suite: str, **sweep
) -> tuple[list, list[dict]]:
    """Run (or read back) the converged specs of a table's runs and attach each run's gap
    to its row.

    Parameters
    ----------
    specs : list of RunSpec
        The table's runs.
    rows : list of dict
        Their rows (changed in place: :func:`attach_gaps`).
    out : path
        The report folder.
    backend : str
        The backend variant of the replays and tight runs.
    suite : str
        Their raw/ sub-folder.
    **sweep
        :func:`.sweep.run_sweep`'s keywords (force, quiet, unavailable, executor).

    Returns
    -------
    (list of ConvergedSpec, list of dict)
        The converged specs and their rows (for :func:`.sweep.check_runs`).
    """
    from .sweep import run_sweep

    finished = [s for s, r in zip(specs, rows, strict=True) if r.get("status") == "ok"]
    todo = converged_specs(finished, backend, suite)
    done = run_sweep(todo, out, **sweep) if todo else []
    attach_gaps(specs, rows, done)
    return todo, done


__all__ = [
    "LLOYD_OPTION_NAMES",
    "GAP",
    "GAP_NOTE",
    "NO_LLOYD",
    "has_lloyd_energy",
    "lloyd_options",
    "ConvergedSpec",
    "problem_key",
    "converged_specs",
    "attach_gaps",
    "gap_of",
    "gap_columns",
    "gap_notes",
    "run_converged",
]
