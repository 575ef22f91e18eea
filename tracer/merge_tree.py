"""The fixed order in which a render's samples are pooled, so that any split of it pools to the same bits.

Floating-point addition is not associative: folding a render's passes into a film one after
the other (Chan's formula, ``tracer.film``) gives other bits than folding two halves separately
and then merging them. A render cut into tasks of disjoint sample indices (``tracer.cluster``)
would then differ, in the last bits, from the same render on one machine, and with the task size.
So every render pools its samples along one tree that depends only on the render's settings:

- a **pass** gives every pixel ``k`` samples (``render_loop.pass_samples``), and a **leaf** is
  ``leaf_passes`` consecutive passes, folded one after the other into a fresh film; ``leaf_passes``
  is the smallest count that keeps a render under ``MAX_LEAVES`` leaves;
- the leaves ``0 .. n - 1`` are cut into **pieces**, aligned blocks of a power-of-two count of
  leaves from the largest down (the binary digits of ``n``: 13 leaves are pieces of 8, 4 and 1);
- a piece is the perfect binary tree over its leaves: node ``(start, size)`` is node ``(start,
  size / 2)`` with node ``(start + size / 2, size / 2)`` merged into it;
- the render is the first piece with the others merged into it, in order.

A render on one machine pools its leaves as they come, holding at most one pending node per
level (a binary counter: log2 of the leaves, 12 films at most). A distributed render gives each
task a node of this tree (``task_nodes``), and the driver pools the nodes in whatever order they
arrive into the same tree (:class:`Pool`), so both give the same bits, whatever the task size.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, TypeVar

MAX_LEAVES = 4096

# A node of the tree: ``(start, size)``, leaves start .. start + size - 1.
Node = tuple[int, int]
T = TypeVar("T")


@dataclass(frozen=True)
class Layout:
    """How a render of ``spp`` samples per pixel is cut into passes of ``k`` and leaves of
    ``leaf_passes`` passes. Sample offsets are relative to the render's first sample index."""

    spp: int
    k: int
    leaf_passes: int

    @property
    def leaf_spp(self) -> int:
        return self.k * self.leaf_passes

    @property
    def leaves(self) -> int:
        return -(-self.spp // self.leaf_spp)

    def samples(self, node: Node) -> tuple[int, int]:
        """``(first, stop)`` sample offsets of the leaves of ``node``."""
        start, size = node
        return start * self.leaf_spp, min(self.spp, (start + size) * self.leaf_spp)

    def leaf_of(self, offset: int) -> int:
        """The leaf holding sample offset ``offset``."""
        return offset // self.leaf_spp


def layout(spp: int, k: int) -> Layout:
    """The layout of a render of ``spp`` samples in passes of ``k``: leaves of as few passes as
    keep it under ``MAX_LEAVES`` leaves (so a local render holds at most log2(MAX_LEAVES)
    pending films, and a cluster has up to ``MAX_LEAVES`` tasks to share)."""
    passes = -(-spp // k)
    return Layout(spp, k, max(1, -(-passes // MAX_LEAVES)))


def pieces(leaves: int) -> list[Node]:
    """The aligned power-of-two blocks that cover leaves ``0 .. leaves - 1``, largest first."""
    out, start = [], 0
    for bit in reversed(range(leaves.bit_length())):
        if leaves >> bit & 1:
            out.append((start, 1 << bit))
            start += 1 << bit
    return out


def task_nodes(leaves: int, task_leaves: int) -> list[Node]:
    """Nodes of the tree, in order, of ``task_leaves`` leaves each (a power of two) where a piece
    is that large, and the smaller pieces whole: the tasks of a distributed render."""
    if task_leaves < 1 or task_leaves & (task_leaves - 1):
        raise ValueError(f"a task holds a power-of-two number of leaves, not {task_leaves}")
    nodes = []
    for start, size in pieces(leaves):
        step = min(size, task_leaves)
        nodes.extend((first, step) for first in range(start, start + size, step))
    return nodes


class Pool(Generic[T]):
    """Pools the nodes of one render's tree in its fixed order, whatever order they are added in.

    ``merge(a, b)`` returns ``a`` with ``b`` pooled into it (it may reuse ``a``); it is called
    exactly as the tree says, so the result does not depend on the order of :meth:`add`.
    """

    def __init__(self, leaves: int, merge: Callable[[T, T], T]):
        self.leaves = leaves
        self._merge = merge
        self._pieces = pieces(leaves)
        self._nodes: dict[Node, T] = {}

    def _piece_size(self, start: int) -> int:
        for first, size in self._pieces:
            if first <= start < first + size:
                return size
        raise ValueError(f"leaf {start} is outside the render's {self.leaves} leaves")

    def add(self, node: Node, value: T) -> None:
        """Add the pooled samples of ``node`` (an aligned power-of-two block inside a piece) and
        merge up the tree as far as the siblings are there."""
        start, size = node
        piece = self._piece_size(start)
        if size > piece or start % size or node in self._nodes:
            raise ValueError(f"node {node} is not a new node of the tree of {self.leaves} leaves")
        while size < piece:
            left = start & ~(2 * size - 1)
            sibling = (left + size if left == start else left, size)
            if sibling not in self._nodes:
                break
            other = self._nodes.pop(sibling)
            value = self._merge(value, other) if left == start else self._merge(other, value)
            start, size = left, 2 * size
        self._nodes[(start, size)] = value

    @property
    def complete(self) -> bool:
        return all(node in self._nodes for node in self._pieces)

    def nodes(self) -> list[Node]:
        """The nodes held, in leaf order (for a record of what has been pooled)."""
        return sorted(self._nodes)

    def result(self) -> T | None:
        """Everything added, pooled: in the tree's order when every leaf is there, else (a render
        cut short) the nodes held merged in leaf order. None if nothing was added."""
        pooled = None
        for node in sorted(self._nodes):
            value = self._nodes[node]
            pooled = value if pooled is None else self._merge(pooled, value)
        return pooled
