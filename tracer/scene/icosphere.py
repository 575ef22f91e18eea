"""The icosphere that ``sphere`` shapes are meshed as: a regular icosahedron whose triangles are
split in four ``subdivisions`` times, every vertex pushed back onto the sphere after each split.

It is written here rather than taken from trimesh so that scenes without mesh files never import
trimesh and scipy (about 0.8 s of every start-up). It reproduces trimesh's ``icosphere`` bit for
bit, vertex order and face order included (``tests/test_icosphere.py`` compares them for every
allowed subdivision level), so scene digests and the shipped references stay valid.
"""

from __future__ import annotations

import numpy as np

# The regular icosahedron's twelve vertices on the unit sphere are the cyclic permutations of
# (0, +-A, +-B) with A = 1 / sqrt(1 + phi^2) and B = phi / sqrt(1 + phi^2), phi the golden ratio.
# The decimals are the ones trimesh stores (B to 14 digits), which keeps the mesh identical.
_A = 0.5257311121191336
_B = 0.85065080835204
ICOSAHEDRON_VERTICES = np.array([
    [-_A, _B, 0.0], [_A, _B, 0.0], [-_A, -_B, 0.0], [_A, -_B, 0.0],
    [0.0, -_A, _B], [0.0, _A, _B], [0.0, -_A, -_B], [0.0, _A, -_B],
    [_B, 0.0, -_A], [_B, 0.0, _A], [-_B, 0.0, -_A], [-_B, 0.0, _A]])
# Counter-clockwise seen from outside, so geometric normals point out of the sphere.
ICOSAHEDRON_FACES = np.array([
    [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
    [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
    [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])


def unit_icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) float64 on the unit sphere and faces (20 * 4**subdivisions, 3) int64."""
    vertices = ICOSAHEDRON_VERTICES.copy()
    faces = ICOSAHEDRON_FACES.copy()
    for _ in range(subdivisions):
        # One midpoint per undirected edge. Edges are numbered in order of (larger index,
        # smaller index), the order trimesh's packed-integer row hash sorts them in.
        edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        key = (edges[:, 1].astype(np.int64) << 32) | edges[:, 0]
        _, first, edge_of = np.unique(key, return_index=True, return_inverse=True)
        midpoints = vertices[edges[first]].mean(axis=1)
        # mid[f, k]: the midpoint vertex of face f's edge from corner k to corner k + 1.
        mid = edge_of.reshape(-1, 3) + len(vertices)
        faces = np.column_stack([
            faces[:, 0], mid[:, 0], mid[:, 2],
            mid[:, 0], faces[:, 1], mid[:, 1],
            mid[:, 2], mid[:, 1], faces[:, 2],
            mid[:, 0], mid[:, 1], mid[:, 2]]).reshape(-1, 3)
        vertices = _onto_unit_sphere(np.vstack((vertices, midpoints)))
    if subdivisions <= 0:
        vertices = _onto_unit_sphere(vertices)
    return vertices, faces


def _onto_unit_sphere(vertices: np.ndarray) -> np.ndarray:
    # v + v/|v| (1 - |v|) rather than v / |v|: the same floating-point steps as trimesh.
    length = np.sqrt(np.dot(vertices**2, [1, 1, 1]))
    return vertices + vertices / length.reshape(-1, 1) * (1.0 - length).reshape(-1, 1)
