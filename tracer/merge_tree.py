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

A render on one machine pools its leaves as they come (:class:`Pool`), holding at most one
pending node per level (a binary counter: log2 of the leaves, 12 films at most). A distributed
render gives each task a node of this tree (``task_nodes``) and merges sibling nodes as they
finish, up to the pieces (the same :class:`Pool`, whose merge submits a merge task), so both
give the same bits, whatever the task size.

A task smaller than a leaf is a :class:`Segment`, some consecutive passes of one leaf: its film
continues the fold of the segment before it (it is handed that film), so a leaf rendered as a
chain of segments is folded exactly as the leaf rendered whole, wherever the chain is cut (a
cut falls between passes, and a pass is folded pixel by pixel: ``tracer.film``). Segments are
what lets a render whose leaves are huge (``2^40`` spp in 4096 leaves: ``2^28`` spp each) keep
finished work within seconds.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Generic, TypeVar

MAX_LEAVES = 4096
# A local render holds up to one pending film per level of the tree, plus the leaf being filled:
# the levels are capped so that these stay under this many bytes (a 4K stratified film is 2.6 GB).
PENDING_BYTES = 4 << 30

# A node of the tree: ``(start, size)``, leaves start .. start + size - 1.
Node = tuple[int, int]
T = TypeVar("T")


@dataclass(frozen=True)
class Segment:
    """Passes ``first_pass .. stop_pass - 1`` (counted within the leaf) of leaf ``leaf``: a task
    smaller than a leaf, whose film continues the one of the leaf's passes before it."""

    leaf: int
    first_pass: int
    stop_pass: int


# What one task of a distributed render renders: a node of the tree, or a segment of a leaf.
Task = Node | Segment


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

    @property
    def passes(self) -> int:
        return -(-self.spp // self.k)

    def passes_in(self, leaf: int) -> int:
        """Passes of leaf ``leaf`` (the last leaf may hold fewer)."""
        return min(self.leaf_passes, self.passes - leaf * self.leaf_passes)

    def samples(self, task: Task) -> tuple[int, int]:
        """``(first, stop)`` sample offsets of a node's leaves or of a segment's passes."""
        if isinstance(task, Segment):
            first = task.leaf * self.leaf_spp
            return first + task.first_pass * self.k, min(self.spp, first + task.stop_pass * self.k)
        start, size = task
        return start * self.leaf_spp, min(self.spp, (start + size) * self.leaf_spp)

    def segments(self, leaf: int, passes: int) -> Iterator[Segment]:
        """Leaf ``leaf`` as consecutive segments of ``passes`` passes (the last one what remains)."""
        total = self.passes_in(leaf)
        for first in range(0, total, passes):
            yield Segment(leaf, first, min(total, first + passes))

    def check_segment(self, segment: Segment) -> None:
        """Raise ``ValueError`` unless ``segment`` is a run of passes inside one leaf."""
        if not (0 <= segment.leaf < self.leaves
                and 0 <= segment.first_pass < segment.stop_pass <= self.passes_in(segment.leaf)):
            raise ValueError(f"{segment} is not a run of passes inside a leaf of this render "
                             f"({self.leaves} leaves of {self.leaf_passes} passes)")

    def leaf_of(self, offset: int) -> int:
        """The leaf holding sample offset ``offset``."""
        return offset // self.leaf_spp


def max_leaves(film_bytes: int) -> int:
    """The most leaves a render whose film takes ``film_bytes`` may have: ``MAX_LEAVES``, or fewer
    where the pending films (levels + 2 of them) would pass ``PENDING_BYTES``."""
    levels = max(1, min(MAX_LEAVES.bit_length() - 1, PENDING_BYTES // max(1, film_bytes) - 2))
    return 1 << levels


def layout(spp: int, k: int, film_bytes: int = 0) -> Layout:
    """The layout of a render of ``spp`` samples in passes of ``k`` into films of ``film_bytes``:
    leaves of as few passes as keep it under ``max_leaves`` (a local render then holds at most
    log2 of that many pending films, and a cluster has up to that many tasks to share). It
    depends only on the render's settings, never on how the render is cut up."""
    passes = -(-spp // k)
    return Layout(spp, k, max(1, -(-passes // max_leaves(film_bytes))))


def check_node(leaves: int, node: Node) -> None:
    """Raise ``ValueError`` unless ``node`` is a node of the tree of ``leaves`` leaves: an
    aligned power-of-two block inside one piece."""
    start, size = node
    inside = any(first <= start and start + size <= first + span for first, span in pieces(leaves))
    if size < 1 or size & (size - 1) or start % size or not inside:
        raise ValueError(f"{node} is not a node of the merge tree of {leaves} leaves (an aligned "
                         "power-of-two block of leaves inside one piece)")


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


def task_leaves(tree: Layout, task_passes: int) -> int:
    """Leaves of a task of ``task_passes`` passes: the largest power of two of them it holds, or
    0 when it is smaller than a leaf (a segment)."""
    wanted = task_passes // tree.leaf_passes
    return 1 << (wanted.bit_length() - 1) if wanted else 0


def tasks(tree: Layout, task_passes: int) -> Iterator[tuple[Node, Iterator[Task]]]:
    """The tasks of a distributed render of ``task_passes`` passes each, as ``(node, chain)`` in
    leaf order: the chain's tasks, run one after the other, render that node. A task of at least
    a leaf is a node (``task_nodes``, of :func:`task_leaves` leaves), a chain of one; a smaller
    one is a segment, and each leaf is a chain of them, each continuing the film of the one
    before. Lazily: a leaf may be a million segments."""
    leaves = task_leaves(tree, task_passes)
    if leaves:
        for node in task_nodes(tree.leaves, leaves):
            yield node, iter((node,))
    else:
        for leaf in range(tree.leaves):
            yield (leaf, 1), tree.segments(leaf, task_passes)


def task_count(tree: Layout, task_passes: int) -> int:
    """How many tasks :func:`tasks` gives (without listing them)."""
    leaves = task_leaves(tree, task_passes)
    if leaves:
        return len(task_nodes(tree.leaves, leaves))
    per_leaf = -(-tree.leaf_passes // task_passes)
    return (tree.leaves - 1) * per_leaf - (-tree.passes_in(tree.leaves - 1) // task_passes)


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
        return next(size for first, size in self._pieces if first <= start < first + size)

    def add(self, node: Node, value: T) -> None:
        """Add the pooled samples of ``node`` (an aligned power-of-two block inside a piece, none
        of whose leaves was added before) and merge up the tree as far as the siblings are there."""
        check_node(self.leaves, node)
        start, size = node
        if any(first < start + size and start < first + span for first, span in self._nodes):
            raise ValueError(f"node {node} holds leaves already pooled: they would count twice")
        piece = self._piece_size(start)
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
