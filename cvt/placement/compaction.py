"""Compaction of placed elements: neighbours share their walls (method ``ours-compact``).

After placement every element sits in its own raster cell, so two neighbours are kept
apart by two half-cells of slack.  Compaction moves the centres and grows the sizes of all
elements at once, in a few rounds; the angles (the direction field's) are never changed.

One round
---------
Elements are convex: element i is ``c_i + r_i·R(θ_i)·K`` with K the unit element
(:mod:`cvt.shapes`) and h_i(n) = max_{k in K} (R(θ_i)k)·n its support function.  Two
elements are disjoint with a joint of at least G when a unit direction n gives

    n·(c_j − c_i) − h_i(n)·r_i − h_j(−n)·r_j >= G                                  (1)

(the gap between the two along n; its maximum over n is their Euclidean distance).  With
n fixed, (1) is linear in (c_i, c_j, r_i, r_j).  The region (a raster mask, possibly
non-convex, with thin parts) is kept by the same rule against its boundary: the boundary
(raster edge included) is cut into straight pieces of pixel edges, at most
``SEGMENT_LENGTH`` px long, and element i stays clear of a piece with end points p, q when

    min(n·p, n·q) − n·c_i − h_i(n)·r_i >= G/2                                        (2)

(a convex element against a segment: exact, so an element may stand beside a reflex
corner of the region or in a thin part).  A round is the linear program over the
displacements (Δc_i, Δr_i):

    maximise   Σ_i r_i·Δr_i                (the covered area, linearised: d(r²)/2)
    subject to (1) for every near pair, (2) for every near boundary piece,
               |Δc_i|_∞ <= δ_i = move·inradius(K)·r_i,   −shrink·r_i <= Δr_i <= growth·r_i.

n is fixed per pair and round: the candidate with the largest left side of (1)/(2) now,
among the face normals of both polygons, the centre line (or the nearest point of the
piece and its normal) and last round's n of that pair; curved shapes add 16 sampled
directions refined by a golden-section search.

The program is solved (``solver``) either approximately as a whole, by a fixed number of
steps (``iterations``, default 70) of the primal-dual hybrid gradient method (PDHG,
Chambolle-Pock with diagonal steps, in Halpern's reflected form with restarts) on all
elements at once: sparse products and clipping in NumPy and scipy.sparse, the default; or exactly per tile by HiGHS' dual simplex
(``highspy``; ``solver="highs"``, and always when ``move_cost`` > 0): the program is split
into square tiles of about ``tile_elements`` elements, a pair cut by a tile border becomes
a wall between the two, each side keeping to its half of the current slack of (1) (the two
halves add up to (1)), so each tile is an independent program; tiles shift by half a tile
every other round.

Why every round is overlap-free (the guarantee)
-----------------------------------------------
* A pair (a piece) enters the program when its current gap lower bound g (the best
  candidate's left side of (1)/(2), never more than the true distance) is below G (G/2)
  plus what the two can approach in one round: element i moves by at most √2·δ_i and
  grows by at most growth·r_i·ρ (ρ = circumradius of K), and the distance between two
  convex sets drops by at most the sum of these (it is 1-Lipschitz in each set's
  Hausdorff distance).  Pairs and pieces left out therefore stay at least G (G/2) apart.
* Pairs and pieces in the program are separated by (1)/(2) once the solution meets them.
  Neither solver meets them exactly (HiGHS to its tolerance, ~1e-7; PDHG's last step
  leaves rows short by up to a few tenths of a pixel), so after every solve each
  constraint is evaluated again in float64 and elements short of ``SLACK`` (1e-7 px) are
  shrunk about their centres (both elements of a row by the same factor, each element by
  the smallest factor of its rows); shrinking only adds to every left side of (1)/(2)
  (h >= 0), so one pass restores them all.  A row that no shrinking can meet (PDHG put
  two centres closer than G) puts its elements back at the round's start, repeated
  until none is left (the start meets every row), so that no element is lost; counted as
  ``reverted``.  Both solvers keep the bounds on moves and growth exactly (PDHG clips
  every step to them).  The guarantee rests on this exact check, not on the solver: a
  tile that HiGHS does not solve to optimality stays where it is (Δ = 0 is feasible) and
  is counted in the round's ``history``.
* Containment: (1)/(2) are linear, so they hold all along the straight path from the old
  state to the new one; an element moves continuously without crossing the boundary, so
  an element whose centre starts in the region stays in it (a centre outside the region
  is an InputError).
* The start may be slightly off (placement lets a corner cross its cell's contour by up to
  half a pixel): before every program the same shrinking makes every row hold; a row no
  size can meet (two centres closer than G, a centre closer than G/2 to the border) drops
  one element (the smaller; counted in ``dropped``).

Sizes and density
-----------------
The objective weighs growth by the current size (area), and each element's growth and
shrinking per round are capped relative to its own size, so a field of sizes keeps its
contrast: with a density 4:1 between two halves (sizes 2:1) the median size ratio went
from 2.02 to 2.00 (squares, 1024², N = 4000) while coverage rose from 0.78 to 0.97.
Uniform weights (Σ Δr_i) and relative ones (Σ Δr_i·r0_i²/r_i) were measured 0.15-0.5
points lower on every shape.

Under size caps (``max_sizes``: ours-compact's density caps, the size that follows the
density) elements short of their caps come first: element i's growth is weighed by
r_i·(cap_i / r_i)^p (``fairness`` p = 2: the gradient of Σ cap_i²·ln r_i, each size's
logarithm weighted by its target area), so that an element already at its cap yields
room to a neighbour that lags behind its own.  Weighed by r_i alone, 30-35 % of the
elements ended below 0.97 of their caps (1 % below 0.6), and the size error (RMS of
log2(area / target)) was 1.12-1.25x ours' on ellipses, triangles and circles (Table 3's
density and combined scenes, 512², N = 1000, seeds 0-4).  With p = 2 (and ours-compact's
caps 3 % above the density's sizes instead of 2 %) it is 0.72-0.99x on every shape of
both scenes, coverage −0.23 to +0.44 points; 0.71-1.01x, +0.04 to +0.49 points, on two
densities no scene uses (two Gaussian blobs of contrast 5, a linear ramp of contrast 4).
With the 2 % caps: p = 1 left circles at 1.09x, p = 1.5 triangles at 1.04x (1.14x in
Table 3's quick set), p = 2 cost up to 0.52 points, p = 3 up to 0.95; caps 5 % above
gained 0.3-1.3 points but left circles at 1.09x.  Without caps the weights are r_i, as
before.

Caps that follow the elements (``max_sizes`` a function of position, ours-compact's
under a density) are read at each element's centre every round, because the target is
the density where the element ends, not where it started: on a picture as density
(scikit-image's camera.png, 512², N = 1000) compaction moves centres by 4 px (median;
11-15 px at the 99th percentile, elements 16 px apart) and one in five crosses to where
the density asks for a size 7 % or more away; with the caps fixed at the start those
elements held half (triangles) to four fifths (circles) of the size error, which was
1.06/1.15/1.34x ours' on squares/triangles/circles (seeds 0-1).  Read again each
round, a cap that fell below its element makes it shrink towards it (by up to
``shrink`` of itself a round; shrinking keeps every row) and one that rose lets it
grow.  And each element moves only within the widest box (whole pixels, up to its move
bound, at least ``_STEADY_LEAST``) in which the cap stays within ±``growth`` × (the
rounds left, this one included) of its own at every pixel: a change the rounds left
could follow, ±``growth`` in the last round, where a smooth density never binds.  Where
a round's gain falls below ``tol`` before the last, one more round follows, as the
last.  Measured (512², N = 1000, 5 shapes, seeds 0-2, ours-compact's size error over
ours', with one more round than the shape's under a density): camera 0.71-0.93x (was
0.88-1.33x); three pictures not used in choosing this (astronaut, coffee, chelsea)
0.66-1.05x (was 0.74-1.29x); four tried after (coins, horse, text, moon) 0.62-1.10x
(was 0.67-1.52x); coverage −0.88 to +1.04 points.  Table 3's density and combined
scenes (seeds 0-4): 0.71-0.98x (was 0.72-0.99x), +0.10 to +0.55 points.  On a finely
textured picture (motorcycle_left, seeds 0-1) that left circles and triangles at
1.12-1.13x (was 1.57-1.66x) and −1.0 to −1.7 points: its cap changes from pixel to
pixel, so the steady boxes held elements back and a cap read at one pixel shrank an
element for that pixel's sake.  So ours-compact's caps follow the density smoothed over a
pixel (``cvt.placement.ours.DensityCaps``) and, under a density, compaction runs two
rounds more than the shape's: motorcycle_left circles 1.11x, triangles 1.12x, squares
0.99x, coverage −0.35 to +0.35 points against the caps fixed where the elements started
(Table 3's density and combined scenes, seeds 0-4: 0.70-0.97x, +0.06 to +0.45 points).
The size error reads the density at one pixel; against the density averaged over each
element's footprint, motorcycle_left's circles and triangles are 0.88x and 0.94x ours'
(0.94x and 0.98x with the caps at one pixel).  Two pictures tried after, five shapes,
seeds 0-1: gravel.png 0.98-1.10x; not met on hubble_deep_field.jpg, whose galaxies are
a few pixels across, 1.21-1.72x (the fit alone, ours-fit, is 1.28x on circles), though
against the footprint's density it is 0.79-0.94x.  Sending an element in the last round to the pixel next to it whose own cap
fits its size brought motorcycle_left to 1.04x/1.07x, but only by choosing the pixel the
measure reads (the footprint's ratios did not move): not kept.  Measured
no better: boxes held to ±growth in the last round alone (coins' triangles and circles
1.14-1.15x), to ±0.1-0.2 in every round (−1.4 to −3.3 points), to twice the rounds
left (coins 1.11-1.12x), drops held to ``shrink`` × the rounds left (down to −1.26
points), a least move of 1 px (coins' circles 1.18x), ``fairness`` 3 (down to −1.4
points), the shape's rounds alone (down to −2 points), no shrinking towards a cap that
fell (chelsea's circles 1.14x), every element shrunk to its cap after the last round
(−2 to −4.5 points).

Where the density changes within an element (hubble_deep_field's galaxies, a few pixels
across against elements 16 px apart), compaction's moves of a few pixels carry elements
onto a spot or off it, and the cap read at the final centre's pixel is then far from the
smoothed cap the element followed: at 1.72x on hubble's circles, 15 % of the elements
had moved to where the density's size factor differs from their site's by more than
1.41x, and they held 85-88 % of the excess over ours' (seeds 0-1). So ours-compact
(``cvt.placement.ours``) ends with three rounds whose caps follow the density read at
one pixel, 20 % above the smoothed caps' factor, and no element ends more than 10 %
above the cap read at its own centre's pixel (cut before and after those rounds:
shrinking an element about its centre keeps it inside itself; those rounds come before
the turn to a field, whose round the cut follows: after it, their moves raised the
direction error of the combined scene's squares from 0.49° to 0.86° at 160², N = 120);
it weighs growth by ``fairness`` 3 under its caps, runs six rounds before those three
(nine more than the shape's) and ``_STEADY_LEAST`` is 0.2 px (was 0.5: ten rounds of
half a pixel carried elements across a spot). Measured (512², N = 1000, five shapes,
seeds 0-1, ours-compact's size error over ours'): motorcycle_left 0.80-0.97x (was
0.86-1.12x), hubble_deep_field 0.85-1.10x (was 1.21-1.72x), coverage −0.78 to +2.04
points; camera, coins, astronaut 0.66-0.99x (+0.72 to +5.83 points); two pictures not
used in choosing this (brick, grass) 0.78-1.02x (grass was 0.93-1.17x), −0.81 to +2.17
points; Table 3's density and combined scenes (seeds 0-4) 0.70-0.98x, +0.39 to +1.14
points. Eight more pictures tried after (gravel, rocket, page, chelsea, coffee, horse,
moon, text): 0.52-1.04x (was 0.61-1.10x), −0.72 to +10.95 points (horse, a silhouette,
gained most). The footprint's ratios moved by −0.06 to +0.06 (motorcycle_left and hubble
0.84-0.94x). The cost is time: 13 rounds instead of 6 (squares, circles and triangles on
hubble and camera, OpenCL, two runs each: fit and compaction 0.90 s against 0.49 s, the
whole method 1.29 s against 0.90 s). Each part measured alone on motorcycle_left and
hubble: without the last rounds (the cut alone) coverage fell by up to 2.4 points; with
``fairness`` 2 their triangles were 1.13x and 1.17x, hubble's circles 1.19x; with two or
four rounds before the last three hubble's circles were 1.12x/1.06x at −1.5/−1.1 points;
with ``_STEADY_LEAST`` 0.5, 1.12x. Measured no better (hubble's circles): caps read at
one pixel in every round (1.63x, −0.6 to −2.3 points), the steady boxes held to ±0.3-0.5
or rises alone held to ±0.3-0.5 (1.14-1.23x), drops held to ``shrink`` × the rounds left
(1.52x), compaction started from the sites instead of the fit (1.69x), a faster shrink
(``shrink`` 0.10-0.15: 1.52-1.53x, up to −1.2 points).

``max_growth`` (off by default) caps every size at
(1 + max_growth) × its placed size; ``move_cost`` > 0 puts a price on moves (columns
Δc⁺, Δc⁻), which keeps regular lattices from drifting (a lattice of circles then reaches
its optimum π/4 exactly) but measured up to 0.4 points lower and 30-60 % slower on CVTs.

Solvers (4000 squares, 1024², after 20 Lloyd iterations)
--------------------------------------------------------
HiGHS on the whole program slows down round after round as more rows become tight (the
simplex basis couples long chains of touching elements); interior point and PDLP at
1e-4 are slower still.  One small model per tile of about 64 elements (cross pairs as
walls) keeps HiGHS' dual simplex fast, at about 3.5 iterations per element and round
whatever the tile size, the options or a basis carried from an earlier round, and costs
about 2 points of coverage against the untiled program at equal rounds.  Tiles are
independent and HiGHS lets go of the interpreter, so one thread per core solves them.

PDHG on the whole untiled program does better on both counts, as the program needs no
exact optimum: every row is checked and repaired afterwards.  On the first round of the
case above, the area gain (after the repair) of the tiles' exact optima is 0.158 and of
the untiled optimum 0.186; PDHG from zero reaches 0.168 / 0.179 / 0.183 after 50 / 100
/ 200 steps, leaving rows short by at most 0.2-0.4 px (repaired by shrinking, with less
loss than the tile walls cost).  A step is two sparse products (~6 entries per pair row)
and a few whole-array operations; four rounds of PDHG take about a quarter of the tiles'
time and cover 1.1 % more area (Table 2's ours-compact rows 0.4-1.4 points more).
Plain PDHG's best primal/dual step ratio was 4 (2 and 8 within 0.3 % of the area).
Measured no better: starting each round from last round's duals (mapped by pair), steps
folded into the matrices, float32 products, relaxation 1.5 (~20 % fewer steps for the
same gain).  Float32 pays only once the program outgrows the processor's cache: one of at
least ``_PDHG_SINGLE_ENTRIES`` entries (some 20 000 squares without walls) steps in float32
throughout, the answer within 1e-5 px of float64's (area within 1e-8), then checked in
float64 as always: the LP in 0.55x the time at 64 000 squares (1.6-2.1 M entries; A and
Aᵀ in float64 are some 40 MB) and 0.7x on a 20 000-tile mosaic (0.7 M entries, in Z
order; out of it float32 took 1.2x float64's time there).  Fewer steps cost area in every
round: 50 steps per round instead of 70 covered 0.36 % less area at 64 000 squares, 70
in the first round and 40 after 0.53 %.  A set of ``_SPATIAL_ORDER_ELEMENTS`` elements or
more is worked in Z order (:func:`_spatial_order`; results in the caller's order): from
the random order of Lloyd's sites, 0.78x the processor time of compaction at 64 000
squares and 0.83x on the mosaic.  The covered area is the same to 3e-5, but the rows
come in another order and a pair may be seen from its other element, so PDHG's
approximate steps and ties between equally good directions differ: on the mosaic
elements ended within 0.03 px of the caller's order's, at 64 000 squares 1.6 % of them
more than 1 px away (circles: 2e-5 px).  Smaller sets, in cache anyway, keep the
caller's order and their results bit for bit.
Halpern's iteration on the reflected step (z ← w·(2T(z) − z) + (1 − w)·z₀,
w = (k+1)/(k+2), anchored at the start and restarted from T(z) when the fixed-point
residual has fallen 5-fold; Lu & Yang's r2HPDHG) costs the same per step and needs
fewer: 70 steps per round at ratio 4 cover more area than 100 plain steps on every
shape (4000 elements, 1024², seeds 0-1: rectangles +0.0 to +0.1 points of coverage,
ellipses +0.5, the others +0.1 to +0.2) and 0.5 % more on a 20 000-tile walled mosaic.
Longer primal steps (ratio 8) with 55 steps gained on squares but lost 0.9 points on
rectangles (β = 0.5) and 0.3 on ellipses; at ratio 4, 55-65 steps lose 0.1-0.3 points
to 70.  PDLP's adaptive primal weight (the ratio moved at each restart halfway, in
logarithm, to the primal over the dual movement since the last one, kept in [2.5, 16],
carried from round to round) gained 0.01-0.15 points on every shape at 70 steps, but
did not buy steps: against the fixed ratio at 70 it lost up to 0.22 points at 60 steps
(circles, octagons) and 0.04 at 65 (hexagons) (seeds 0-2, alternating triangles
included).  Anchored at the start it nears each round's optimum more closely; from
an exact lattice that optimum is to stay, where plain PDHG's inexact steps broke the
symmetry (a lattice shaken by 0.1 px grows as before).
Steps stop early only when converged (T(z) = z and no row short by more than 1e-10 px:
small programs, which then meet HiGHS' optimum).  PDHG is plain NumPy and
scipy.sparse's CSR kernels; on a large program (over ``_PDHG_BLOCK_ENTRIES`` entries per
thread) each step's products and updates are split into blocks of rows and of columns
(Aᵀy by the rows of Aᵀ, whose sums run in the order of the CSC scatter) worked by
``threads`` threads, and the near pairs' candidates likewise into pieces: each number is
computed by the same operations in the same order however the work is split, so the
result does not depend on ``threads`` (bit for bit, tested).

Walls as chords
---------------
A picture's walls (its strong edges, 4-connected staircases one pixel thick) give one
piece per pixel step, and an element beside a slanted wall some twenty near pieces in
every round.  With more than ``_WALL_CHORD_ELEMENTS`` elements the wall pixels are taken
a ``_CHORD_BLOCK`` px square at a time, and where a square's pixel centres lie within
``_CHORD_WIDTH`` of their principal axis its steps become one chord, kept clear of by
G/2 plus its width (the farthest centre off it): the widened chord holds every step of
the square, so (2) against it keeps each step G/2 away (:func:`_wall_chords`).  Steps
between squares, squares that fit no line and squares with a centre within G/2 +
``_CHORD_ROOM`` of the chord stay steps (no element is dropped for a chord).  The last
round is against the steps themselves, so that the elements close the room the widths
left.  On a 64 000-tile mosaic at 4096 px (coffee) the pieces' rows fell from 0.63 M
to 0.27 M in a round of chords, compaction's CPU time to 0.80x (0.75-0.76x on 20 000-tile
ones at 2560 px: astronaut, rocket).  Measured on 20 000-tile mosaics at 2560 px (astronaut seeds 0-1, rocket):
coverage +0.1 to +0.2 points, colour error +0.4 to +0.5 % (seeds alone move it by 0.45
%); with chords in every round +0.3 to +0.4 points and +1.1 to +1.4 %.  Smaller sets
keep the steps, and their results bit for bit.

Choices in the formulation
--------------------------
* (1) uses h_j(−n), not h_j(n): the two are equal for centrally symmetric elements, not
  for triangles.
* Variables are displacements from the round's start (the program is equally well scaled
  at any raster size); sizes are capped per round relative to each size, not by one
  absolute cap; the objective is the area Σ r_i·Δr_i.
* The region is kept by (2) against boundary pieces with a best direction per piece.
* The program is solved approximately as a whole by PDHG, or exactly per tile with walls
  between tiles by HiGHS (see Solvers); the exact check after each round makes either safe.
* The near pairs and pieces of a round are cut by exact filters from the candidates of
  kd-trees: the centres by class of reach (within a factor √2), the pieces' midpoints by
  class of half-length (within a factor 2) and of width (chords apart), each query
  sized by its classes' largest.  Any superset gives the same rows (sorted by their
  keys); finer classes only make it smaller: at 64 000 squares on a walled mosaic the
  candidates fell from 0.58 M to 0.33 M (pieces) and 0.62 M to 0.47 M (pairs) a round.
"""

from __future__ import annotations

import functools
import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InputError
from ..problem import Grid
from ..shapes import check_shape, element_ball
from ..threads import side_by_side, usable_cores
from ..validate import one_of, real_number, whole_number
from .fit import parse_gap

SLACK = 1e-7  # px: every kept constraint holds with at least this much after a round
SEGMENT_LENGTH = 32  # px: longest boundary piece
SOLVERS = ("pdhg", "highs")  # a round's program: PDHG whole, or HiGHS per tile
_SELECT = 1e-6  # px: extra reach when choosing near pairs and pieces
_SAMPLES = 16  # directions sampled for curved shapes (then refined)
_REFINE = 14  # golden-section steps of that refinement
_GOLD = (math.sqrt(5) - 1) / 2
_TIE = 1e-6  # px: candidate directions this close count as equally good (> SLACK·√2)
_TILES_PER_WORKER = 8  # fewer tiles per thread than this: not worth a thread
_PDHG_ITERATIONS = 70  # PDHG steps per round
_PDHG_STILL = 1e-10  # px: PDHG has converged when T(z) = z to this and no row is short by more
_STEP_RATIO = 4.0  # PDHG: primal steps this much longer (dual ones shorter) than balanced
_HALPERN_RESTART = 0.2  # PDHG: new anchor once the fixed-point residual falls by this factor
_HALPERN_CHECK = 4  # PDHG: steps between evaluations of that residual
_PIECE_ROWS = 100_000  # candidate pairs per thread at least (fewer: fewer threads)
_PDHG_BLOCK_ENTRIES = 200_000  # PDHG: entries of A per thread at least (fewer: fewer threads)
_PDHG_SINGLE_ENTRIES = 500_000  # PDHG: programs with this many entries of A step in float32
_SPATIAL_ORDER_ELEMENTS = 10_000  # this many elements or more: worked in Z order (_spatial_order)
_WALL_CHORD_ELEMENTS = 10_000  # more elements than this: walls kept by chords (_wall_chords)
_CHORD_BLOCK = 8  # px: a chord stands for the wall pixels of a square of this side
_CHORD_WIDTH = 0.75  # px: the most a chord's wall pixel centres may lie off it
_CHORD_ROOM = 1.0  # px: no chord where a centre is within this of it (beyond G/2 and its width)
_FAIRNESS = 2.0  # under size caps: growth weighed by r·(cap / r)^this (Sizes and density)
_REACH_STEPS = 2  # reach classes per factor 2 (_reach_classes)
_STEADY_LEAST = 0.2  # px: under caps that follow the centres, the last round's move bound at least


@dataclass
class CompactionResult:
    centres: np.ndarray  # (N, 2) px
    sizes: np.ndarray  # (N,) 0 where there is no element
    angles: np.ndarray  # (N,) radians, as given
    rounds: int  # rounds run
    seconds: float  # wall time of compact()
    lp_seconds: float = 0.0  # of which in the LP solver
    dropped: int = 0  # elements given size 0 (centre closer than the gap to another)
    history: list = field(default_factory=list)  # per round: pairs, pieces, area, seconds

    def followed_by(self, later: CompactionResult, *, counted: bool = True) -> CompactionResult:
        """This result continued by ``later``, a pass of compaction started from its
        centres and sizes: later's centres and sizes, the elements either pass dropped,
        and (``counted``) the rounds, seconds and history of both; otherwise this
        result's own (a pass that is part of another step, such as a turn round).

        Parameters
        ----------
        later : CompactionResult
            The later pass.
        counted : bool
            Whether the later pass's rounds and times count as compaction's.

        Returns
        -------
        CompactionResult
        """
        if not counted:
            return replace(
                self, centres=later.centres, sizes=later.sizes, dropped=self.dropped + later.dropped
            )
        return replace(
            self,
            centres=later.centres,
            sizes=later.sizes,
            rounds=self.rounds + later.rounds,
            seconds=self.seconds + later.seconds,
            lp_seconds=self.lp_seconds + later.lp_seconds,
            dropped=self.dropped + later.dropped,
            history=self.history + later.history,
        )

    def as_dict(self) -> dict:
        return {
            "compaction_rounds": self.rounds,
            "compaction_seconds": self.seconds,
            "compaction_lp_seconds": self.lp_seconds,
            "compaction_dropped": self.dropped,
        }


def _argmax_rows(g, tie=_TIE):
    """Per row, the first candidate within ``tie`` of the row's best (candidates come in
    order of preference: ties are common, e.g. a square's corner on a piece's end point
    is as far along the diagonal as along the border's normal, and the diagonal would
    lock the element in place), and its value."""
    # candidate by candidate on a transposed copy (a loop over the few candidates): a
    # reduction along the short axis of a (rows, candidates) array costs several times
    # more, and so do strided columns
    by_candidate = np.ascontiguousarray(g.T)
    top = np.full(len(g), -np.inf)
    for col in by_candidate:
        np.maximum(top, col, out=top)
    top -= tie
    k = np.zeros(len(g), dtype=np.int64)
    for m in range(len(by_candidate) - 1, -1, -1):  # the first within tie wins: filled last
        np.copyto(k, m, where=by_candidate[m] >= top)
    return k, g[np.arange(len(g)), k]


def _refine_angles(gap_at, phi, width):
    """Golden-section search of each row's best angle in [phi − width, phi + width]."""
    lo, hi = phi - width, phi + width
    a = hi - _GOLD * (hi - lo)
    b = lo + _GOLD * (hi - lo)
    ga, gb = gap_at(a), gap_at(b)
    for _ in range(_REFINE):
        left = ga > gb  # the maximum is in [lo, b]
        hi = np.where(left, b, hi)
        lo = np.where(left, lo, a)
        na = np.where(left, hi - _GOLD * (hi - lo), b)
        nb = np.where(left, a, lo + _GOLD * (hi - lo))
        fresh = np.where(left, na, nb)
        gf = gap_at(fresh)
        ga, gb = np.where(left, gf, gb), np.where(left, ga, gf)
        a, b = na, nb
    best = np.where(ga > gb, a, b)
    return best, np.maximum(ga, gb)


def _gaps_of_rows(gap, unit, args):
    """``gap_for(rows)``: the gap function (nx, ny) of those rows (a slice or indices),
    broadcasting over columns; ``gap``: :func:`_pair_gap` or :func:`_seg_gap`, ``args``:
    its per-row arguments as (rows, 1) columns, gathered once per call of gap_for (the
    curved shapes' refinement evaluates the same rows some thirty times)."""

    def gap_for(rows):
        picked = tuple(a[rows] for a in args)
        return lambda nx, ny: gap(unit, *picked, nx, ny)

    return gap_for


def _best_direction(gap_for, g, direction_of, curved_from=None, enough=None):
    """Per row, the preferred candidate direction (columns of the candidates' gaps ``g``,
    in order of preference) and its gap.  ``direction_of(k)``: the direction (x, y) of
    each row's candidate k (built only for the one chosen, not for every candidate).
    For curved shapes (``curved_from``: a reference angle per row) the rows whose gap is
    below ``enough`` also try _SAMPLES directions within ±90° of it, refined by golden
    section, taken when clearly better.  ``gap_for``: :func:`_gaps_of_rows`.  ``g`` is
    overwritten."""
    np.copyto(g, -np.inf, where=~np.isfinite(g))  # last round's n is NaN for new rows
    k, best = _argmax_rows(g)
    bx, by = direction_of(k)
    sub = np.flatnonzero(best < enough) if curved_from is not None else np.zeros(0, np.int64)
    if len(sub):  # rows far apart already are left out of the program: no need to refine
        off = np.linspace(-math.pi / 2, math.pi / 2, _SAMPLES)
        phis = curved_from[sub, None] + off[None, :]
        gap_of = gap_for(sub)
        ks, _ = _argmax_rows(gap_of(np.cos(phis), np.sin(phis)))
        phi, gref = _refine_angles(
            lambda p: gap_of(np.cos(p)[:, None], np.sin(p)[:, None])[:, 0],
            phis[np.arange(len(sub)), ks],
            off[1] - off[0],
        )
        better = gref > best[sub] + _TIE
        take = sub[better]
        bx[take], by[take], best[take] = np.cos(phi[better]), np.sin(phi[better]), gref[better]
    return bx, by, best


# --------------------------------------------------------------------- pairs
def _pair_gap(unit, dx, dy, ri, rj, ci, si, cj, sj, nx, ny):
    """Left side of (1) without G: the gap between two elements along n (broadcasting)."""
    return nx * dx + ny * dy - ri * unit.support(nx, ny, ci, si) - rj * unit.support(-nx, -ny, cj, sj)


def _best_pair_directions(unit, c, r, cos, sin, i, j, prev_n, enough=None, along=None, offsets=None):
    """Per pair: the unit n (from i to j) to separate them along, and their gap along it
    (``along``: the gaps along the centre lines where the caller has them, NaN where the
    centres coincide; ``offsets``: c[j] − c[i] as (x, y, length) where the caller has
    them)."""
    if offsets is None:
        dx, dy = c[j, 0] - c[i, 0], c[j, 1] - c[i, 1]
        offsets = dx, dy, np.hypot(dx, dy)
    dx, dy, d = offsets
    with np.errstate(invalid="ignore", divide="ignore"):
        clx, cly = np.where(d > 0, dx / d, 1.0), np.where(d > 0, dy / d, 0.0)
    args = tuple(v[:, None] for v in (dx, dy, r[i], r[j], cos[i], sin[i], cos[j], sin[j]))
    gap_for = _gaps_of_rows(_pair_gap, unit, args)
    gap_of = gap_for(slice(None))
    # the candidates' gaps in order of preference, written into one array: faces (walls
    # to slide along; i's, then j's), last round's n, centre line
    faces = len(unit.faces.normals) if not unit.curved else 0
    other = np.arange(len(i))
    if faces and unit.faces.symmetric:
        # j's faces seen from j: the gap along −g is the gap along g from j to i.  Where j
        # is turned as i is and the shape is centrally symmetric, j's faces are i's (its
        # opposite normals), later in the order of preference and of the same gap (to
        # rounding, far below _TIE): never chosen, so not evaluated
        apart = (cos[i] != cos[j]) | (sin[i] != sin[j])
        other = np.flatnonzero(apart)
    j_faces = faces if len(other) else 0
    # candidate-major (a view of it transposed): each candidate's column is contiguous
    # for its writes and for _argmax_rows, which needs no transposed copy of it
    g = np.empty((faces + j_faces + 2, len(i))).T
    ri, rj, ci, si, cj, sj = (a[:, 0] for a in args[2:])
    if faces:
        _face_gaps(unit, dx, dy, ri, rj, ci, si, cj, sj, out=g[:, :faces])
    if j_faces and 2 * len(other) > len(i):  # most turned apart (a field): all, no gathers
        _face_gaps(unit, -dx, -dy, rj, ri, cj, sj, ci, si, out=g[:, faces : faces + j_faces])
        if len(other) < len(i):
            g[np.flatnonzero(~apart), faces : faces + j_faces] = -np.inf
    elif j_faces:
        g[:, faces : faces + j_faces] = -np.inf
        g[other, faces : faces + j_faces] = _face_gaps(
            unit, -dx[other], -dy[other], rj[other], ri[other], cj[other], sj[other], ci[other], si[other]
        )
    # last round's n: new pairs have none (NaN, never chosen)
    if np.isfinite(prev_n[:, 0]).any():
        g[:, -2] = gap_of(prev_n[:, 0:1], prev_n[:, 1:2])[:, 0]
    else:
        g[:, -2] = np.nan
    if along is None:
        g[:, -1] = gap_of(clx[:, None], cly[:, None])[:, 0]
    else:
        g[:, -1] = along
        fresh = np.flatnonzero(~(d > 0))
        g[fresh, -1] = gap_for(fresh)(clx[fresh, None], cly[fresh, None])[:, 0]

    def direction_of(k):
        """The direction of candidate k of each pair: a face normal of i, minus one of
        j, last round's n or the centre line."""
        last = k == faces + j_faces + 1
        bx, by = np.where(last, clx, prev_n[:, 0]), np.where(last, cly, prev_n[:, 1])
        on_face = np.flatnonzero(k < faces + j_faces)
        if len(on_face):
            m = k[on_face]
            of_j = m >= faces
            m = np.where(of_j, m - faces, m)
            owner = np.where(of_j, j[on_face], i[on_face])
            fx, fy = unit.face_normal(m, cos[owner], sin[owner])
            sign = np.where(of_j, -1.0, 1.0)
            bx[on_face], by[on_face] = sign * fx, sign * fy
        return bx, by

    curved = unit.curved and unit.semi_axes[0] != unit.semi_axes[1]  # circles: centre line
    return _best_direction(gap_for, g, direction_of, np.arctan2(cly, clx) if curved else None, enough)


def _face_gaps(unit, dx, dy, ra, rb, ca, sa, cb, sb, out=None):
    """The gaps (rows, K) along the face normals n_k of polygon a (turned by its angle)
    from a to b (``dx``, ``dy``: b's centre minus a's; one entry per row), into ``out``
    where given: h_a(n_k) is a constant of the shape, and for a centrally symmetric
    shape the opposite normal's gap needs no new support.  Worked face by face along
    the rows (a row's few faces as numpy's inner loop cost several times more)."""
    if out is None:
        out = np.empty((len(ra), len(unit.faces.normals)))
    by_face = out.T
    offsets = unit.faces.offsets[:, None]
    if unit.faces.symmetric:
        h = len(by_face) // 2
        fx, fy = unit.face_normals(ca, sa, h, faces_first=True)
        nd = fx * dx + fy * dy
        # = rb·h_b(±n): b turned as a is has a's offsets along a's normals (to rounding)
        alike = (ca == cb) & (sa == sb)
        same = np.flatnonzero(alike)
        if len(same) == len(ra):  # all turned alike (no field): one broadcast
            hb = np.empty_like(nd)
            hb[:] = offsets[:h]
        elif 2 * len(same) < len(ra):  # most turned apart (a field): all, no gathers
            hb = unit.support(fx, fy, cb, sb)
            hb[:, same] = offsets[:h]
        else:
            hb = np.empty_like(nd)
            hb[:, same] = offsets[:h]
            turned = np.flatnonzero(~alike)
            hb[:, turned] = unit.support(fx[:, turned], fy[:, turned], cb[turned], sb[turned])
        hb *= rb
        np.subtract(nd, hb, out=by_face[:h])
        np.negative(nd, out=by_face[h:])
        by_face[h:] -= hb
        by_face -= ra * offsets
    else:
        fx, fy = unit.face_normals(ca, sa, faces_first=True)
        by_face[:] = fx * dx + fy * dy - ra * offsets - rb * unit.support(-fx, -fy, cb, sb)
    return out


def _reach_classes(reach: np.ndarray) -> list[np.ndarray]:
    """The indices of ``reach`` grouped into classes whose reaches lie within a factor
    2^(1/_REACH_STEPS): a query sized by its class's largest reach, not by the largest of
    all, keeps the candidates of small elements few where sizes vary (a density)."""
    level = np.floor(_REACH_STEPS * np.log2(reach / reach.min())).astype(np.int64)
    order = np.argsort(level, kind="stable")
    cuts = np.flatnonzero(np.diff(level[order])) + 1
    return np.split(order, cuts)


def _kd_tree(points, **options):
    """scipy's cKDTree of ``points``, scipy.spatial imported on first use: importing this
    module (every command's method registry does) stays cheap."""
    from scipy.spatial import cKDTree

    return cKDTree(points, **options)


def _point_trees(points, reach) -> list:
    """[(indices, kd-tree of their points, their largest reach)] per class of reach
    (:func:`_reach_classes`): built once per round, queried for the near pairs and for
    the near pieces.  The trees are built unbalanced and with plain boxes (scipy's
    balanced_tree, compact_nodes): faster to build and to query here, and the pairs found
    are the same (their order is set afterwards)."""
    return [
        (cls, _kd_tree(points[cls], balanced_tree=False, compact_nodes=False), reach[cls].max())
        for cls in _reach_classes(reach)
    ]


def _near_items(point_trees, item_trees, extra):
    """(k, i): every point k and item i with |points[k] − item| <= reach[k] + the item's
    half-length and width + extra (and some farther ones), in the kd-trees' order.
    ``point_trees``: the points by class of reach (:func:`_point_trees`); ``item_trees``:
    [(item indices, kd-tree of their midpoints, their largest half-length plus their
    largest width)] (:func:`_segment_trees`)."""

    def near(cls, tree, top, members, item_tree, half_length):
        found = tree.sparse_distance_matrix(item_tree, top + half_length + extra, output_type="ndarray")
        return cls[found["i"]], members[found["j"]]

    # scipy's queries let go of the GIL: one per pair of classes, on every core, in order
    found = side_by_side(
        *(functools.partial(near, *points, *items) for points in point_trees for items in item_trees)
    )
    return np.concatenate([k for k, _ in found]), np.concatenate([i for _, i in found])


def _sorted_pairs(a, b, nb):
    """The index pairs (a, b), b < ``nb``, sorted by a then b (as np.lexsort((b, a))
    orders them): the keys a·nb + b sorted and split again, in a quarter of the time
    of an argsort of the keys and the two gathers."""
    key = np.sort(a.astype(np.int64) * nb + b)
    return key // nb, key % nb


def _segment_trees(segs: np.ndarray, widen: np.ndarray | None = None) -> list:
    """[(indices, kd-tree of their midpoints, largest half-length + largest width)] per
    class of half-length (a wall's staircase: 1-2 px; a chord: up to 6; a border piece:
    up to 16) and of width (``widen``: a chord's; None: all 0): a query about a piece's
    midpoint must reach its half-length and width further, and most pieces are short
    steps of no width."""
    half = 0.5 * np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1])
    widen = np.zeros(len(segs)) if widen is None else widen
    # classes of half-length within a factor 2 (at most 1 px: one class), the widened
    # apart: one class of all the long ones widened the query of a 3 px chord by a 16 px
    # border piece's half, and one of all the short ones a step's by a chord's width
    level = 2 * np.ceil(np.log2(np.maximum(half, 1.0))).astype(np.int64) + (widen > 0)
    out = []
    for v in np.unique(level):
        members = np.flatnonzero(level == v)
        mid = 0.5 * (segs[members, :2] + segs[members, 2:])
        # unbalanced, plain boxes: as in _point_trees (the same candidates, faster)
        tree = _kd_tree(mid, balanced_tree=False, compact_nodes=False)
        out.append((members, tree, float(half[members].max() + widen[members].max())))
    return out


def _pairs_within(point_trees, count, extra, ordered=True):
    """Index pairs (a, b), a < b, of the ``count`` points with |points[a] − points[b]| <=
    reach[a] + reach[b] + extra (and some farther ones), ordered by a then b (unless
    ``ordered`` is False: in the kd-trees' order): class by class of reach
    (``point_trees``: :func:`_point_trees`), so one large element does not widen the
    query of every small one."""
    classes, trees, tops = zip(*point_trees, strict=True)

    def within(x):
        got = trees[x].query_pairs(2 * tops[x] + extra, output_type="ndarray")
        return classes[x][got[:, 0]], classes[x][got[:, 1]]

    def between(x, y):
        found = trees[x].sparse_distance_matrix(trees[y], tops[x] + tops[y] + extra, output_type="ndarray")
        return classes[x][found["i"]], classes[y][found["j"]]

    # scipy's queries let go of the GIL: each on the next free core, the answers in order
    queries = []
    for x in range(len(classes)):
        queries.append(functools.partial(within, x))
        queries += [functools.partial(between, x, y) for y in range(x + 1, len(classes))]
    found = side_by_side(*queries)
    a, b = np.concatenate([p for p, _ in found]), np.concatenate([q for _, q in found])
    if not ordered:
        return np.minimum(a, b), np.maximum(a, b)
    return _sorted_pairs(np.minimum(a, b), np.maximum(a, b), count)


def _near_pairs(unit, c, r, cos, sin, budget, gap, prev, act, point_trees, threads=1):
    """Pairs whose gap could close to < gap this round; their n and current gap
    (``act``: the elements with a size, ``point_trees``: their centres by class of reach
    ρ·r + budget, :func:`_point_trees`).  The candidate pairs are worked in pieces by up
    to ``threads`` threads (:func:`_in_pieces`), and the pairs kept ordered by i then j
    (each row's figures do not depend on the others: sorting the few kept instead of
    the many candidates gives the same rows in the same order)."""
    if len(act) < 2:
        e = np.zeros(0)
        return np.zeros(0, np.int64), np.zeros(0, np.int64), e, e, e
    a, b = _pairs_within(point_trees, len(act), gap + _SELECT, ordered=False)

    def kept(a, b):
        """The candidates (a, b) (positions in act) that make rows, with their n and gap."""
        i, j = act[a], act[b]
        dx, dy = c[j, 0] - c[i, 0], c[j, 1] - c[i, 1]
        d = np.hypot(dx, dy)
        enough = gap + budget[i] + budget[j] + _SELECT
        keep = d < unit.circumradius * (r[i] + r[j]) + enough
        i, j, dx, dy, d, enough = _select(keep, i, j, dx, dy, d, enough)
        # the centre line is one of the candidates and the one chosen is within _TIE of
        # the best: pairs already far enough apart along it are left out without the others
        with np.errstate(invalid="ignore", divide="ignore"):
            along = _pair_gap(unit, dx, dy, r[i], r[j], cos[i], sin[i], cos[j], sin[j], dx / d, dy / d)
        keep = ~(along >= enough + _TIE)  # coincident centres (NaN) stay
        i, j, enough, along, dx, dy, d = _select(keep, i, j, enough, along, dx, dy, d)
        prev_n = _lookup(prev, i * len(r) + j)
        nx, ny, g = _best_pair_directions(unit, c, r, cos, sin, i, j, prev_n, enough, along, (dx, dy, d))
        keep = g < enough
        return _select(keep, i, j, nx, ny, g)

    i, j, nx, ny, g = _in_pieces(kept, threads, a, b)
    # keys unique (a < b): any sort gives this order; the kd-trees' order comes in long
    # sorted runs (Z order), which the stable sort (a merge sort) takes whole
    at = np.argsort(i * len(r) + j, kind="stable")
    return tuple(v.take(at) for v in (i, j, nx, ny, g))


def _in_pieces(fn, threads, *arrays) -> tuple:
    """fn(*arrays) for a ``fn`` that works row by row and returns a tuple of 1-D arrays:
    run on consecutive pieces of the rows (at least ``_PIECE_ROWS`` each) by up to
    ``threads`` threads (numpy lets go of the interpreter), the pieces' answers joined
    in order: the same arrays as one call."""
    count = len(arrays[0])
    parts = max(1, min(threads, count // _PIECE_ROWS))
    if parts == 1:
        return fn(*arrays)
    cuts = np.linspace(0, count, parts + 1).astype(np.int64)

    def piece(k):
        return fn(*(v[cuts[k] : cuts[k + 1]] for v in arrays))

    answers = side_by_side(*(functools.partial(piece, k) for k in range(parts)))
    return tuple(np.concatenate(column) for column in zip(*answers, strict=True))


def _select(keep, *arrays) -> tuple:
    """The entries where ``keep`` (bool) is True of each of the 1-D ``arrays``: the
    indices found once and taken from each, not the mask counted again per array
    (a boolean index does that: over twice the time for ten arrays)."""
    at = np.flatnonzero(keep)
    return tuple(a.take(at) for a in arrays)


def _lookup(prev, keys):
    """Last round's direction of each key (NaN where the key is new)."""
    if prev is None or len(prev[0]) == 0:
        return np.full((len(keys), 2), np.nan)
    pk, pn = prev
    pos = np.searchsorted(pk, keys)
    np.minimum(pos, len(pk) - 1, out=pos)
    # most keys were there last round: all gathered, the new ones set to NaN after
    out = pn.take(pos, axis=0)
    out[np.flatnonzero(pk.take(pos) != keys)] = np.nan
    return out


# --------------------------------------------------------------------- region
def boundary_segments(mask: np.ndarray, length: int = SEGMENT_LENGTH) -> np.ndarray:
    """(S, 4) pieces (x0, y0, x1, y1) of the region's boundary: maximal straight runs of
    pixel edges between an inside and an outside pixel (the raster's edge counts as
    outside), cut into pieces of at most ``length`` px."""
    mask = np.asarray(mask, dtype=bool)
    h, w = mask.shape
    if mask.all():  # the whole raster (a Grid): its four sides, in the order found below
        ends = np.array([0, 0])
        runs = [
            (np.array([0, h]), ends, np.array([w, w]), True),
            (np.array([0, w]), ends, np.array([h, h]), False),
        ]
    else:
        pad = np.zeros((h + 2, w + 2), dtype=bool)
        pad[1:-1, 1:-1] = mask
        runs = []
        # horizontal edges at y = row between pixel rows row-1 and row; runs along x
        hb = pad[:-1, 1:-1] != pad[1:, 1:-1]  # (h+1, w)
        # vertical edges at x = col between pixel columns col-1 and col; runs along y
        vb = (pad[1:-1, :-1] != pad[1:-1, 1:]).T  # (w+1, h)
        for edges, horizontal in ((hb, True), (vb, False)):
            e = np.zeros((edges.shape[0], edges.shape[1] + 2), dtype=np.int8)
            e[:, 1:-1] = edges
            step = np.diff(e, axis=1)
            line, start = np.nonzero(step == 1)
            _, stop = np.nonzero(step == -1)  # same row order, so runs pair up
            runs.append((line, start, stop, horizontal))
    out = []
    for line, start, stop, horizontal in runs:
        n = -(-(stop - start) // length)  # pieces per run
        rep = np.repeat(np.arange(len(start)), n)
        first = np.cumsum(n) - n
        k = np.arange(len(rep)) - first[rep]
        a = start[rep] + k * length
        b = np.minimum(a + length, stop[rep])
        fixed = line[rep].astype(np.float64)
        if horizontal:
            out.append(np.stack([a, fixed, b, fixed], axis=1))
        else:
            out.append(np.stack([fixed, a, fixed, b], axis=1))
    return np.concatenate(out).astype(np.float64)


def _wall_links(walls: np.ndarray) -> tuple[np.ndarray, ...]:
    """The pixels of thin walls in row-major order and their links to their neighbours.

    Worked on the wall pixels alone (their neighbours gathered), not by whole-raster
    passes: walls are a few per cent of a picture's pixels.

    Parameters
    ----------
    walls : (H, W) bool ndarray
        Thin walls.

    Returns
    -------
    i, j : (P,) int ndarrays
        Row and column of each wall pixel, row-major (``np.nonzero``'s order).
    right, down, left, up : (P,) bool ndarrays
        Whether the pixel right of, below, left of, above each is a wall pixel too.
    """
    walls = np.asarray(walls, dtype=bool)
    h, w = walls.shape
    i, j = np.nonzero(walls)
    # row-major: a wall pixel's right neighbour, if a wall pixel, comes next
    right = np.zeros(len(i), dtype=bool)
    right[:-1] = (i[1:] == i[:-1]) & (j[1:] == j[:-1] + 1)
    left = np.zeros(len(i), dtype=bool)
    left[1:] = right[:-1]
    down = np.zeros(len(i), dtype=bool)
    inner = np.flatnonzero(i < h - 1)
    down[inner] = walls[i[inner] + 1, j[inner]]
    up = np.zeros(len(i), dtype=bool)
    inner = np.flatnonzero(i > 0)
    up[inner] = walls[i[inner] - 1, j[inner]]
    return i, j, right, down, left, up


def wall_segments(walls: np.ndarray) -> np.ndarray:
    """(S, 4) pieces (x0, y0, x1, y1) of the centre lines of thin walls: from each wall
    pixel's centre to the centre of each wall pixel right of it and below it (a lone
    wall pixel is a point).  For a 4-connected wall the pieces form one unbroken line."""
    return _steps(_wall_links(walls))


def _steps(links) -> np.ndarray:
    """:func:`wall_segments` from the walls' links (:func:`_wall_links`)."""
    i, j, r, d, left, up = links
    x, y = j + 0.5, i + 0.5
    # a wall pixel only reached from the left or from above is already on a piece
    lone = ~(r | d | left | up)
    pieces = [
        np.stack([x[r], y[r], x[r] + 1, y[r]], axis=1),
        np.stack([x[d], y[d], x[d], y[d] + 1], axis=1),
        np.stack([x[lone], y[lone], x[lone], y[lone]], axis=1),
    ]
    return np.concatenate(pieces).astype(np.float64).reshape(-1, 4)


def _wall_chords(
    walls: np.ndarray, centres: np.ndarray, room: float, walled=None
) -> tuple[np.ndarray, np.ndarray]:
    """The centre lines of thin walls as fewer, wider pieces: (S, 4) pieces (x0, y0, x1,
    y1) and (S,) their widths.  The wall pixels are taken a square of ``_CHORD_BLOCK``
    px at a time; where a square's pixel centres (three or more) lie within
    ``_CHORD_WIDTH`` of a line (their principal axis), their steps (:func:`wall_segments`)
    are replaced by one chord along it, as wide as the farthest centre lies off it: the
    chord widened by that holds each centre and so each step between two of them (it is
    convex).  Steps between squares and the squares that fit no line stay as they are
    (width 0), and so do the squares with one of the ``centres`` within ``room`` plus the
    chord's width and half-length of its middle (an element there could not keep clear
    of it).  Kept clear of by G/2 plus its width, a chord keeps every step it stands for
    G/2 away.  ``walled``: the walls' (links, steps) where the caller has them."""
    links, steps = _walled(walls) if walled is None else walled
    i, j = links[:2]
    h, w = np.shape(walls)
    if len(i) == 0:
        return steps, np.zeros(len(steps))
    per_row = -(-w // _CHORD_BLOCK)
    square = (i // _CHORD_BLOCK) * per_row + j // _CHORD_BLOCK
    count = np.bincount(square)
    # about each square's corner, then its mean: small numbers, little rounding
    x = (j % _CHORD_BLOCK) + 0.5
    y = (i % _CHORD_BLOCK) + 0.5
    held = np.maximum(count, 1).astype(np.float64)
    mx = np.bincount(square, weights=x) / held
    my = np.bincount(square, weights=y) / held
    dx, dy = x - mx[square], y - my[square]
    sxx = np.bincount(square, weights=dx * dx)
    syy = np.bincount(square, weights=dy * dy)
    sxy = np.bincount(square, weights=dx * dy)
    angle = 0.5 * np.arctan2(2 * sxy, sxx - syy)  # the principal axis
    ux, uy = np.cos(angle), np.sin(angle)
    t = dx * ux[square] + dy * uy[square]
    off = np.abs(dy * ux[square] - dx * uy[square])
    lo = np.full(len(count), np.inf)
    hi = np.full(len(count), -np.inf)
    wide = np.zeros(len(count))
    np.minimum.at(lo, square, t)
    np.maximum.at(hi, square, t)
    np.maximum.at(wide, square, off)
    fits = np.flatnonzero((count >= 3) & (wide <= _CHORD_WIDTH))
    cx = (fits % per_row) * _CHORD_BLOCK + mx[fits]
    cy = (fits // per_row) * _CHORD_BLOCK + my[fits]
    # each fitting square's chord (x0, y0, x1, y1): from its least to its greatest t
    ends = np.stack(
        [
            cx + lo[fits] * ux[fits],
            cy + lo[fits] * uy[fits],
            cx + hi[fits] * ux[fits],
            cy + hi[fits] * uy[fits],
        ],
        axis=1,
    ).reshape(-1, 4)
    if len(centres) and len(fits):
        mid = 0.5 * (ends[:, :2] + ends[:, 2:])
        reach = 0.5 * (hi[fits] - lo[fits]) + wide[fits] + room
        found = _kd_tree(mid).sparse_distance_matrix(
            _kd_tree(centres), float(reach.max()), output_type="ndarray"
        )
        k, e = found["i"], found["j"]
        kx, ky = _closest_on_segment(*ends[k].T, centres[e, 0], centres[e, 1])
        close = np.hypot(kx - centres[e, 0], ky - centres[e, 1]) <= wide[fits][k] + room
        clear = np.ones(len(fits), dtype=bool)
        clear[k[close]] = False
        fits, ends = fits[clear], ends[clear]
    # a step stays unless both its ends lie in a square that has a chord
    chorded = np.zeros(len(count), dtype=bool)
    chorded[fits] = True
    first = (steps[:, 1] // _CHORD_BLOCK) * per_row + steps[:, 0] // _CHORD_BLOCK
    last = (steps[:, 3] // _CHORD_BLOCK) * per_row + steps[:, 2] // _CHORD_BLOCK
    first, last = first.astype(np.int64), last.astype(np.int64)
    stays = (first != last) | ~chorded[first]
    chords = ends
    # a hair more than the farthest centre: the chord's ends and the distances are rounded
    width = np.concatenate([wide[fits] + 1e-9, np.zeros(int(stays.sum()))])
    return np.concatenate([chords, steps[stays]]), width


@dataclass
class _Pieces:
    """The pieces of the region's boundary (and walls) the elements keep clear of:
    (S, 4) ``segs``, their ``widen`` (None: all 0) and its largest, and their kd-trees
    (:func:`_segment_trees`)."""

    segs: np.ndarray
    widen: np.ndarray | None
    widest: float
    trees: list
    columns: tuple = ()  # segs' four columns, each contiguous: gathers of a column are cheap

    def __post_init__(self):
        self.columns = tuple(np.ascontiguousarray(v) for v in self.segs.T)


def _walled(walls: np.ndarray) -> tuple:
    """The walls' links (:func:`_wall_links`) and steps (:func:`wall_segments`), found
    once (a picture-sized np.nonzero) for the chords and for the last round's steps."""
    links = _wall_links(walls)
    return links, _steps(links)


def _region_pieces(mask, walls, centres, gap, chords=True, walled=None) -> _Pieces:
    """The boundary's pieces (:func:`boundary_segments`) and the walls' (:func:`wall_segments`;
    with ``chords``, for more than ``_WALL_CHORD_ELEMENTS`` elements (``centres``: the
    placed ones'), :func:`_wall_chords`, none where a centre is within G/2 +
    ``_CHORD_ROOM`` of one).  ``walled``: :func:`_walled` of the walls where the caller
    has it."""
    segs = boundary_segments(mask)
    widen = None
    if walls is not None and walls.any():
        walled = _walled(walls) if walled is None else walled
        if chords and len(centres) > _WALL_CHORD_ELEMENTS:
            chords, width = _wall_chords(walls, centres, 0.5 * gap + _CHORD_ROOM, walled)
            widen = np.concatenate([np.zeros(len(segs)), width])
            segs = np.concatenate([segs, chords])
        else:
            segs = np.concatenate([segs, walled[1]])
    widest = 0.0 if widen is None or len(widen) == 0 else float(widen.max())
    return _Pieces(segs, widen, widest, _segment_trees(segs, widen))


def _seg_gap(unit, px, py, qx, qy, cx, cy, r, cos, sin, nx, ny):
    """Left side of (2): gap between an element and a segment along n (element → segment)."""
    return (
        np.minimum(nx * px + ny * py, nx * qx + ny * qy)
        - nx * cx
        - ny * cy
        - r * unit.support(nx, ny, cos, sin)
    )


def _closest_on_segment(px, py, qx, qy, x, y):
    ex, ey = qx - px, qy - py
    ll = ex * ex + ey * ey
    t = np.clip(((x - px) * ex + (y - py) * ey) / np.where(ll > 0, ll, 1.0), 0.0, 1.0)
    return px + t * ex, py + t * ey


def _near_segments(unit, c, r, cos, sin, budget, half, pieces, prev, act, point_trees, threads=1):
    """(Element, piece) rows whose gap could close to < ``half`` (plus the piece's width,
    ``pieces``: :class:`_Pieces`) this round; their n and current gap to the piece's
    centre line, ordered by element then piece.  The candidates are worked in pieces by
    up to ``threads`` threads (:func:`_in_pieces`: the same rows in the same order), and
    only the rows kept are sorted (each row's figures do not depend on the others: the
    same rows in the same order as sorting the two to three times as many candidates)."""
    empty = np.zeros(0)
    segs, widen = pieces.segs, pieces.widen
    if len(act) == 0 or len(segs) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), empty, empty, empty
    k, s = _near_items(point_trees, pieces.trees, half + _SELECT)  # the trees hold the widths
    # every element's face normals, turned, once: gathered per row (the same numbers)
    normals = unit.face_normals(cos, sin, faces_first=True) if not unit.curved else None

    def kept(k, s):
        """The candidates (k, s) (position in act, piece) that make rows, with n and gap."""
        e = act[k]
        px, py, qx, qy = (v.take(s) for v in pieces.columns)
        x, y = c[e, 0], c[e, 1]
        kx, ky = _closest_on_segment(px, py, qx, qy, x, y)
        d = np.hypot(kx - x, ky - y)
        # a wide piece (a chord) is kept clear of by its width more
        reach = half if widen is None else half + widen[s]
        keep = d < unit.circumradius * r[e] + budget[e] + reach + _SELECT
        e, s, px, py, qx, qy, x, y, kx, ky, d = _select(keep, e, s, px, py, qx, qy, x, y, kx, ky, d)
        prev_n = _lookup(prev, e * len(segs) + s)
        with np.errstate(invalid="ignore", divide="ignore"):
            tx, ty = np.where(d > 0, (kx - x) / d, 1.0), np.where(d > 0, (ky - y) / d, 0.0)
        # the piece's normal, turned towards the element's outside
        sx, sy = -(qy - py), qx - px
        sl = np.hypot(sx, sy)
        with np.errstate(invalid="ignore", divide="ignore"):
            sx, sy = sx / sl, sy / sl  # NaN for a point piece (a lone wall pixel): never chosen
        flip = np.where(sx * (kx - x) + sy * (ky - y) < 0, -1.0, 1.0)
        # in order of preference: the piece's own normal, the element's faces, last round's
        # n, the direction of the nearest point (beside a reflex corner of the region)
        # (the candidates' gaps written into one array, their directions built only for the
        # one chosen)
        nsx, nsy = sx * flip, sy * flip
        args = tuple(v[:, None] for v in (px, py, qx, qy, x, y, r[e], cos[e], sin[e]))
        gap_for = _gaps_of_rows(_seg_gap, unit, args)
        gap_of = gap_for(slice(None))
        faces = len(unit.faces.normals) if not unit.curved else 0
        g = np.empty((faces + 3, len(e))).T  # candidate-major, as in _best_pair_directions
        g[:, 0] = gap_of(nsx[:, None], nsy[:, None])[:, 0]
        if faces:  # worked face by face along the rows, as in _face_gaps
            fx, fy = (v.take(e, axis=1) for v in normals)
            # along its own faces the element reaches out by the shape's offsets
            p_, q_ = fx * px + fy * py, fx * qx + fy * qy
            g[:, 1 : 1 + faces].T[:] = (
                np.minimum(p_, q_) - fx * x - fy * y - r[e] * unit.faces.offsets[:, None]
            )
        # last round's n: new rows have none (NaN, never chosen)
        known = np.flatnonzero(np.isfinite(prev_n[:, 0]))
        g[:, -2] = np.nan
        g[known, -2] = gap_for(known)(prev_n[known, 0:1], prev_n[known, 1:2])[:, 0]
        g[:, -1] = gap_of(tx[:, None], ty[:, None])[:, 0]

        def direction_of(k):
            """The direction of candidate k of each row: the piece's normal, a face normal,
            last round's n or the nearest point's."""
            bx = np.where(k == 0, nsx, np.where(k == faces + 2, tx, prev_n[:, 0]))
            by = np.where(k == 0, nsy, np.where(k == faces + 2, ty, prev_n[:, 1]))
            on_face = np.flatnonzero((k >= 1) & (k <= faces))
            if len(on_face):
                bx[on_face], by[on_face] = unit.face_normal(k[on_face] - 1, cos[e[on_face]], sin[e[on_face]])
            return bx, by

        curved = unit.curved and unit.semi_axes[0] != unit.semi_axes[1]  # circles: nearest point
        enough = (half if widen is None else half + widen[s]) + budget[e] + _SELECT
        bx, by, best = _best_direction(
            gap_for, g, direction_of, np.arctan2(ty, tx) if curved else None, enough
        )
        keep = best < enough
        return _select(keep, e, s, bx, by, best)

    e, s, bx, by, best = _in_pieces(kept, threads, k, s)
    at = np.argsort(e * len(segs) + s, kind="stable")  # keys unique: as in _near_pairs
    return tuple(v.take(at) for v in (e, s, bx, by, best))


# --------------------------------------------------------------------- constraints
def _mix(u: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser of uint64 words (wrapping arithmetic): every input bit
    moves the high bits, so a float's sign or exponent alone tells two hashes apart."""
    u = u ^ (u >> np.uint64(30))
    u = u * np.uint64(0xBF58476D1CE4E5B9)
    u = u ^ (u >> np.uint64(27))
    u = u * np.uint64(0x94D049BB133111EB)
    return u ^ (u >> np.uint64(31))


@dataclass
class _Rows:
    """The round's constraints: (1) for pairs (i, j), (2) for (element e, piece)."""

    i: np.ndarray
    j: np.ndarray
    nx: np.ndarray
    ny: np.ndarray
    hi: np.ndarray  # h_i(n)
    hj: np.ndarray  # h_j(−n)
    e: np.ndarray
    s: np.ndarray  # piece index
    sx: np.ndarray
    sy: np.ndarray
    he: np.ndarray  # h_e(n)
    sm: np.ndarray  # min(n·p, n·q) of the piece

    def live(self, r) -> "_Rows":
        """The rows whose elements are all still present (size > 0)."""
        kp = (r[self.i] > 0) & (r[self.j] > 0)
        ks = r[self.e] > 0
        return _Rows(
            *(getattr(self, f)[kp] for f in ("i", "j", "nx", "ny", "hi", "hj")),
            *(getattr(self, f)[ks] for f in ("e", "s", "sx", "sy", "he", "sm")),
        )

    def tightest_pieces(self) -> "_Rows":
        """The same constraints with fewer piece rows: rows of one element along the same
        n have the same left side of (2) but for min(n·p, n·q) (h_e(n) is the element's),
        so only the one with the least binds; the others are dropped (first of equals,
        rows otherwise in their order).  Beside a wall's 1-px staircase most pieces of an
        element share its face normals or an axis."""
        if len(self.e) < 2:
            return self
        # group the rows by one int64 key, the element then a hash of n's bits (argsort of
        # a nearly sorted key: a fraction of a four-key lexsort); the exact check below
        # falls back to that lexsort if two directions of an element share a hash
        # (+ 0.0 turns −0.0 into 0.0: equal directions, equal bits)
        bits = _mix(_mix((self.sx + 0.0).view(np.uint64)) + (self.sy + 0.0).view(np.uint64))
        key = (self.e.astype(np.uint64) << np.uint64(40)) | (bits >> np.uint64(24))
        order = np.argsort(key, kind="stable")
        k = key[order]
        start = np.flatnonzero(np.concatenate([[True], k[1:] != k[:-1]]))
        group = np.repeat(np.arange(len(start)), np.diff(np.append(start, len(k))))
        sx, sy, sm = self.sx[order], self.sy[order], self.sm[order]
        if (
            np.array_equal(sx, sx[start][group])
            and np.array_equal(sy, sy[start][group])
            and np.isfinite(sm).all()
        ):
            least = sm == np.minimum.reduceat(sm, start)[group]
            hit = np.flatnonzero(least)  # rows of a group in their order: the first wins
            first = np.ones(len(hit), dtype=bool)
            first[1:] = group[hit[1:]] != group[hit[:-1]]
            ks = np.sort(order[hit[first]])
        else:
            order = np.lexsort((self.sm, self.sy, self.sx, self.e))
            e, sx, sy = self.e[order], self.sx[order], self.sy[order]
            first = np.ones(len(order), dtype=bool)
            first[1:] = (e[1:] != e[:-1]) | (sx[1:] != sx[:-1]) | (sy[1:] != sy[:-1])
            ks = np.sort(order[first])
        return _Rows(
            self.i,
            self.j,
            self.nx,
            self.ny,
            self.hi,
            self.hj,
            *(getattr(self, f)[ks] for f in ("e", "s", "sx", "sy", "he", "sm")),
        )

    def pair_slack(self, c, r, gap):
        i, j = self.i, self.j
        return (
            self.nx * (c[j, 0] - c[i, 0])
            + self.ny * (c[j, 1] - c[i, 1])
            - self.hi * r[i]
            - self.hj * r[j]
            - gap
        )

    def seg_slack(self, c, r, half):
        e = self.e
        return self.sm - self.sx * c[e, 0] - self.sy * c[e, 1] - self.he * r[e] - half


def _shrink_to_fit(rows: _Rows, c, r, gap, need):
    """Shrink elements about their centres until every row of elements still present has
    slack >= ``need``.  A row short by v is met by scaling both its elements by
    1 − v/(h_i·r_i + h_j·r_j) (a piece's row: 1 − v/(h_e·r_e)); each element takes the
    smallest factor of its rows, and shrinking only adds slack to every other row, so one
    pass meets them all.  A row that no size > 0 can meet (two centres closer than the
    gap, a centre closer than gap/2 to the border) drops one element: the smaller of the
    pair, or the element.  Returns the sizes and how many elements were dropped."""
    r = r.copy()
    dropped = 0
    for _ in range(8):  # one shrinking pass suffices; more only after drops
        live_p = (r[rows.i] > 0) & (r[rows.j] > 0)
        live_s = r[rows.e] > 0
        vp = np.where(live_p, need - rows.pair_slack(c, r, gap), 0.0)
        vs = np.where(live_s, need - rows.seg_slack(c, r, 0.5 * gap), 0.0)
        short_p, short_s = vp > 0, vs > 0
        if not (short_p.any() or short_s.any()):
            return r, dropped
        # aim at 2·need so that rounding cannot leave a row a hair short of need
        with np.errstate(divide="ignore", invalid="ignore"):
            fp = (vp + need) / (rows.hi * r[rows.i] + rows.hj * r[rows.j])
            fs = (vs + need) / (rows.he * r[rows.e])
        hopeless_p = short_p & ~(fp < 1)
        hopeless_s = short_s & ~(fs < 1)
        if hopeless_p.any() or hopeless_s.any():
            i, j = rows.i[hopeless_p], rows.j[hopeless_p]
            smaller = np.where((r[i] < r[j]) | ((r[i] == r[j]) & (i > j)), i, j)
            gone = np.unique(np.concatenate([smaller, rows.e[hopeless_s]]))
            r[gone] = 0.0
            dropped += len(gone)
            continue
        cut = np.zeros(len(r))
        np.maximum.at(cut, rows.i[short_p], fp[short_p])
        np.maximum.at(cut, rows.j[short_p], fp[short_p])
        np.maximum.at(cut, rows.e[short_s], fs[short_s])
        r *= 1.0 - cut
    raise RuntimeError("compaction: could not restore separation after shrinking")


def _revert_hopeless(rows: _Rows, c, r, new_c, new_r, gap, need):
    """Put back at their round's start (centre and size, in place) the elements of every
    row that no shrinking could meet at the new centres (an approximate solution may
    bring two centres closer than the gap); repeated until none is left, which ends at
    the latest when all are back (the start meets every row).  Returns how many were put
    back: without this, shrinking would drop one element of each such row."""
    back = np.zeros(len(r), dtype=bool)
    zero = np.zeros(len(r))
    for _ in range(len(r) + 1):  # a few passes of whole-array work, seldom more than one
        live_p = (new_r[rows.i] > 0) & (new_r[rows.j] > 0)
        live_s = new_r[rows.e] > 0
        # with sizes 0 a row has its most slack: short even then, shrinking cannot help
        hp = live_p & (rows.pair_slack(new_c, zero, gap) <= 2 * need)
        hs = live_s & (rows.seg_slack(new_c, zero, 0.5 * gap) <= 2 * need)
        if not (hp.any() or hs.any()):
            break
        idx = np.unique(np.concatenate([rows.i[hp], rows.j[hp], rows.e[hs]]))
        idx = idx[~back[idx]]
        if len(idx) == 0:  # every such row is between elements at their start: hopeless there too
            break
        back[idx] = True
        new_c[idx], new_r[idx] = c[idx], r[idx]
    return int(back.sum())


def _lp_columns(k, elems, delta, move_cost, weight, lo_dr, hi_dr):
    """Cost and bounds of the columns of :func:`_solve_lp`: ``k`` per element (Δx⁺, Δx⁻,
    Δy⁺, Δy⁻, Δr when moves cost, else Δx, Δy, Δr)."""
    split = k == 5
    ncol = k * len(elems)
    cost = np.zeros(ncol)
    lo = np.zeros(ncol)
    hi = np.empty(ncol)
    d = delta[elems]
    if split:
        for m in range(4):
            hi[m::5] = d
            cost[m::5] = move_cost
    else:
        lo[0::3] = lo[1::3] = -d
        hi[0::3] = hi[1::3] = d
    cost[k - 1 :: k] = -weight[elems]
    lo[k - 1 :: k], hi[k - 1 :: k] = lo_dr[elems], hi_dr[elems]
    return cost, lo, hi


def _solve_tiles(k, n_tiles, model, cost, lo, hi, options, workers):
    """Solve each tile's program with HiGHS (``model``: the element and row bounds of the
    tiles, the rows' lower bounds and the CSR matrix), in ``workers`` threads; returns x,
    the simplex iterations and the tiles not solved to optimality (those keep x = 0)."""
    import highspy

    from ..quiet import quiet_highs

    bounds_e, r_cut, row_lo, r_start, index, value = model
    ncol = len(cost)
    x = np.zeros(ncol)
    inf = highspy.kHighsInf
    optimal = highspy.HighsModelStatus.kOptimal
    rowwise = highspy.MatrixFormat.kRowwise

    def solve(h, tiles_of_worker):
        """Solve the given tiles, one small model each, with solver ``h``; a tile the
        solver does not finish stays where it is (x = 0, a feasible point)."""
        iters = failed = 0
        for t in tiles_of_worker:  # a loop over tiles, not pairs
            c0, c1 = k * bounds_e[t], k * bounds_e[t + 1]
            a0, a1 = r_cut[0][t], r_cut[1][t]
            lp = highspy.HighsLp()
            lp.num_col_ = c1 - c0
            lp.num_row_ = a1 - a0
            lp.col_cost_, lp.col_lower_, lp.col_upper_ = cost[c0:c1], lo[c0:c1], hi[c0:c1]
            lp.row_lower_ = row_lo[a0:a1]
            lp.row_upper_ = np.full(a1 - a0, inf)
            lp.a_matrix_.format_ = rowwise
            lp.a_matrix_.start_ = (r_start[a0 : a1 + 1] - r_start[a0]).astype(np.int32)
            lp.a_matrix_.index_ = index[r_start[a0] : r_start[a1]]
            lp.a_matrix_.value_ = value[r_start[a0] : r_start[a1]]
            h.passModel(lp)
            h.run()
            if h.getModelStatus() == optimal:
                x[c0:c1] = h.getSolution().col_value
                iters += h.getInfo().simplex_iteration_count
            else:
                failed += 1
        return iters, failed

    # HiGHS lets go of the interpreter while it solves: tiles are independent programs,
    # so the workers' threads solve them side by side (each tile's answer is the same
    # whichever worker solves it)
    workers = max(1, min(workers, n_tiles // _TILES_PER_WORKER))
    solvers = [quiet_highs() for _ in range(workers)]  # made here: silencing is process-wide
    for h in solvers:
        for key, value_ in options.items():
            h.setOptionValue(key, value_)
    jobs = [range(w, n_tiles, workers) for w in range(workers)]
    if workers == 1:
        done = [solve(solvers[0], jobs[0])]
    else:

        def work(h, job):
            try:
                return solve(h, job)
            finally:  # a thread that ran HiGHS ends its scheduler before it exits, as
                # highspy's own solver threads do (a scheduler left behind can deadlock)
                reset = getattr(highspy.Highs, "resetThreadScheduler", None)
                if reset is not None:
                    reset(False)

        with ThreadPoolExecutor(workers) as pool:
            done = list(pool.map(work, solvers, jobs))
    iters, failed = (sum(v) for v in zip(*done, strict=True))
    return x, iters, failed


def _solve_lp(
    rows: _Rows, act, c, r, gap, delta, lo_dr, hi_dr, weight, tile, options, move_cost=0.0, workers=1
):
    """The round's program in displacements (Δc, Δr) of the active elements, one HiGHS
    model per tile; returns Δc (N, 2), Δr (N,), the simplex iterations and the number of
    tiles HiGHS did not solve to optimality (those keep Δ = 0)."""

    n = len(r)
    # active elements ordered by tile: each tile's columns are one contiguous block
    t_act = tile[act]
    order = np.argsort(t_act, kind="stable")
    elems = act[order]
    tiles, first = np.unique(t_act[order], return_index=True)
    bounds_e = np.append(first, len(elems))
    col = np.full(n, -1, dtype=np.int64)
    col[elems] = np.arange(len(elems))
    if (col[rows.i] < 0).any() or (col[rows.j] < 0).any() or (col[rows.e] < 0).any():
        raise RuntimeError("compaction: a row refers to an element without a size")
    ps = rows.pair_slack(c, r, gap)
    # a pair across two tiles becomes a wall between them: each side may take half of
    # the slack, so the tiles' programs are independent
    cross = tile[rows.i] != tile[rows.j]
    inner = ~cross
    # columns per element: Δx⁺, Δx⁻, Δy⁺, Δy⁻, Δr when moves cost (|Δc| in the objective),
    # else Δx, Δy, Δr
    split = move_cost > 0
    k = 5 if split else 3

    def entries(cidx, ax, ay, ah):
        """Column indices and values of one element's part of the rows."""
        if split:
            return (
                np.stack([cidx, cidx + 1, cidx + 2, cidx + 3, cidx + 4], axis=1),
                np.stack([ax, -ax, ay, -ay, ah], axis=1),
            )
        return np.stack([cidx, cidx + 1, cidx + 2], axis=1), np.stack([ax, ay, ah], axis=1)

    nx, ny, hi_, hj_ = rows.nx[inner], rows.ny[inner], rows.hi[inner], rows.hj[inner]
    ii, vi = entries(k * col[rows.i[inner]], -nx, -ny, -hi_)
    ij, vj = entries(k * col[rows.j[inner]], nx, ny, -hj_)
    p_idx, p_val = np.concatenate([ii, ij], axis=1), np.concatenate([vi, vj], axis=1)
    p_lo = -ps[inner]
    p_tile = tile[rows.i[inner]]
    # one-element rows: pieces, and the two halves of each cross pair
    one = np.concatenate([rows.e, rows.i[cross], rows.j[cross]])
    o_idx, o_val = entries(
        k * col[one],
        np.concatenate([-rows.sx, -rows.nx[cross], rows.nx[cross]]),
        np.concatenate([-rows.sy, -rows.ny[cross], rows.ny[cross]]),
        np.concatenate([-rows.he, -rows.hi[cross], -rows.hj[cross]]),
    )
    half_s = 0.5 * ps[cross]
    o_lo = -np.concatenate([rows.seg_slack(c, r, 0.5 * gap), half_s, half_s])
    o_tile = tile[one]
    # every row in one CSR layout ordered by tile (a tile's pair rows, then its one-element
    # rows), columns numbered within the row's tile: a tile's model is then plain slices
    nr_p, nr_o = len(p_lo), len(o_lo)
    r_tile = np.concatenate([p_tile, o_tile])
    order = np.lexsort((np.repeat([0, 1], [nr_p, nr_o]), r_tile))
    r_tile = r_tile[order]
    # column numbers within the tile: minus the tile's first column
    first_col = (k * bounds_e[np.searchsorted(tiles, r_tile)]).astype(np.int32)
    ent = np.full((nr_p + nr_o, 2 * k), -1, dtype=np.int32)
    val = np.zeros((nr_p + nr_o, 2 * k))
    ent[:nr_p], val[:nr_p] = p_idx, p_val
    ent[nr_p:, :k], val[nr_p:, :k] = o_idx, o_val
    ent, val = ent[order], val[order]
    real = ent >= 0
    ent -= first_col[:, None]
    index = ent[real]
    value = val[real]
    del ent, val
    # the current state (0) is feasible
    row_lo = np.minimum(np.concatenate([p_lo, o_lo])[order], 0.0)
    r_start = np.zeros(len(r_tile) + 1, dtype=np.int64)
    np.cumsum(real.sum(axis=1), out=r_start[1:])
    r_cut = np.searchsorted(r_tile, tiles, side="left"), np.searchsorted(r_tile, tiles, side="right")

    cost, lo, hi = _lp_columns(k, elems, delta, move_cost, weight, lo_dr, hi_dr)
    model = (bounds_e, r_cut, row_lo, r_start, index, value)
    x, iters, failed = _solve_tiles(k, len(tiles), model, cost, lo, hi, options, workers)
    dc = np.zeros((n, 2))
    dr = np.zeros(n)
    if split:
        dc[elems, 0], dc[elems, 1], dr[elems] = x[0::5] - x[1::5], x[2::5] - x[3::5], x[4::5]
    else:
        dc[elems, 0], dc[elems, 1], dr[elems] = x[0::3], x[1::3], x[2::3]
    return dc, dr, iters, failed


@functools.cache
def _csr_matvec():
    """scipy's CSR and CSC product kernels (private functions) where they are there and
    give ``m @ v`` and ``m.T @ w`` on a small case, else None: a scipy that moves or
    changes them falls back to the public product instead of failing."""
    import scipy.sparse as sp

    try:
        from scipy.sparse._sparsetools import csc_matvec, csr_matvec

        m = sp.csr_matrix(np.array([[1.0, 2.0, 0.0], [0.0, 3.0, -4.0]]))
        v, w, out, out_t = np.array([1.0, -1.0, 0.5]), np.array([2.0, -3.0]), np.zeros(2), np.zeros(3)
        csr_matvec(2, 3, m.indptr, m.indices, m.data, v, out)
        csc_matvec(3, 2, m.indptr, m.indices, m.data, w, out_t)
    except Exception:  # any failure means: use the public product
        return None
    ok = np.array_equal(out, m @ v) and np.array_equal(out_t, m.T @ w)
    return (csr_matvec, csc_matvec) if ok else None


def _product(m, v, out, transpose=False):
    """``out`` = m @ v (``transpose``: m.T @ v) for a CSR matrix m, written into ``out``:
    scipy's own kernels (the same sums in the same order), without the checks and the
    new array of ``m @ v``, which cost a fifth of a PDHG step's product on a program of
    4000 elements.  m.T @ v reads m's rows as the columns of m.T (CSC): it adds each row's
    entries into ``out`` in row order, the sums of m.T.tocsr() @ v exactly, without the
    transposed copy and faster (scattered writes into the short ``out`` instead of
    gathered reads from the long v)."""
    kernels = _csr_matvec()
    if kernels is None:
        out[:] = m.T @ v if transpose else m @ v
        return out
    out.fill(0.0)  # the kernels add to out
    rows, cols = m.shape
    if transpose:
        kernels[1](cols, rows, m.indptr, m.indices, m.data, v, out)
    else:
        kernels[0](rows, cols, m.indptr, m.indices, m.data, v, out)
    return out


def _pdhg_program(rows: _Rows, act, c, r, gap, delta, lo_dr, hi_dr, weight):
    """The round's program for :func:`_solve_pdhg`: ``A x >= b`` (CSR, and its index,
    value and row-start arrays), the bounds and the cost of x = (Δx, Δy, Δr) per active
    element."""
    import scipy.sparse as sp

    n = len(r)
    # int32 column numbers and row starts: scipy keeps a CSR matrix's indices in int32
    # where they fit, and would otherwise copy them
    col = np.full(n, -1, dtype=np.int32)
    col[act] = np.arange(len(act))
    ncol = 3 * len(act)
    npair, nseg = len(rows.i), len(rows.e)
    # A x >= b with x = (Δx, Δy, Δr) per active element: pair rows (6 entries), then
    # piece rows (3 entries); CSR built directly, rows are already in order
    ci, cj, ce = 3 * col[rows.i], 3 * col[rows.j], 3 * col[rows.e]
    if (ci < 0).any() or (cj < 0).any() or (ce < 0).any():
        raise RuntimeError("compaction: a row refers to an element without a size")
    index = np.concatenate(
        [
            np.stack([ci, ci + 1, ci + 2, cj, cj + 1, cj + 2], axis=1).ravel(),
            np.stack([ce, ce + 1, ce + 2], axis=1).ravel(),
        ]
    )
    value = np.concatenate(
        [
            np.stack([-rows.nx, -rows.ny, -rows.hi, rows.nx, rows.ny, -rows.hj], axis=1).ravel(),
            np.stack([-rows.sx, -rows.sy, -rows.he], axis=1).ravel(),
        ]
    )
    start = np.concatenate([np.arange(0, 6 * npair + 1, 6), 6 * npair + np.arange(3, 3 * nseg + 1, 3)])
    if 6 * npair + 3 * nseg < 2**31 and ncol < 2**31:
        start = start.astype(np.int32)
    a = sp.csr_matrix((value, index, start), shape=(npair + nseg, ncol))
    # the current state (x = 0) is feasible
    b = np.minimum(-np.concatenate([rows.pair_slack(c, r, gap), rows.seg_slack(c, r, 0.5 * gap)]), 0.0)
    lo, hi, cost = np.empty(ncol), np.empty(ncol), np.zeros(ncol)
    d = delta[act]
    lo[0::3] = lo[1::3] = -d
    hi[0::3] = hi[1::3] = d
    lo[2::3], hi[2::3] = lo_dr[act], hi_dr[act]
    cost[2::3] = -weight[act]
    return a, b, lo, hi, cost, (index, value, start)


def _blocks(indptr, parts):
    """``parts`` (at most) ranges of rows of a CSR matrix (``indptr``: its row starts)
    holding about equal numbers of entries: [(first row, end row, first entry, end entry,
    the block's own row starts)]."""
    rows = len(indptr) - 1
    cuts = np.searchsorted(indptr, np.linspace(0, indptr[-1], parts + 1)[1:-1])
    bounds = np.unique(np.concatenate([[0], np.minimum(cuts, rows), [rows]]))
    out = []
    for r0, r1 in zip(bounds[:-1], bounds[1:], strict=True):  # a loop over a few blocks
        e0, e1 = int(indptr[r0]), int(indptr[r1])
        out.append((int(r0), int(r1), e0, e1, (indptr[r0 : r1 + 1] - e0).astype(indptr.dtype)))
    return out


def _block_product(kernel, m, block, v, out):
    """``out[r0:r1]`` = the rows r0..r1 of the CSR matrix ``m`` times ``v`` (``block``:
    one of :func:`_blocks`), by scipy's CSR kernel: each row's sum as in ``m @ v``."""
    r0, r1, e0, e1, indptr = block
    part = out[r0:r1]
    part.fill(0.0)  # the kernel adds to out
    kernel(r1 - r0, m.shape[1], indptr, m.indices[e0:e1], m.data[e0:e1], v, part)


class _HalpernPdhg:
    """The state of :func:`_solve_pdhg`'s iteration on one program ``A x >= b``: the
    iterates, the anchor, the step buffers and, for a large program, its blocks of rows
    and of columns (each block's views of the arrays made once: a slice per step and
    array would cost the interpreter more than a block's arithmetic) and the threads that
    work them side by side."""

    def __init__(self, a, b, bounds, steps, threads):
        lo, hi, cost = bounds
        tau, sigma = steps
        ncol, m = a.shape[1], a.shape[0]
        self.a, self.b = a, b
        dt = b.dtype  # every vector in the program's precision (float64, or float32)
        self.x, self.y = np.zeros(ncol, dt), np.zeros(m, dt)
        # the anchor z₀ = (x0, y0): the start (0) until the first restart
        self.x0, self.y0, self.anchored = np.zeros(ncol, dt), np.zeros(m, dt), False
        # every step works in these buffers: a fresh array per step would be fresh memory
        # from the system each time (page faults cost about as much as the arithmetic)
        self.xt, self.z, scratch, self.res_x, self.aty = (np.zeros(ncol, dt) for _ in range(5))
        self.yt, y_scratch, self.res_y = np.empty(m, dt), np.empty(m, dt), np.empty(m, dt)
        self.kernels = _csr_matvec()
        nnz = len(a.data)
        parts = 1 if self.kernels is None else max(1, min(threads, nnz // _PDHG_BLOCK_ENTRIES))
        if parts > 1:
            # Aᵀy by the rows of Aᵀ (CSR, entries in A's row order): each sum in the order
            # of _product's scatter, so the same numbers, and a block of columns per thread
            self.at = a.T.tocsr()
            row_blocks, col_blocks = _blocks(a.indptr, parts), _blocks(self.at.indptr, parts)
        else:
            self.at, row_blocks, col_blocks = None, [(0, m)], [(0, ncol)]
        x_side = (
            self.x,
            self.xt,
            self.z,
            self.aty,
            cost,
            tau,
            lo,
            hi,
            self.res_x,
            1.0 / tau,
            self.x0,
            scratch,
        )
        self.col_views = [(blk, *(v[blk[0] : blk[1]] for v in x_side)) for blk in col_blocks]
        y_side = (self.y, self.yt, b, sigma, np.zeros(m, dt), self.res_y, 1.0 / sigma, self.y0, y_scratch)
        self.row_views = [(blk, *(v[blk[0] : blk[1]] for v in y_side)) for blk in row_blocks]

    def each(self, fn, views, *args):
        """fn(block's views, *args) for every block, side by side (:func:`cvt.threads.side_by_side`)."""
        if len(views) == 1:
            fn(views[0], *args)
        else:  # the first block on this thread, the others on the process's pool
            side_by_side(*(functools.partial(fn, v, *args) for v in views))

    def primal(self, views, w, check, product):
        """On a block of columns: x's Halpern update from last step's z (``w``; None
        after a restart or at the start), Aᵀy (``product``), then x̃ = clip(x − τ(c −
        Aᵀy)) in place (np.clip with array bounds costs several of these passes),
        z = 2x̃ − x and, if ``check``, the residual's terms (T's own norm: 1/τ, 1/σ)."""
        blk, xb, xtb, zb, atyb, costb, taub, lob, hib, rxb, itb, x0b, sb = views
        if w is not None:  # z ← w·(2T(z) − z) + (1 − w)·z₀, x's part (z = 2x̃ − x)
            np.multiply(zb, w, out=xb)
            if self.anchored:
                xb += np.multiply(x0b, 1.0 - w, out=sb)
        if product:
            if self.at is not None:
                _block_product(self.kernels[0], self.at, blk, self.y, self.aty)
            else:
                _product(self.a, self.y, self.aty, transpose=True)
        np.subtract(atyb, costb, out=xtb)
        xtb *= taub
        xtb += xb
        np.maximum(xtb, lob, out=xtb)  # np.clip's order: lo, then hi (lo <= hi)
        np.minimum(xtb, hib, out=xtb)
        np.multiply(xtb, 2.0, out=zb)
        zb -= xb
        if check:
            np.subtract(xtb, xb, out=rxb)
            np.multiply(rxb, rxb, out=rxb)
            rxb *= itb

    def dual(self, views, w, check):
        """On a block of rows: ỹ = max(0, y + σ(b − A z)), then, if ``check``, the
        residual's terms, else y's Halpern update (``w``)."""
        blk, yb, ytb, bb, sigb, zero, ryb, isb, _, _ = views
        if self.at is not None:
            _block_product(self.kernels[0], self.a, blk, self.z, self.yt)
        else:
            _product(self.a, self.z, self.yt)
        np.subtract(bb, ytb, out=ytb)
        ytb *= sigb
        ytb += yb
        np.maximum(ytb, zero, out=ytb)  # against an array: a scalar 0 is ~4x slower
        if check:
            dy = np.subtract(ytb, yb, out=ryb)
            np.multiply(dy, dy, out=dy)
            dy *= isb
        else:
            self.dual_update(views, w)

    def dual_update(self, views, w):
        """y's part of z ← w·(2T(z) − z) + (1 − w)·z₀ on a block of rows."""
        _, yb, ytb, *_, y0b, ysb = views
        yb *= -w
        yb += np.multiply(ytb, 2.0 * w, out=ysb)
        if self.anchored:
            yb += np.multiply(y0b, 1.0 - w, out=ysb)

    def run(self, iterations):
        """Up to ``iterations`` steps (fewer when converged); returns x̃ and the steps."""
        first = None  # fixed-point residual |T(z) − z| after the last restart
        k = steps = 0
        w_x = None  # the Halpern weight x's update still owes (made with the next x̃)
        for steps in range(1, iterations + 1):  # noqa: B007 (returned) a loop over whole-array steps
            check = first is None or steps % _HALPERN_CHECK == 0
            self.each(self.primal, self.col_views, w_x, check, steps > 1)
            w = (k + 1.0) / (k + 2.0)
            self.each(self.dual, self.row_views, w, check)  # no check, no restart: y's update too
            residual = None
            if check:
                # by ufuncs (a BLAS dot wakes its threads, which costs far more than
                # the sum on a busy machine)
                residual = math.sqrt(float(self.res_x.sum()) + float(self.res_y.sum()))
                if first is None:
                    first = residual
                if residual <= _HALPERN_RESTART * first:
                    # restart from T(z): the iteration then converges linearly on a
                    # program like this one, as PDHG with restarts does
                    self.x[:], self.y[:] = self.xt, self.yt
                    self.x0[:], self.y0[:], self.anchored = self.xt, self.yt, True
                    first, k, w_x = None, 0, None
                else:
                    self.each(self.dual_update, self.row_views, w)
                    k, w_x = k + 1, w
            else:
                k, w_x = k + 1, w
            # a fixed point of T is the program's optimum: stop when T(z) = z and x̃
            # meets the rows (small programs; large ones use every step)
            if (
                residual is not None
                and residual < _PDHG_STILL
                and np.max(self.b - self.a @ self.xt, initial=0.0) < _PDHG_STILL
            ):
                break
        return self.xt, steps


def _solve_pdhg(rows: _Rows, act, c, r, gap, delta, lo_dr, hi_dr, weight, iterations, step_ratio, threads=1):
    """The round's program (the same as :func:`_solve_lp`'s, untiled) solved
    approximately by ``iterations`` steps of the primal-dual hybrid gradient method
    (Chambolle-Pock, diagonal steps of Pock & Chambolle 2011), all elements at once, in
    Halpern's reflected form with restarts (r2HPDHG, Lu & Yang 2024; module docstring):
    z ← w·(2·T(z) − z) + (1 − w)·z₀ with w = (k + 1)/(k + 2), z₀ the anchor (the start,
    x = 0, y = 0, until a restart); the answer is the last T(z), which keeps the bounds.

    Starts from x = 0, y = 0 (last round's duals, mapped by pair, were measured no
    better).  Returns Δc (N, 2), Δr (N,), the largest row violation left and the steps
    taken (fewer than ``iterations`` when converged).  The moves and growths always keep
    their bounds (each step is clipped to them); the rows hold only approximately, which
    the caller's float64 check and shrinking make exact.

    A large program's step is split into blocks of rows and of columns worked by up to
    ``threads`` threads (numpy and scipy's kernels let go of the interpreter): every
    entry is computed by the same operations in the same order whatever the split, so
    the result does not depend on ``threads``."""
    n = len(r)
    a, b, lo, hi, cost, (index, value, start) = _pdhg_program(
        rows, act, c, r, gap, delta, lo_dr, hi_dr, weight
    )
    ncol = a.shape[1]
    # diagonal steps: 1 / (row or column sum of |A|), balanced by step_ratio
    absval = np.abs(value)
    col_sum = np.bincount(index, weights=absval, minlength=ncol)
    row_sum = np.add.reduceat(absval, start[:-1]) if len(absval) else np.zeros(0)
    tau = step_ratio / np.maximum(col_sum, 1e-12)
    sigma = 1.0 / (step_ratio * np.maximum(row_sum, 1e-12))
    program = a, b, (lo, hi, cost), (tau, sigma)
    if a.nnz >= _PDHG_SINGLE_ENTRIES:
        # past the processor's cache (A and Aᵀ in float64: ~40 MB at 64 000 squares) the
        # steps are bound by memory traffic, which float32 halves (module docstring,
        # Solvers); the answer within a few 1e-6 px, then checked in float64 as any other
        f = np.float32
        program = (
            a.astype(f),
            b.astype(f),
            (lo.astype(f), hi.astype(f), cost.astype(f)),
            (tau.astype(f), sigma.astype(f)),
        )
    x, steps = _HalpernPdhg(*program, threads).run(iterations)
    # float32's bounds may round outward: the moves and growths keep float64's exactly
    x = np.clip(x.astype(np.float64), lo, hi)
    dc = np.zeros((n, 2))
    dr = np.zeros(n)
    dc[act, 0], dc[act, 1], dr[act] = x[0::3], x[1::3], x[2::3]
    violation = float(np.max(b - a @ x, initial=0.0))
    return dc, dr, violation, steps


# --------------------------------------------------------------------- driver
def _spatial_order(c: np.ndarray) -> np.ndarray:
    """The elements' order along a Z-order (Morton) curve through their centres: worked
    in this order, near elements have near indices, so the gathers of the near pairs'
    search and of the program's sparse products stay within the processor's cache."""
    lo = c.min(axis=0)
    cell = max(float((c.max(axis=0) - lo).max()) / 65535.0, 1.0)  # 16 bits a coordinate
    q = np.floor((c - lo) / cell).astype(np.int64)

    def spread(v):
        """The 16 low bits of v moved to the even bit positions."""
        v = (v | (v << 8)) & 0x00FF00FF
        v = (v | (v << 4)) & 0x0F0F0F0F
        v = (v | (v << 2)) & 0x33333333
        return (v | (v << 1)) & 0x55555555

    return np.argsort(spread(q[:, 0]) | (spread(q[:, 1]) << 1), kind="stable")


def _work_order(c, *arrays) -> tuple:
    """The order a set is worked in (None: the caller's; a large set: Z order, for the
    cache) and ``c`` and the ``arrays`` (None stays None) in that order."""
    if len(c) < _SPATIAL_ORDER_ELEMENTS:
        return None, (c, *arrays)
    order = _spatial_order(c)
    return order, tuple(a if a is None else a[order] for a in (c, *arrays))


def _in_caller_order(order, *arrays) -> tuple:
    """Copies of ``arrays`` (worked in ``order``, None: the caller's) in the caller's order."""
    if order is None:
        return tuple(a.copy() for a in arrays)
    out = tuple(np.empty_like(a) for a in arrays)
    for o, a in zip(out, arrays, strict=True):
        o[order] = a
    return out


def _tiles(c, act, mask, per_tile, k):
    """Tile id per element: squares holding about ``per_tile`` elements each, shifted by
    half a tile on odd rounds so that a pair cut by one tiling is whole in the next."""
    side = math.sqrt(per_tile * mask.sum() / max(len(act), 1))
    off = 0.5 * side * (k % 2)
    t = np.floor((c + off) / side).astype(np.int64)
    return t[:, 0] * (mask.shape[0] // max(int(side), 1) + 3) + t[:, 1]


def _region_mask(region) -> np.ndarray:
    if isinstance(region, Grid):
        return region.inside()
    m = np.asarray(region)
    if m.ndim != 2 or m.size == 0:
        raise InputError(f"region must be a Grid or a 2-D mask, got shape {m.shape}")
    if m.dtype != bool:
        raise InputError(f"region mask must be boolean, got dtype {m.dtype}")
    if not m.any():
        raise InputError("region mask is empty: no pixel is inside the region")
    return m


@dataclass(frozen=True)
class CompactionSettings:
    """How :func:`compact` compacts: every knob in one record.

    Parameters
    ----------
    gap : float
        G px between elements (G/2 to the border and to a wall's centre line).
    rounds : int
        Rounds at most (0: only make the start meet every row).
    move : float
        Per round a centre moves at most ``move`` × its element's in-radius along each axis.
    growth, shrink : float
        Per round a size grows by at most ``growth`` or shrinks by at most ``shrink`` of itself
        (under caps that follow the centres, also how fast a size above its cap shrinks,
        and how far a cap may change within the last round's moves).
    max_growth : float, optional
        Caps each size at (1 + max_growth) × its given size.
    tol : float
        Stop when a round adds less than ``tol`` of the covered area.
    tile_elements : int
        Elements per HiGHS tile (``solver="highs"``).
    move_cost : float
        Cost of |Δc| in the objective (> 0 solves with HiGHS).
    lp_options : dict, optional
        Extra HiGHS options.
    threads : int, optional
        Threads that solve the tiles side by side, or work a large PDHG program's blocks
        and the near pairs' pieces (None: the cores this process may use); the result
        does not depend on it.
    solver : str
        "pdhg" (each round's whole program by ``iterations`` PDHG steps at most) or "highs"
        (HiGHS' dual simplex per tile); either way every round is checked exactly.
    iterations : int
        PDHG steps per round at most.
    fairness : float
        Where size caps (``max_sizes``) are given, element i's growth is weighed by
        r_i·(cap_i / r_i)^fairness in the objective, so that elements short of their caps
        come first (0: by r_i alone, as without caps; 2, the default: the gradient of
        Σ cap_i²·ln r_i; module docstring, Sizes and density).
    """

    gap: float = 0.0
    rounds: int = 4
    move: float = 0.5
    growth: float = 0.15
    shrink: float = 0.05
    max_growth: float | None = None
    tol: float = 1e-4
    tile_elements: int = 64
    move_cost: float = 0.0
    lp_options: dict | None = None
    threads: int | None = None
    solver: str = "pdhg"
    iterations: int = _PDHG_ITERATIONS
    fairness: float = _FAIRNESS

    def checked(self) -> CompactionSettings:
        """The same settings, each checked (InputError naming it) and normalised."""
        move_cost = real_number(self.move_cost, "move_cost", minimum=0.0)
        solver = one_of(self.solver, "solver", SOLVERS)
        return CompactionSettings(
            gap=parse_gap(self.gap),
            rounds=whole_number(self.rounds, "rounds", minimum=0),
            move=real_number(self.move, "move", above=0.0),
            growth=real_number(self.growth, "growth", above=0.0),
            shrink=real_number(self.shrink, "shrink", minimum=0.0, below=1.0),
            max_growth=None
            if self.max_growth is None
            else real_number(self.max_growth, "max_growth", above=0.0),
            tol=real_number(self.tol, "tol", minimum=0.0),
            tile_elements=whole_number(self.tile_elements, "tile_elements", minimum=1),
            move_cost=move_cost,
            lp_options=self.lp_options,
            threads=usable_cores()
            if self.threads is None
            else whole_number(self.threads, "threads", minimum=1),
            # |Δc| in the objective: split columns, HiGHS only
            solver="highs" if move_cost > 0 else solver,
            iterations=whole_number(self.iterations, "iterations", minimum=1),
            fairness=real_number(self.fairness, "fairness", minimum=0.0),
        )


def _checked_elements(centres, angles, sizes, max_sizes):
    """Centres (N, 2), sizes (N,), angles (N,) and size caps as float64 copies, checked,
    and the caps as a function of position (None unless ``max_sizes`` is one; then the
    caps returned are None)."""
    if callable(max_sizes):
        return (*_checked_elements(centres, angles, sizes, None)[:4], max_sizes)
    c = np.array(centres, dtype=np.float64).reshape(-1, 2)
    n = len(c)
    r = np.array(sizes, dtype=np.float64).reshape(-1)
    th = (
        np.broadcast_to(np.asarray(angles, dtype=np.float64), (n,)).copy()
        if angles is not None
        else np.zeros(n)
    )
    if len(r) != n or len(th) != n:
        raise InputError(
            f"centres, angles and sizes must have one entry per element: {n}, {len(th)}, {len(r)}"
        )
    if not (np.isfinite(c).all() and np.isfinite(r).all() and np.isfinite(th).all()):
        raise InputError("centres, angles and sizes must be finite")
    if (r < 0).any():
        raise InputError(f"sizes must be >= 0, got {r.min()!r}")
    if max_sizes is not None:
        max_sizes = np.broadcast_to(np.asarray(max_sizes, dtype=np.float64), (n,))
        if not (np.isfinite(max_sizes).all() and (max_sizes > 0).all()):
            raise InputError("max_sizes must be finite and positive")
    return c, r, th, max_sizes, None


def _region_and_walls(region, walls):
    """The mask the elements stay in (the region and its walls) and the walls, checked."""
    mask = _region_mask(region)
    if walls is None:
        return mask, None
    walls = np.asarray(walls, dtype=bool)
    if walls.shape != mask.shape:
        raise InputError(
            f"walls are {walls.shape[1]}x{walls.shape[0]}, the region {mask.shape[1]}x{mask.shape[0]}"
        )
    return mask | walls, walls


def _check_start(unit, c, r, gap, mask) -> None:
    """InputError where the gap is wider than an element or a centre lies off the region."""
    placed = np.flatnonzero(r > 0)
    if not len(placed):
        return
    widest = 2 * unit.inradius * r[placed].max()
    if gap >= widest:
        raise InputError(
            f"gap {gap:g} px is not smaller than the largest element "
            f"({widest:.3g} px across its narrowest side)"
        )
    h, w = mask.shape
    x, y = c[placed, 0], c[placed, 1]
    inside = (x >= 0) & (x < w) & (y >= 0) & (y < h)
    inside[inside] = mask[y[inside].astype(np.int64), x[inside].astype(np.int64)]
    if not inside.all():
        k = placed[np.argmin(inside)]
        raise InputError(
            f"element {k} has its centre ({c[k, 0]:g}, {c[k, 1]:g}) outside the "
            f"region; compaction keeps elements where they start"
        )


def _round_rows(unit, c, r, cos, sin, budget, gap, pieces, prev, threads=1):
    """The round's rows (near pairs and near boundary pieces, the tightest piece of each;
    ``pieces``: :class:`_Pieces`), and the directions to start the next round's search
    from."""
    prev_p, prev_s = prev
    n = len(r)
    act = np.flatnonzero(r > 0)
    # one kd-tree of the centres (per class of reach) for the pairs and the pieces
    trees = _point_trees(c[act], unit.circumradius * r[act] + budget[act]) if len(act) else []
    calls = (
        lambda: _near_pairs(unit, c, r, cos, sin, budget, gap, prev_p, act, trees, threads),
        lambda: _near_segments(unit, c, r, cos, sin, budget, 0.5 * gap, pieces, prev_s, act, trees, threads),
    )
    # the pairs beside the pieces where there are threads: each one's serial parts
    # overlap the other's work
    (i, j, px, py, _), (e, s, sx, sy, _) = side_by_side(*calls) if threads > 1 else [f() for f in calls]
    segs = pieces.segs
    seg_m = np.minimum(sx * segs[s, 0] + sy * segs[s, 1], sx * segs[s, 2] + sy * segs[s, 3])
    if pieces.widen is not None:  # (2) against the piece widened: its line moved towards the element
        seg_m -= pieces.widen[s]
    rows = _Rows(
        i,
        j,
        px,
        py,
        unit.support(px, py, cos[i], sin[i]),
        unit.support(-px, -py, cos[j], sin[j]),
        e,
        s,
        sx,
        sy,
        unit.support(sx, sy, cos[e], sin[e]),
        seg_m,
    )
    # the rows come ordered by i then j (e then s): their keys are sorted already
    prev_p = (i * n + j, np.stack([px, py], axis=1))
    prev_s = (e * len(segs) + s, np.stack([sx, sy], axis=1))
    return rows.tightest_pieces(), (prev_p, prev_s), (len(i), len(e))


def _growth_bounds(settings, r, r0, max_sizes, follow):
    """(N,) the most each size may change by this round: ``growth`` of itself, less where
    ``max_growth`` or a cap binds (never below 0); where caps follow the centres
    (``follow``), an element above its cap must shrink towards it, by up to ``shrink``
    of itself (the bound is then negative)."""
    up = settings.growth * r
    if settings.max_growth is not None:
        up = np.clip(r0 * (1 + settings.max_growth) - r, 0.0, up)
    if max_sizes is None:
        return up
    above = r - max_sizes
    up = np.clip(-above, 0.0, up)
    if follow:
        # the cap dropped where the element went: shrink towards it (shrinking keeps
        # every row, so Δc = 0 with Δr at this bound is still feasible)
        up = np.where(above > 0, -np.minimum(above, settings.shrink * r), up)
    return up


def _round_bounds(settings, unit, c, r, r0, max_sizes, caps):
    """A round's move bounds, growth bounds (:func:`_growth_bounds`) and caps.  ``caps``
    is (caps_at, rounds left, raster shape): where caps follow the centres (caps_at not
    None) they are read at ``c`` and each move is kept where a cap changes by at most
    ``growth`` × the rounds left, what they could follow (:func:`_caps_here`)."""
    caps_at, left, shape = caps
    delta = settings.move * unit.inradius * r
    if caps_at is not None:
        max_sizes, delta = _caps_here(caps_at, c, r, delta, settings.growth * left, shape)
    return delta, _growth_bounds(settings, r, r0, max_sizes, follow=caps_at is not None), max_sizes


def _ring_values(image, caps_at, which, col, row, dx, dy, shape) -> np.ndarray:
    """(len(which), len(dx)) the caps at the pixels (row + dy, col + dx) of elements
    ``which``, clipped to the (H, W) raster ``shape``: read from ``image`` where there is
    one, else asked of ``caps_at`` at the pixels' centres."""
    h, w_ = shape
    j = np.clip(col[which, None] + dx, 0, w_ - 1)
    i = np.clip(row[which, None] + dy, 0, h - 1)
    if image is not None:
        return image[i, j]
    v = np.asarray(caps_at(np.stack([j.ravel() + 0.5, i.ravel() + 0.5], axis=1)), dtype=np.float64)
    return v.reshape(i.shape)


def _caps_here(caps_at, c, r, delta, steady, shape):
    """Caps that follow the centres: (N,) the caps at the centres ``c``, and the move
    bounds: each element moves only within the widest box of whole-pixel half-width w
    (up to its ``delta``) in which the cap stays within (1 ± ``steady``) of its own at
    every pixel of the (H, W) raster ``shape``, and at least ``_STEADY_LEAST`` px (module
    docstring, Sizes and density).  Where ``caps_at`` has an ``image`` (its cap at every
    pixel) the pixels are read from it, else ``caps_at`` is asked at their centres."""
    caps = _checked_elements(c, None, r, caps_at(c))[3]
    image = getattr(caps_at, "image", None)
    h, w_ = shape
    col = np.clip(np.floor(c[:, 0]).astype(np.int64), 0, w_ - 1)
    row = np.clip(np.floor(c[:, 1]).astype(np.int64), 0, h - 1)
    own = caps if image is None else image[row, col]  # the image's own rounding
    lo, hi = own * (1 - steady), own * (1 + steady)
    reach = np.zeros(len(c))
    live = np.flatnonzero(r > 0)
    # an element's rings within the raster are read by offsets into the flat image, the
    # others' pixels clipped to its border (what the rings beyond it repeat)
    room = np.minimum(np.minimum(col, w_ - 1 - col), np.minimum(row, h - 1 - row))
    at = row * w_ + col
    flat = None if image is None else image.ravel()
    w = 1
    while len(live):  # one ring of pixels at a time, the elements still steady
        o = np.arange(-w, w + 1)
        side = np.full(2 * w + 1, w)
        dx = np.concatenate([o, o, -side[1:-1], side[1:-1]])
        dy = np.concatenate([-side, side, o[1:-1], o[1:-1]])
        if image is None:
            v = _ring_values(None, caps_at, live, col, row, dx, dy, (h, w_))
        else:
            inner = room[live] >= w
            v = np.empty((len(live), len(dx)), dtype=image.dtype)
            v[inner] = flat.take(at[live[inner], None] + (dy * w_ + dx))
            v[~inner] = _ring_values(image, None, live[~inner], col, row, dx, dy, (h, w_))
        # steady: every pixel of the ring within the element's band (NaN is not)
        live = live[(v.min(axis=1) >= lo[live]) & (v.max(axis=1) <= hi[live])]
        reach[live] = w
        w += 1
        live = live[delta[live] > w - 1]  # the box of half-width w is within reach
    return caps, np.minimum(delta, np.maximum(reach, _STEADY_LEAST))


def _objective_weights(r, act, max_sizes, fairness):
    """Each element's weight in the round's objective Σ w_i·Δr_i, mean 1 over ``act``:
    r_i (the covered area, d(r²)/2), times (cap_i / r_i)^``fairness`` where size caps
    are given (module docstring, Sizes and density)."""
    weight = r.copy()
    if max_sizes is not None and fairness:
        # r > 0 on act; elsewhere the weight is unused
        weight[act] *= (max_sizes[act] / r[act]) ** fairness
    return weight / weight[act].mean()


def _solve_round(settings, rows, act, c, r, bounds, mask, k):
    """Δc, Δr of one round by the settings' solver; also its steps, failed tiles and
    the largest row violation left (PDHG)."""
    gap, delta, lo_dr, hi_dr, weight = bounds
    if settings.solver == "pdhg":
        dc, dr, violation, iters = _solve_pdhg(
            rows,
            act,
            c,
            r,
            gap,
            delta,
            lo_dr,
            hi_dr,
            weight,
            settings.iterations,
            _STEP_RATIO,
            settings.threads,
        )
        return dc, dr, iters, 0, violation
    tile = _tiles(c, act, mask, settings.tile_elements, k)
    options = {"presolve": "off", **(settings.lp_options or {})}
    dc, dr, iters, failed = _solve_lp(
        rows, act, c, r, gap, delta, lo_dr, hi_dr, weight, tile, options, settings.move_cost, settings.threads
    )
    return dc, dr, iters, failed, None


def compact(
    centres,
    angles,
    sizes,
    shape: str,
    aspect,
    region,
    settings: CompactionSettings | None = None,
    *,
    walls=None,
    max_sizes=None,
    on_round=None,
    **overrides,
) -> CompactionResult:
    """Compact placed elements (module docstring): return new centres and sizes.

    ``centres`` (N, 2) px, ``angles`` (N,) radians (kept), ``sizes`` (N,) in unit-element
    units (0 = no element; those stay absent); ``shape`` one of ``cvt.shapes.ELEMENT_SHAPES``,
    ``aspect`` β of rectangles and ellipses; ``region`` a :class:`cvt.problem.Grid` or an
    (H, W) bool mask (True = inside; the raster's edge is the border too).  ``settings``
    (a :class:`CompactionSettings`; keyword ``overrides`` replace its fields, e.g.
    ``gap=1.5, rounds=8``) say how far elements move and grow per round and when to stop.
    ``max_sizes`` ((N,), optional) caps each size (a size above its cap may only shrink);
    or a function of positions ((M, 2) px -> (M,)): caps that follow the elements.
    ``walls`` ((H, W) bool, outside the region): thin walls whose centre lines
    (:func:`wall_segments`) bound the elements instead of their pixels' sides: each
    element keeps G/2 from a wall's centre line, as from the border.
    ``on_round(k, centres, sizes)`` is called with each round's (overlap-free) state."""
    settings = replace(settings or CompactionSettings(), **overrides).checked()
    shape = check_shape(shape)
    gap, rounds = settings.gap, settings.rounds
    mask, walls = _region_and_walls(region, walls)
    c, r, th, max_sizes, caps_at = _checked_elements(centres, angles, sizes, max_sizes)
    unit = element_ball(shape, aspect)
    _check_start(unit, c, r, gap, mask)
    t0 = time.perf_counter()
    walled = _walled(walls) if walls is not None and walls.any() else None
    pieces = _region_pieces(mask, walls, c[r > 0], gap, walled=walled)
    prev = (None, None)
    result = CompactionResult(c, r, th, 0, 0.0)
    order, (c, r, r0, cos, sin, max_sizes) = _work_order(c, r, r.copy(), np.cos(th), np.sin(th), max_sizes)
    left = rounds  # rounds left, this one included (how steady moves under caps_at are)
    for k in range(max(rounds, 1)):
        caps = (caps_at, max(left, 1), mask.shape)
        delta, up, max_sizes = _round_bounds(settings, unit, c, r, r0, max_sizes, caps)
        budget = math.sqrt(2) * delta + unit.circumradius * np.maximum(up, 0.0)
        if left <= 1 and pieces.widen is not None:
            # the last round against the walls' own steps: the elements close the room
            # the chords' widths left (the pieces change: no last directions for them)
            pieces, prev = _region_pieces(mask, walls, c[r > 0], gap, False, walled), (prev[0], None)
        rows, prev, (n_pairs, n_pieces) = _round_rows(
            unit, c, r, cos, sin, budget, gap, pieces, prev, settings.threads
        )
        # the start must meet every row (placement may cross a contour by half a pixel)
        r, dropped = _shrink_to_fit(rows, c, r, gap, SLACK)
        result.dropped += dropped
        if dropped:
            rows = rows.live(r)
        if rounds == 0:
            break
        act = np.flatnonzero(r > 0)
        if len(act) == 0:
            break
        area0 = float(np.sum(r * r))
        weight = _objective_weights(r, act, max_sizes, settings.fairness)
        tl, tcpu = time.perf_counter(), time.process_time()
        bounds = (gap, delta, -settings.shrink * r, up, weight)
        dc, dr, iters, failed, violation = _solve_round(settings, rows, act, c, r, bounds, mask, k)
        result.lp_seconds += time.perf_counter() - tl
        tcpu = time.process_time() - tcpu
        new_c = c + dc
        new_r = np.where(r > 0, np.maximum(r + dr, 0.0), 0.0)
        reverted = _revert_hopeless(rows, c, r, new_c, new_r, gap, SLACK)
        new_r, dropped = _shrink_to_fit(rows, new_c, new_r, gap, SLACK)
        result.dropped += dropped
        c, r = new_c, new_r
        if on_round is not None:
            on_round(k + 1, *_in_caller_order(order, c, r))
        area1 = float(np.sum(r * r))
        result.rounds = k + 1
        result.history.append(
            {
                "pairs": n_pairs,
                "pieces": n_pieces,
                "area_gain": area1 / area0 - 1,
                "lp_cpu": tcpu,
                "iters": iters,
                "failed_tiles": failed,
                "violation": violation,
                "reverted": reverted,
                "seconds": time.perf_counter() - t0,
            }
        )
        stalled = area1 < area0 * (1 + settings.tol)
        if stalled and (caps_at is None or left <= 1):
            break
        left = 1 if stalled else left - 1  # stalled under caps that follow: one more, the last
    result.centres, result.sizes = _in_caller_order(order, c, r)
    result.seconds = time.perf_counter() - t0
    return result


__all__ = [
    "SLACK",
    "SEGMENT_LENGTH",
    "CompactionSettings",
    "CompactionResult",
    "boundary_segments",
    "wall_segments",
    "compact",
]
