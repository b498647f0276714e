"""Learned light selection (emitters/selection_learning.py): a learned selector's pmf sums to one, matches its picks
(chi-square) and is what select() reports; it moves picks away from lights that gave nothing and never below the
defensive share of the BVH's; the cells' tree and the records' arithmetic."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.emitters.selection import LightSampler, _child_weights, build_selector, cell_of
from lightprobe.emitters.selection_learning import (
    DEFENSIVE,
    Records,
    _kd_tree,
    _kth_smallest,
    _record_terms,
    learned,
    with_cut,
)

from .test_selection import LIGHTS, RECEIVERS, assert_picks_follow_the_pmf

ENV = (40.0, 0.0, 20.0, 5.0)


def _blocked(light: np.ndarray, point: np.ndarray) -> np.ndarray:
    """The synthetic scene's visibility: seven lights in eight give nothing to receivers with x > 0."""
    return (light % 8 != 0) & (point[:, 0] > 0.0)


def _learned_sampler(env=None, n: int = 16_000, seed: int = 1, blocked: bool = True, margin: float = 0.0):
    """A sampler over the test lights, learned from ``n`` records at random points of [-3, 3]^3 (normals up), each
    a light picked by the BVH, its value the BVH's probability of it there (as if the BVH's importance were each
    light's contribution) unless :func:`_blocked`."""
    sampler = LightSampler("learned", LIGHTS, env_irradiance=env)
    bvh = LightSampler("bvh", LIGHTS)
    sel = with_cut(sampler.arrays)
    rng = np.random.default_rng(seed)
    records = Records(n, 1, 1)
    records.point[:] = rng.uniform(-3.0, 3.0, (n, 3))
    records.normal[:] = (0.0, 1.0, 0.0)
    light, pmf = bvh.select(records.point.astype(np.float64), records.normal.astype(np.float64), rng.random(n))
    records.light[:] = light
    records.value[:] = np.where(_blocked(light, records.point) & blocked, -pmf, pmf)  # < 0: blocked
    sampler.arrays = learned(sel, records, leaf=2048, margin=margin)
    return sampler


def test_a_cell_keeps_what_it_learned_only_where_it_lowers_the_second_moment():
    # where seven lights in eight give nothing to x > 0, the cells there learn (their records' second moment under
    # the learned choice is far below the BVH's); where nothing is blocked the learned ratios are the BVH's up to
    # noise, every cell goes back to the BVH, and the selector keeps no cells to look up
    sampler = _learned_sampler(margin=0.5)
    sel = sampler.arrays
    assert cell_of(sel, 1.5, 0.0, 0.5) >= 0 and cell_of(sel, 2.5, -2.0, 1.0) >= 0
    assert cell_of(sel, -1.5, 0.0, 0.5) < 0 and cell_of(sel, -2.5, 2.0, -1.0) < 0
    plain = _learned_sampler(blocked=False, margin=0.5).arrays
    assert plain.cell_axis.size == 0 and plain.cut_levels == sel.cut_levels
    # and the cells that learned nothing are pruned into as few leaves as the tree allows
    kept = sel.cell_axis >= 0
    assert np.count_nonzero(kept) < np.count_nonzero(_learned_sampler(margin=0.0).arrays.cell_axis >= 0)


def test_a_scene_that_blocks_little_learns_nothing():
    # the records carry what blocked samples would have given, negated: under MIN_BLOCKED of it lost, no cells
    sel = with_cut(build_selector("learned", LIGHTS))
    records = Records(4000, 1, 1)
    rng = np.random.default_rng(5)
    records.point[:] = rng.uniform(-3.0, 3.0, (4000, 3))
    records.normal[:] = (0.0, 1.0, 0.0)
    records.light[:] = rng.integers(0, sel.n_bounded, 4000)
    records.value[:] = np.where(np.arange(4000) % 50 == 0, -1.0, 1.0)  # 2 % lost, under MIN_BLOCKED
    assert learned(sel, records, leaf=500, margin=0.0) is sel
    records.value[:] = np.where(np.arange(4000) % 4 == 0, -1.0, 1.0)  # 25 % lost
    assert learned(sel, records, leaf=500, margin=0.0).cell_axis.size > 1


@pytest.mark.parametrize("env", [None, ENV])
def test_a_learned_pmf_sums_to_one_and_matches_the_picks(env):
    sampler = _learned_sampler(env)
    for i, (p, nrm) in enumerate(RECEIVERS):
        assert cell_of(sampler.arrays, *np.asarray(p, float)) >= 0 or i == 3  # the far receiver may lie anywhere
        assert_picks_follow_the_pmf(sampler, p, nrm, 200 + i, 2 * len(RECEIVERS))


def test_the_rescaled_number_stays_stratified_within_each_light():
    sampler = _learned_sampler()
    n = 1 << 16
    u = (np.arange(n) + 0.5) / n
    for p, nrm in RECEIVERS[:2]:
        light, _, rest = sampler.select(p, nrm, u, rescaled=True)
        assert np.all((rest >= 0.0) & (rest < 1.0))
        for lt in np.unique(light):
            r = np.sort(rest[light == lt])
            if r.size >= 8:
                assert np.abs(r - (np.arange(r.size) + 0.5) / r.size).max() < 1.5 / r.size


def test_learning_moves_picks_away_from_lights_that_gave_nothing_but_keeps_the_defensive_share():
    bvh = LightSampler("bvh", LIGHTS)
    sampler = _learned_sampler()
    odd = np.arange(bvh.arrays.n_lights) % 8 != 0
    p, nrm = np.array([1.5, 0.0, 0.5]), np.array([0.0, 1.0, 0.0])  # a receiver where these lights gave nothing
    before, after = bvh.pmf(p, nrm), sampler.pmf(p, nrm)
    assert before[odd].sum() > 0.5
    assert after[odd].sum() < 0.5 * before[odd].sum()
    # at each of the cut's levels a child keeps at least alpha of its BVH share: a light at least alpha^levels
    levels = sampler.arrays.cut_levels
    assert np.all(after[before > 0] >= before[before > 0] * DEFENSIVE**levels * (1 - 1e-12))
    # where every light gave its due (x < 0), the learned choice stays near the BVH's
    q = np.array([-1.5, 0.0, 0.5])
    before, after = bvh.pmf(q, nrm), sampler.pmf(q, nrm)
    assert 0.5 < after[odd].sum() / before[odd].sum() < 2.0


def test_a_cut_keeps_within_its_entries_and_changes_no_pick():
    sel = build_selector("learned", LIGHTS)
    cut = with_cut(sel, max_entries=80)
    assert cut.cut_levels >= 1 and np.count_nonzero(cut.learn_offset >= 0) * 8 <= 80
    assert with_cut(sel).cut_levels >= cut.cut_levels
    u = np.random.default_rng(3).random(2000)
    plain, clustered = LightSampler("bvh", LIGHTS), LightSampler("bvh", LIGHTS)
    clustered.arrays = cut
    for p, nrm in RECEIVERS:
        assert np.array_equal(plain.select(p, nrm, u)[1], clustered.select(p, nrm, u)[1])


def test_the_cells_tree_splits_a_floor_and_its_walls():
    # two thirds of the points on the floor y = 0: the median along y is 0 for most of them, so the split must
    # move to the next coordinate up or to another axis
    rng = np.random.default_rng(4)
    floor = np.column_stack([rng.uniform(0, 4, 6000), np.zeros(6000), rng.uniform(0, 4, 6000)])
    wall = np.column_stack([np.zeros(3000), rng.uniform(0, 3, 3000), rng.uniform(0, 4, 3000)])
    points = np.vstack([floor, wall]).astype(np.float32)
    axis, split, nxt = _kd_tree(points, 500)
    leaves = axis < 0
    cells = nxt[leaves, 0]
    assert np.array_equal(np.sort(cells), np.arange(cells.size))
    found = np.empty(points.shape[0], np.int64)
    for i, x in enumerate(points.astype(np.float64)):
        node = 0
        while axis[node] >= 0:
            node = nxt[node, 0 if x[axis[node]] < split[node] else 1]
        found[i] = nxt[node, 0]
    assert np.bincount(found).max() <= 500


def test_the_kth_smallest_is_numpys_partition_value():
    # the k-d tree's median (its own selection, not np.partition): every k of arrays with and without ties
    rng = np.random.default_rng(7)
    for n in (1, 2, 3, 8, 33, 200):
        for values in (rng.uniform(-1, 1, n), rng.integers(0, 4, n).astype(np.float64), np.zeros(n)):
            for k in range(n):
                work = values.copy()
                assert _kth_smallest(work, k) == np.partition(values, k)[k], (n, k)
                assert np.array_equal(np.sort(work), np.sort(values))  # reordered, nothing lost


def test_a_records_value_is_divided_by_its_lights_probability_below_each_learned_child():
    sel = with_cut(build_selector("learned", LIGHTS), max_entries=80)
    assert sel.cut_levels == 2
    point = np.array([[0.3, 0.2, -0.4]], np.float32)
    normal = np.array([[0.0, 1.0, 0.0]], np.float32)
    p64, n64 = point[0].astype(np.float64), normal[0].astype(np.float64)
    axis, split, nxt = np.array([-1]), np.zeros(1), np.zeros((1, 2), np.int64)
    for light in (0, 17, 305):
        cell, entry, v, weight, p_bvh = _record_terms(
            sel, axis, split, nxt, point, normal, np.array([light], np.int32), np.array([2.0], np.float32)
        )
        # walk the light's path in Python: each level's share; v at level d = 2 / product of the shares below it
        trail, node, shares, weights, entries = int(sel.light_trail[light]), 0, [], [], []
        while True:
            slot = trail & 7
            trail >>= 3
            w, total = _child_weights(sel.wide_bounds, node, *p64, *n64)
            shares.append(w[slot] / total)
            weights.append(w[slot])
            entries.append(sel.learn_offset[node] + slot)
            child = int(sel.wide_child[node, slot])
            if child < 0:
                break
            node = child
        for d in range(min(2, len(shares))):
            assert entry[0, d] == entries[d]
            assert weight[0, d] == pytest.approx(weights[d], rel=1e-12)
            assert v[0, d] == pytest.approx(2.0 / np.prod(shares[d + 1 :]), rel=1e-9)
        assert cell[0] == 0 and p_bvh[0] == pytest.approx(np.prod(shares), rel=1e-12)


def test_records_keep_the_pilot_within_their_limit():
    r = Records(pixels=1000, pilot=16, slots=2, limit=8000)
    assert r.samples == 4 and r.stride == 1 and r.light.size == 8000
    r = Records(pixels=10_000, pilot=16, slots=2, limit=8000)
    assert r.samples == 1 and r.stride == 3 and r.light.size <= 8000 and np.all(r.light == -1)
