"""Compaction's near pairs and near pieces (cvt/placement/compaction.py): the kd-trees'
candidates, by classes of reach and of half-length, are a superset that the exact
filters cut down; checked against brute force over every pair and every (element,
piece), and the last-direction lookup against a dict."""

from __future__ import annotations

import math

import numpy as np
import pytest

from compact_distributions.cvt.placement import compaction as cp
from compact_distributions.cvt.shapes import element_ball

GAP = 0.7


def _scene(seed, n=260, pieces=180, side=160.0):
    """Elements with sizes over a factor of some 30 (many classes of reach), random
    angles and budgets, and pieces from points to 40 px long, some widened (chords)."""
    rng = np.random.default_rng(seed)
    c = rng.uniform(0.0, side, (n, 2))
    r = np.exp(rng.uniform(math.log(0.3), math.log(9.0), n))
    r[rng.random(n) < 0.05] = 0.0  # some absent
    th = rng.uniform(-math.pi, math.pi, n)
    budget = r * rng.uniform(0.0, 0.6, n)
    p = rng.uniform(0.0, side, (pieces, 2))
    length = np.where(
        rng.random(pieces) < 0.1, 0.0, np.exp(rng.uniform(math.log(0.5), math.log(40.0), pieces))
    )
    turn = rng.uniform(0.0, math.pi, pieces)
    q = p + length[:, None] * np.stack([np.cos(turn), np.sin(turn)], axis=1)
    segs = np.concatenate([p, q], axis=1)
    widen = np.where(rng.random(pieces) < 0.5, rng.uniform(0.0, 0.75, pieces), 0.0)
    return c, r, th, budget, cp._Pieces(segs, widen, float(widen.max()), cp._segment_trees(segs, widen))


def _trees(c, r, budget, unit):
    act = np.flatnonzero(r > 0)
    return act, cp._point_trees(c[act], unit.circumradius * r[act] + budget[act])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_candidates_hold_every_pair_and_piece_within_reach(seed):
    """Every pair whose centres lie within their reaches plus the gap, and every
    (element, piece) whose distance is within the element's reach plus the piece's
    half-length, G/2 and its width, is among the kd-trees' candidates (brute force)."""
    unit = element_ball("square", 1.0)
    c, r, _, budget, pieces = _scene(seed)
    act, trees = _trees(c, r, budget, unit)
    reach = unit.circumradius * r[act] + budget[act]
    a, b = cp._pairs_within(trees, len(act), GAP + cp._SELECT, ordered=False)
    got = set(zip(a.tolist(), b.tolist(), strict=True))
    d = np.hypot(*(c[act][:, None, :] - c[act][None, :, :]).transpose(2, 0, 1))
    want = np.argwhere(np.triu(d <= reach[:, None] + reach[None, :] + GAP, 1))
    assert len(want) > 100
    assert {(int(x), int(y)) for x, y in want} <= got
    k, s = cp._near_items(trees, pieces.trees, 0.5 * GAP + cp._SELECT)
    got = set(zip(k.tolist(), s.tolist(), strict=True))
    segs = pieces.segs
    mid = 0.5 * (segs[:, :2] + segs[:, 2:])
    half = 0.5 * np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1])
    dm = np.hypot(*(c[act][:, None, :] - mid[None, :, :]).transpose(2, 0, 1))
    want = np.argwhere(dm <= reach[:, None] + half[None, :] + 0.5 * GAP + pieces.widen[None, :])
    assert len(want) > 100
    assert {(int(x), int(y)) for x, y in want} <= got


def test_candidates_on_every_core_come_in_the_order_of_one_core(monkeypatch):
    """The kd-tree queries run side by side on the process's pool: their candidates are
    those of the queries run one after another in this thread, in the same order."""
    from compact_distributions.cvt import threads

    unit = element_ball("square", 1.0)
    c, r, _, budget, pieces = _scene(3, n=900, pieces=400)
    act, trees = _trees(c, r, budget, unit)
    assert len(trees) > 3  # several classes of reach: several queries each

    def candidates():
        return (
            *cp._pairs_within(trees, len(act), GAP + cp._SELECT, ordered=False),
            *cp._near_items(trees, pieces.trees, 0.5 * GAP + cp._SELECT),
        )

    monkeypatch.setattr(threads, "usable_cores", lambda: 2)
    pooled = candidates()
    monkeypatch.setattr(threads, "usable_cores", lambda: 1)  # side_by_side: one call after another
    alone = candidates()
    for got, want in zip(pooled, alone, strict=True):
        assert len(want) > 1000 and np.array_equal(got, want)


@pytest.mark.parametrize(
    ("shape", "aspect"), [("square", 1.0), ("rectangle", 0.5), ("triangle", 1.0), ("ellipse", 0.5)]
)
def test_rows_are_those_of_every_candidate(shape, aspect, monkeypatch):
    """The rows of the near pairs and pieces (two rounds: the second starts from the
    first's directions) are bit for bit those found with every pair and every (element,
    piece) as a candidate: the kd-trees lose none, and the rows do not depend on the
    candidates' order or number."""
    unit = element_ball(shape, aspect)
    c, r, th, budget, pieces = _scene(7)
    cos, sin = np.cos(th), np.sin(th)
    act, trees = _trees(c, r, budget, unit)
    m = len(act)

    def every_pair(point_trees, count, extra, ordered=True):
        a, b = np.triu_indices(count, 1)
        return a[::-1].copy(), b[::-1].copy()  # reversed: an order the kd-trees never give

    def every_item(point_trees, item_trees, extra):
        k, s = np.meshgrid(np.arange(m), np.arange(len(pieces.segs)), indexing="ij")
        return k.ravel()[::-1].copy(), s.ravel()[::-1].copy()

    def rows(prev_p, prev_s, c):
        act, trees = _trees(c, r, budget, unit)
        p = cp._near_pairs(unit, c, r, cos, sin, budget, GAP, prev_p, act, trees)
        s = cp._near_segments(unit, c, r, cos, sin, budget, 0.5 * GAP, pieces, prev_s, act, trees)
        return p, s

    def two_rounds():
        p, s = rows(None, None, c)
        n, ns = len(r), len(pieces.segs)
        prev_p = (p[0] * n + p[1], np.stack(p[2:4], axis=1))
        prev_s = (s[0] * ns + s[1], np.stack(s[2:4], axis=1))
        moved = c + np.random.default_rng(1).normal(0.0, 0.3, c.shape)
        return (p, s), rows(prev_p, prev_s, moved)

    fast = two_rounds()
    monkeypatch.setattr(cp, "_pairs_within", every_pair)
    monkeypatch.setattr(cp, "_near_items", every_item)
    brute = two_rounds()
    for f_round, b_round in zip(fast, brute, strict=True):
        for f_rows, b_rows in zip(f_round, b_round, strict=True):
            assert len(f_rows[0]) > 50
            for f, b in zip(f_rows, b_rows, strict=True):
                assert np.array_equal(f, b)


def test_reach_and_half_length_classes_partition_and_bound():
    """_reach_classes: every index once, each class's reaches within a factor
    2^(1/_REACH_STEPS); _segment_trees: every piece once, each class's half-lengths
    within a factor 2 (or all at most 1 px), widened pieces and the others apart, the
    recorded reach its largest half-length plus its largest width."""
    rng = np.random.default_rng(4)
    reach = np.exp(rng.uniform(0.0, 4.0, 500))
    classes = cp._reach_classes(reach)
    assert np.array_equal(np.sort(np.concatenate(classes)), np.arange(500))
    for cls in classes:
        assert reach[cls].max() <= reach[cls].min() * 2 ** (1 / cp._REACH_STEPS) * (1 + 1e-12)
    segs = rng.uniform(0.0, 50.0, (400, 4))
    segs[:40, 2:] = segs[:40, :2]  # points
    half = 0.5 * np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1])
    widen = np.where(rng.random(400) < 0.3, rng.uniform(0.0, 0.75, 400), 0.0)
    for w in (None, widen):
        trees = cp._segment_trees(segs, w)
        members = np.concatenate([t[0] for t in trees])
        assert np.array_equal(np.sort(members), np.arange(400))
        w = np.zeros(400) if w is None else w
        for idx, _, top in trees:
            assert top == half[idx].max() + w[idx].max()
            assert half[idx].max() <= 1.0 or half[idx].min() > half[idx].max() / 2
            assert (w[idx] > 0).all() or (w[idx] == 0).all()


def test_lookup_matches_a_dict():
    """_lookup gives last round's direction of each key present and NaN for the others."""
    rng = np.random.default_rng(6)
    pk = np.unique(rng.integers(0, 10_000, 3000))
    pn = rng.normal(size=(len(pk), 2))
    keys = rng.integers(-5, 10_010, 5000)
    out = cp._lookup((pk, pn), keys)
    table = {int(k): v for k, v in zip(pk, pn, strict=True)}
    for k, o in zip(keys, out, strict=True):
        if int(k) in table:
            assert np.array_equal(o, table[int(k)])
        else:
            assert np.isnan(o).all()
    assert np.isnan(cp._lookup(None, keys)).all()
