"""The merge tree (``tracer.merge_tree``): a render pooled from parts of any size, in any order, is
the whole render bit for bit.

These tests compare films with ``np.array_equal``, never a tolerance: a difference in the last
bit is a broken merge order, not noise. The same parts on a Dask cluster: tests/test_cluster.py.
"""

from __future__ import annotations

import dataclasses
import random

import numpy as np
import pytest

from tracer import merge_tree
from tracer import scene as scene_mod
from tracer.errors import InputError
from tracer.render_loop import RenderSettings, pass_samples, pooled_into, render, tree_layout
from tracer.strategy import Strategy


def small_scene(width=32, height=24):
    return scene_mod.load_scene(scene_mod.default_scene_path(), width, height)


def same_film(a, b) -> bool:
    """Every statistic of two films equal bit for bit."""
    same = (np.array_equal(a.count, b.count) and np.array_equal(a.mean, b.mean)
            and np.array_equal(a.m2, b.m2))
    if a.replicates or b.replicates:
        same = same and np.array_equal(a.rep_count, b.rep_count) and np.array_equal(a.rep_mean, b.rep_mean)
    return same


def test_pieces_and_task_nodes_cover_every_leaf_once():
    """Pieces are the binary digits of the leaf count, largest first, and tasks of any power-of-two
    size tile them: every leaf in exactly one task, every task inside one piece."""
    assert merge_tree.pieces(13) == [(0, 8), (8, 4), (12, 1)]
    assert merge_tree.pieces(1) == [(0, 1)]
    for leaves in range(1, 70):
        pieces = merge_tree.pieces(leaves)
        for task_leaves in (1, 2, 4, 8, 64):
            nodes = merge_tree.task_nodes(leaves, task_leaves)
            covered = [leaf for start, size in nodes for leaf in range(start, start + size)]
            assert covered == list(range(leaves))
            for start, size in nodes:
                assert any(p0 <= start and start + size <= p0 + ps for p0, ps in pieces)
                assert start % size == 0 and size & (size - 1) == 0
    with pytest.raises(ValueError):
        merge_tree.task_nodes(8, 3)


def test_pool_merges_in_the_tree_order_whatever_the_order_of_arrival():
    """With a merge that records its own order (string concatenation in brackets: not
    associative), nodes added in any order, of any task size, give one and the same expression:
    the tree's. A partial pool merges what it holds in leaf order."""
    def merge(a, b):
        return f"({a}+{b})"

    rng = random.Random(5)
    for leaves in (1, 6, 13, 32):
        expected = None
        for task_leaves in (1, 2, 4, 16):
            nodes = merge_tree.task_nodes(leaves, task_leaves)
            for _ in range(4):
                rng.shuffle(nodes)
                pool = merge_tree.Pool(leaves, merge)
                for start, size in nodes:
                    pool.add((start, size), _leaf_expression(start, size))
                assert pool.complete
                got = pool.result()
                expected = expected or got
                assert got == expected, (leaves, task_leaves)
    pool = merge_tree.Pool(13, merge)
    for node in ((12, 1), (0, 4)):
        pool.add(node, _leaf_expression(*node))
    assert not pool.complete and pool.nodes() == [(0, 4), (12, 1)]
    assert pool.result() == "(" + _leaf_expression(0, 4) + "+L12)"
    with pytest.raises(ValueError):
        merge_tree.Pool(13, merge).add((8, 8), "x")  # crosses the pieces 8..11 and 12


def _leaf_expression(start, size):
    """The tree's expression for node (start, size), built independently of Pool."""
    if size == 1:
        return f"L{start}"
    half = size // 2
    return f"({_leaf_expression(start, half)}+{_leaf_expression(start + half, half)})"


@pytest.mark.parametrize("sampler, max_leaves", [("independent", 4096), ("stratified", 4096),
                                                  ("independent", 4)])
def test_parts_pooled_in_any_order_are_the_whole_render(sampler, max_leaves, monkeypatch):
    """Parts of a render (``render(part=...)``: what a Dask task renders) for two task sizes,
    pooled in shuffled order, equal the whole render on two threads bit for bit; with a resumed
    sample range (first_sample > 0), a last leaf cut short (spp not a multiple of the leaf), and
    (MAX_LEAVES lowered to 4, as a million-spp render has) leaves of several passes."""
    monkeypatch.setattr(merge_tree, "MAX_LEAVES", max_leaves)
    scene = small_scene()
    strategy = Strategy("mis")
    k = pass_samples(10**6, 32 * 24, strategy.samples_per_lane)
    spp = 12 * k + 5  # 13 passes, the last one short
    settings = RenderSettings(spp=spp, seed=7, threads=2, first_sample=16, sampler=sampler)
    whole = render(scene, strategy, settings).film
    tree = tree_layout(scene, strategy, settings)
    assert (tree.leaves, tree.leaf_passes) == ((13, 1) if max_leaves > 13 else (4, 4))
    for task_leaves in (1, 4):
        nodes = merge_tree.task_nodes(tree.leaves, task_leaves)
        random.Random(task_leaves).shuffle(nodes)
        pool = merge_tree.Pool(tree.leaves, pooled_into)
        ranges = []
        for node in nodes:
            part = render(scene, strategy, dataclasses.replace(settings, threads=1), part=node).film
            pool.add(node, part)
            ranges += part.record.samples
        assert same_film(pool.result(), whole), task_leaves
        first, stop = 16, 16 + spp
        assert sorted(ranges)[0][1] == first and sum(c - b for _, b, c in ranges) == stop - first
    with pytest.raises(InputError, match="not a node"):
        render(scene, strategy, settings, part=(1, 2))  # not aligned


def test_pool_refuses_leaves_twice():
    """A node whose leaves the pool holds already (alone or merged into a parent), or of a size
    that is not a power of two, is refused: it would count samples twice or break the order."""
    pool = merge_tree.Pool(8, lambda a, b: a + b)
    pool.add((0, 1), 1)
    pool.add((1, 1), 1)  # merged into (0, 2)
    for node in ((0, 1), (1, 1), (0, 4), (0, 3)):
        with pytest.raises(ValueError):
            pool.add(node, 1)


def test_strategies_that_learn_are_not_cut_into_parts():
    """Optimal MIS learns from every earlier sample: a part of it would not be the whole render's."""
    with pytest.raises(InputError, match="learns"):
        render(small_scene(8, 8), Strategy("mis", "optimal"), RenderSettings(spp=64, threads=1), part=(0, 1))


@pytest.mark.parametrize("sampler", ["independent", "stratified"])
def test_a_leaf_rendered_as_a_chain_of_segments_is_the_leaf(sampler, monkeypatch):
    """Leaves of 4 passes (MAX_LEAVES lowered to 4) rendered as chains of segments of 1 and 3
    passes (``render(part=Segment, continued=...)``: what a Dask task smaller than a leaf
    renders), each continuing the film of the one before, pool to the whole render bit for bit;
    a segment handed the wrong film (or none) is refused."""
    monkeypatch.setattr(merge_tree, "MAX_LEAVES", 4)
    scene = small_scene()
    strategy = Strategy("mis")
    k = pass_samples(10**6, 32 * 24, strategy.samples_per_lane)
    settings = RenderSettings(spp=12 * k + 5, seed=7, threads=1, first_sample=16, sampler=sampler)
    whole = render(scene, strategy, dataclasses.replace(settings, threads=2)).film
    tree = tree_layout(scene, strategy, settings)
    assert (tree.leaves, tree.leaf_passes) == (4, 4)
    for passes in (1, 3):
        pool = merge_tree.Pool(tree.leaves, pooled_into)
        for node, chain in merge_tree.tasks(tree, passes):
            film = None
            for segment in chain:
                film = render(scene, strategy, settings, part=segment, continued=film).film
            pool.add(node, film)
        assert same_film(pool.result(), whole), passes
    assert merge_tree.task_count(tree, 3) == 7  # leaves of 4, 4, 4 and 1 passes
    first = render(scene, strategy, settings, part=merge_tree.Segment(0, 0, 1)).film
    for continued in (None, first):
        with pytest.raises(InputError, match="continues the film"):
            render(scene, strategy, settings, part=merge_tree.Segment(1, 1, 2), continued=continued)
    with pytest.raises(InputError, match="not a run of passes"):
        render(scene, strategy, settings, part=merge_tree.Segment(3, 0, 2))
