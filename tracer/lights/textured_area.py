"""Area emitters whose radiance is a texture: each triangle's integral of it, and a distribution
over the texels its (u, v) footprint covers.

A textured emitter's triangle t maps its points affinely to texture space (its corners' (u, v),
Mitsuba's (0, 0), (1, 0), (0, 1) for a mesh without them, through the texture's ``to_uv``), so
its **footprint** F_t there is a triangle. The lookup (``tracer.textures.lookup``) is a
piecewise function of texture space on a grid of *cells*:

- ``nearest``: the texels themselves, cell (i, j) = [i, i + 1] / W x [j, j + 1] / H, constant;
- ``bilinear``: cells whose corners are texel centres (as ``tracer.lights.environment`` cuts the
  environment), [i + 1/2, i + 3/2] / W x ..., bilinear between those four texels;
- a checkerboard: a 2 x 2 nearest "bitmap" (color0 on the diagonal); a ``rawconstant`` is a
  1 x 1 nearest bitmap already.

Indices are unwrapped (the footprint may span several periods): cell (i, j) reads texels
i, i + 1, j, j + 1 wrapped by the texture's wrap mode, exactly as the lookup does.

**Integrals (table-build time, exact).** F_t clipped to each cell it touches is a convex
polygon (Sutherland-Hodgman against the cell's four sides); the integral of a bilinear function
over a polygon is a linear combination of its moments (area, the integrals of x, y and xy, by
Green's theorem in closed form: Steger 1996, "On the calculation of arbitrary moments of
polygons"), so every cell's integral, per channel and of the luminance, is exact up to float64
rounding (a full cell's bilinear integral is the mean of its four texels; checked against a
dense quadrature in ``tests/test_textured_area.py``). No quadrature error: the lookup *is*
piecewise bilinear. The triangle's mean radiance, the sum over its cells divided by the
footprint's area, replaces the texture's mean as its emission, so its flux, which the ``power``
and ``bvh`` selections read, is pi area times the mean over channels of that integral (as an
untextured triangle's is pi area mean(Le)).

**Distribution (part of the light table).** For the ``triangle_texels`` technique
(``tracer.lights.techniques.triangle_texels``) the cells, grouped into square blocks of b x b
cells when the footprint spans more than the triangle's share of the table (``cap``), get
weights = the exact integral of the luminance over block ∩ F_t, and a 2-D piecewise-constant
distribution over them: a marginal CDF over rows, a conditional CDF within each row (the
environment's construction, ``environment.running_cdf``, here for many rows at once, inverted by
its ``_invert``). CDFs are float32, as the light table is: the probability of a block is
computed from the rounded CDFs, so the density is the one sampling has; every block of positive
weight keeps at least 2^-22 of its row's (and every row of the marginal's) total, so that after
rounding it still has an interval of positive width (at least 1.7e-7 for up to 2^20 blocks a
row), and every block where the texture is positive can be drawn (light-only renders stay
unbiased). Within a full block the point is uniform; within a block F_t's edge cuts, it is
uniform over the clipped polygon (stored, one 16-float row each: count and up to 7 vertices).
Blocks of F_t's area below what float32 vertices can hold (about 1e-14 of a block) are left
out. What the density is exact to: the float32 differences ``_invert`` divides by place a point
within its block with a relative error below 6e-8.

Triangles whose footprint is degenerate (area below ``MIN_FOOTPRINT`` cells), a sliver (twice
its area under ``MIN_CONDITION`` times its longest edge squared: the float32 map of the light
table would not be the footprint) or spans more than ``MAX_TEXEL_CELLS`` cells keep the
texture's mean (the scene's constant) and are sampled by area; so does every textured triangle
of a scene whose footprints span more than ``MAX_TOTAL_CELLS`` together, and of one whose
distributions would not fit the light table (``tracer.lights.build_tables``). A triangle whose
footprint integral is 0 (black texels only) sends no light and is no candidate
(``tracer.lights.emitters.emitting_triangles``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..textures import BILINEAR, FILTERS, LUMINANCE, MIRROR, REPEAT, WRAPS

# Texel cells a triangle's footprint's bounding box may span (2^24: a 4096 x 4096 texture once).
# Beyond, the triangle keeps the texture's mean and is sampled by area (the integral would take
# seconds).
MAX_TEXEL_CELLS = 2**24
# Blocks of one triangle's distribution at most, and the floats all triangles' tables may take
# (a quarter of what the light table can address, ``projected_images.MAX_TABLE_FLOATS``).
MAX_BLOCKS = 2**16
TABLE_FLOATS = 2**22
# A footprint of less texture-space area than this (in cells) is degenerate: the (u, v) map is
# not invertible and the triangle keeps the texture's mean, sampled by area.
MIN_FOOTPRINT = 1e-9
# A footprint thinner than this (twice its area over its longest edge squared) is a sliver:
# the light table holds its map from barycentrics in float32, whose determinant would then
# lose more than ~1e-4 of its value (float32's 6e-8 over this); such a triangle keeps the
# texture's mean and is sampled by area.
MIN_CONDITION = 2.0**-10
# Texel cells all textured triangles' footprints' boxes may span together (2^26: 16 textures of
# 2048 x 2048 once each). Beyond, every textured triangle keeps its texture's mean and is
# sampled by area: the integrals would take minutes and gigabytes.
MAX_TOTAL_CELLS = 2**26
# The least share of its CDF a block (or row) of positive weight keeps (module docstring).
MIN_SHARE = 2.0**-22
# Cells processed at once (memory: ~1 KB each while clipping).
CHUNK = 2**17
# Vertices a clipped polygon may have: a triangle cut by a square's four sides has at most 7.
MAX_VERTICES = 8


@dataclass
class Grid:
    """The lookup's cell grid of one texture: ``values (H, W, 3)`` float64 texels, ``offset``
    (1/2 for bilinear cells between texel centres, else 0), ``bilinear``, ``wrap`` (an index of
    ``WRAPS``) and ``to_uv (2, 3)``. Texture space (su, sv) lies at grid (su W - offset,
    sv H - offset)."""

    values: np.ndarray
    offset: float
    bilinear: bool
    wrap: int
    to_uv: np.ndarray

    @classmethod
    def of(cls, texture) -> "Grid | None":
        """The grid of ``texture`` (a ``tracer.textures.Texture``); None for a kind that has none
        (a mesh attribute)."""
        if texture.kind == "checkerboard":
            c0, c1 = np.asarray(texture.color0, float), np.asarray(texture.color1, float)
            return cls(np.array([[c0, c1], [c1, c0]]), 0.0, False, REPEAT, np.asarray(texture.to_uv, float))
        if texture.kind != "bitmap":
            return None
        bilinear = FILTERS.index(texture.filter) == BILINEAR
        return cls(np.maximum(np.asarray(texture.pixels, dtype=np.float64), 0.0), 0.5 if bilinear else 0.0,
                   bilinear, WRAPS.index(texture.wrap), np.asarray(texture.to_uv, float))

    def corners(self, uv: np.ndarray) -> np.ndarray:
        """``(..., 3, 2)`` grid coordinates of triangles whose corners have ``uv (..., 3, 2)``."""
        height, width = self.values.shape[:2]
        s = uv @ self.to_uv[:, :2].T + self.to_uv[:, 2]
        return np.stack([s[..., 0] * width - self.offset, s[..., 1] * height - self.offset], axis=-1)

    def texel(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """``(n, 3)`` the texels at unwrapped indices ``i, j (n,)``, wrapped as the lookup wraps."""
        height, width = self.values.shape[:2]
        return self.values[_wrapped(j, height, self.wrap), _wrapped(i, width, self.wrap)]

    def integrals(self, i: np.ndarray, j: np.ndarray, moments: np.ndarray) -> np.ndarray:
        """``(n, 3)`` the integral of the lookup's RGB over the part of cell (i, j) whose moments
        (area, x, y, xy in the cell's coordinates, ``polygon_moments``) are ``moments (n, 4)``."""
        area = moments[:, :1]
        f00 = self.texel(i, j)
        if not self.bilinear:
            return f00 * area
        f10, f01, f11 = self.texel(i + 1, j), self.texel(i, j + 1), self.texel(i + 1, j + 1)
        return (f00 * area + (f10 - f00) * moments[:, 1:2] + (f01 - f00) * moments[:, 2:3]
                + (f00 - f10 - f01 + f11) * moments[:, 3:4])


def _wrapped(i: np.ndarray, size: int, wrap: int) -> np.ndarray:
    """``lookup._wrapped`` over arrays."""
    if wrap == REPEAT:
        return np.mod(i, size)
    if wrap == MIRROR:
        period = np.mod(i, 2 * size)
        return np.where(period < size, period, 2 * size - 1 - period)
    return np.clip(i, 0, size - 1)


# ---------------------------------------------------------------------------------------------
# Triangles against grids of unit cells (many triangles at once: a cell carries its triangle)


def _clip(poly: np.ndarray, count: np.ndarray, axis: int, bound: float, keep_below: bool):
    """Sutherland-Hodgman: polygons ``poly (n, MAX_VERTICES, 2)`` with ``count (n,)`` vertices,
    clipped to coordinate ``axis`` >= ``bound`` (or <= with ``keep_below``); crossings get the
    bound exactly, so that vertices on a cell's side lie on it."""
    n, m = poly.shape[:2]
    k = np.arange(m)[None]
    valid = k < count[:, None]
    following = np.where(k + 1 < count[:, None], k + 1, 0)
    f = (bound - poly[..., axis]) if keep_below else (poly[..., axis] - bound)
    f_next = np.take_along_axis(f, following, axis=1)
    nxt = np.take_along_axis(poly, following[..., None], axis=1)
    inside, inside_next = f >= 0.0, f_next >= 0.0
    keep = valid & inside
    cut = valid & (inside != inside_next)
    t = np.where(cut, f / np.where(cut, f - f_next, 1.0), 0.0)  # f and f_next differ in sign there
    crossing = poly + t[..., None] * (nxt - poly)
    crossing[..., axis] = bound
    emit = np.stack([keep, cut], axis=2).reshape(n, 2 * m)
    values = np.stack([poly, crossing], axis=2).reshape(n, 2 * m, 2)
    position = np.cumsum(emit, axis=1) - 1
    out = np.zeros_like(poly)
    out[np.nonzero(emit)[0], position[emit]] = values[emit]
    return out, emit.sum(axis=1)


def clip_to_cells(corners: np.ndarray, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles ``corners (n, 3, 2)`` (counter-clockwise) clipped to the unit cells (i, j)
    (``(n,)`` each): ``(polygons (n, MAX_VERTICES, 2), counts (n,))`` in each cell's own
    coordinates ([0, 1]^2), counter-clockwise; count < 3 for an empty intersection."""
    poly = np.zeros((len(i), MAX_VERTICES, 2))
    poly[:, :3] = corners - np.stack([i, j], axis=1)[:, None].astype(np.float64)
    count = np.full(len(i), 3)
    for axis, bound, below in ((0, 0.0, False), (0, 1.0, True), (1, 0.0, False), (1, 1.0, True)):
        poly, count = _clip(poly, count, axis, bound, below)
    return poly, count


def polygon_moments(poly: np.ndarray, count: np.ndarray) -> np.ndarray:
    """``(n, 4)``: area and the integrals of x, y and xy over each polygon (``clip_to_cells``),
    by Green's theorem (Steger 1996), taken about the first vertex so that small polygons keep
    their relative precision, then moved back to the cell's origin."""
    m = poly.shape[1]
    k = np.arange(m)[None]
    valid = k < count[:, None]
    following = np.where(k + 1 < count[:, None], k + 1, 0)
    origin = poly[:, :1]
    p = np.where(valid[..., None], poly - origin, 0.0)
    q = np.take_along_axis(p, following[..., None], axis=1)
    x0, y0, x1, y1 = p[..., 0], p[..., 1], q[..., 0], q[..., 1]
    c = np.where(valid, x0 * y1 - x1 * y0, 0.0)
    area = c.sum(axis=1) / 2.0
    mx = ((x0 + x1) * c).sum(axis=1) / 6.0
    my = ((y0 + y1) * c).sum(axis=1) / 6.0
    mxy = (c * (x0 * y1 + 2.0 * x0 * y0 + 2.0 * x1 * y1 + x1 * y0)).sum(axis=1) / 24.0
    ox, oy = origin[:, 0, 0], origin[:, 0, 1]
    return np.stack([area, mx + ox * area, my + oy * area, mxy + ox * my + oy * mx + ox * oy * area], axis=1)


def _classify(corners: np.ndarray, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(full, empty) (n,)``: cells (i, j) inside their triangles (counter-clockwise ``corners
    (n, 3, 2)``), and cells outside one of its edges (every corner on or beyond it): the edge
    functions are linear, so their extremes over a cell are at its corners."""
    full = np.ones(len(i), dtype=bool)
    empty = np.zeros(len(i), dtype=bool)
    for k in range(3):
        a, b = corners[:, k], corners[:, (k + 1) % 3]
        dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
        at = dx * (j - a[:, 1]) - dy * (i - a[:, 0])  # the edge function at the cell's corner (i, j)
        full &= at + np.minimum(0.0, -dy) + np.minimum(0.0, dx) >= 0.0
        empty |= at + np.maximum(0.0, -dy) + np.maximum(0.0, dx) <= 0.0
    return full & ~empty, empty


def counter_clockwise(corners: np.ndarray) -> np.ndarray:
    """Triangles ``corners (T, 3, 2)`` with their order reversed where it is clockwise."""
    d1, d2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    clockwise = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0] < 0.0
    return np.where(clockwise[:, None, None], corners[:, ::-1], corners)


def footprint_area(corners: np.ndarray) -> np.ndarray:
    """``(...)`` the areas of triangles ``corners (..., 3, 2)``."""
    d1, d2 = corners[..., 1, :] - corners[..., 0, :], corners[..., 2, :] - corners[..., 0, :]
    return 0.5 * np.abs(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])


def cell_box(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(first, size)`` (T, 2) int64: the first cell (i, j) and the columns and rows of cells of
    the bounding box of each triangle ``corners (T, 3, 2)``."""
    first = np.floor(corners.min(axis=1)).astype(np.int64)
    return first, np.maximum(np.ceil(corners.max(axis=1)).astype(np.int64) - first, 1)


def _cells(first: np.ndarray, size: np.ndarray, start: int, stop: int):
    """Cells number ``start`` .. ``stop`` - 1 of the boxes ``first, size (T, 2)`` counted box by
    box, row by row: ``(triangle, i, j)`` (n,) each."""
    count = size[:, 0] * size[:, 1]
    ends = np.cumsum(count)
    index = np.arange(start, stop)
    tri = np.searchsorted(ends, index, side="right")
    j, i = np.divmod(index - (ends[tri] - count[tri]), size[tri, 0])
    return tri, first[tri, 0] + i, first[tri, 1] + j


def _moments(corners: np.ndarray, tri: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """``(n, 4)`` the moments (``polygon_moments``) of each cell (i, j)'s part of its triangle
    ``corners[tri]``: those of the whole cell inside, 0 outside, the clipped polygon's across."""
    full, empty = _classify(corners[tri], i, j)
    moments = np.zeros((len(i), 4))
    moments[full] = (1.0, 0.5, 0.5, 0.25)
    partial = np.flatnonzero(~full & ~empty)
    if len(partial):
        poly, n = clip_to_cells(corners[tri[partial]], i[partial], j[partial])
        moments[partial] = np.where((n >= 3)[:, None], polygon_moments(poly, n), 0.0)
    return moments


def integrate(grid: Grid, corners: np.ndarray, block: np.ndarray | None = None) -> np.ndarray:
    """The exact integrals of ``grid``'s lookup, RGB and luminance, over triangles ``corners
    (T, 3, 2)`` (grid coordinates): ``(T, 4)`` per triangle, or with ``block (T,)`` per block of
    ``block`` x ``block`` cells of each triangle's ``block_box``, ``(B, 4)`` those blocks one
    triangle after another, row by row."""
    corners = counter_clockwise(corners)
    per_block = block is not None
    block = np.ones(len(corners), dtype=np.int64) if block is None else block
    block_first, block_size_ = block_box(corners, block)
    box_first, box_size = block_first * block[:, None], block_size_ * block[:, None]
    block_start = np.concatenate([[0], np.cumsum(block_size_[:, 0] * block_size_[:, 1])])
    sums = np.zeros((int(block_start[-1]) if per_block else len(corners), 4))
    total = int(np.sum(box_size[:, 0] * box_size[:, 1]))
    for start in range(0, total, CHUNK):
        tri, i, j = _cells(box_first, box_size, start, min(total, start + CHUNK))
        moments = _moments(corners, tri, i, j)
        touched = moments[:, 0] > 0.0
        tri, i, j = tri[touched], i[touched], j[touched]
        rgb = np.maximum(grid.integrals(i, j, moments[touched]), 0.0)  # a sliver's rounding stays >= 0
        values = np.concatenate([rgb, (rgb @ LUMINANCE)[:, None]], axis=1)
        key = tri
        if per_block:
            b = block[tri]
            key = (block_start[tri] + (j - box_first[tri, 1]) // b * block_size_[tri, 0]
                   + (i - box_first[tri, 0]) // b)
        if len(key):
            lo = int(key.min())
            for channel in range(4):
                part = np.bincount(key - lo, weights=values[:, channel])
                sums[lo:lo + len(part), channel] += part
    return sums


def block_box(corners: np.ndarray, block: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(first, size)`` (T, 2) int64: the blocks of ``block (T,)`` x ``block`` cells (aligned to
    multiples of ``block``) that cover each triangle's ``cell_box``."""
    first, size = cell_box(corners)
    b = block[:, None]
    block_first = first // b
    return block_first, -(-(first + size) // b) - block_first


def block_sizes(size: np.ndarray, cap: int) -> np.ndarray:
    """``(T,)`` the smallest b such that blocks of b x b cells cover boxes of ``size (T, 2)``
    cells in at most ``cap`` blocks (each edge of a box may straddle one more block)."""
    b = np.maximum(1, np.ceil(np.sqrt(size[:, 0] * size[:, 1] / cap))).astype(np.int64)
    while True:
        over = (-(-size[:, 0] // b) + 1) * (-(-size[:, 1] // b) + 1) > cap
        over &= b < size.max(axis=1)
        if not over.any():
            return b
        b[over] += 1


# ---------------------------------------------------------------------------------------------
# Triangles of a scene: footprints, mean radiance, distributions


def corner_uv(scene, triangles: np.ndarray) -> np.ndarray:
    """``(T, 3, 2)`` (u, v) at the corners of ``triangles``, as ``lookup.uv_at`` interpolates
    them (Mitsuba's (0, 0), (1, 0), (0, 1) for a scene without coordinates)."""
    if len(scene.corner_uv) == 0:
        return np.tile(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), (len(triangles), 1, 1))
    return scene.corner_uv[triangles].reshape(-1, 3, 2)


def footprints(scene, triangles: np.ndarray) -> tuple[list, np.ndarray, np.ndarray]:
    """``(grids, texture, corners)``: the lookup grids (``Grid``) of the scene's emission
    textures, ``(T,)`` the one each triangle's emission reads (-1: untextured, or a texture
    without a grid, or a footprint that is degenerate or too large), and ``(T, 3, 2)`` each
    footprint's corners in its grid's coordinates, in the triangle's order (0 where texture is
    -1)."""
    emitters = scene.textures.emitters
    grids = [Grid.of(t) if i in emitters.values() else None for i, t in enumerate(scene.textures.textures)]
    texture = np.array([emitters.get(int(s), -1) for s in scene.shape_of_triangle[triangles]], dtype=np.int64)
    texture = np.where([t >= 0 and grids[t] is not None for t in texture], texture, -1).astype(np.int64)
    corners = np.zeros((len(triangles), 3, 2))
    uv = corner_uv(scene, triangles)
    for t in np.unique(texture[texture >= 0]):
        mine = texture == t
        corners[mine] = grids[t].corners(uv[mine])
    finite = np.all(np.isfinite(corners), axis=(1, 2))
    corners[~finite] = 0.0
    _, size = cell_box(corners)
    cells = size[:, 0].astype(np.float64) * size[:, 1]  # in float: int64 overflows on absurd (u, v)
    area = footprint_area(corners)
    edge2 = np.max(np.sum((corners - np.roll(corners, 1, axis=1)) ** 2, axis=2), axis=1)
    usable = (finite & (area >= MIN_FOOTPRINT) & (2.0 * area >= MIN_CONDITION * edge2)
              & (cells <= MAX_TEXEL_CELLS))
    if cells[usable].sum() > MAX_TOTAL_CELLS:  # the integrals would take minutes: none taken
        usable[:] = False
    texture[~usable] = -1
    corners[texture < 0] = 0.0
    return grids, texture, corners


def mean_radiance(scene, triangles: np.ndarray) -> np.ndarray:
    """``(T, 3)`` each triangle's emitted radiance averaged over its area: for a textured
    triangle the exact integral of its texture over its footprint divided by the footprint's
    area (module docstring), else (untextured, degenerate or huge footprints) the scene's
    constant emission (a textured shape's: its texture's mean)."""
    out = np.array(scene.emission[triangles], dtype=np.float64).reshape(-1, 3)
    if not scene.textures.emitters:
        return out
    grids, texture, corners = footprints(scene, triangles)
    for t in np.unique(texture[texture >= 0]):
        mine = texture == t
        out[mine] = integrate(grids[t], corners[mine])[:, :3] / footprint_area(corners[mine])[:, None]
    return out


def sampled_by_texels(scene, triangles: np.ndarray) -> np.ndarray:
    """``(T,)`` bool: which of ``triangles`` have an emission texture whose integral they take
    and that they can be sampled by."""
    if not scene.textures.emitters:
        return np.zeros(len(triangles), dtype=bool)
    return footprints(scene, triangles)[1] >= 0


@dataclass
class TexelTables:
    """The distributions of T triangles over their footprints' blocks (module docstring), one
    triangle after another (the ``triangle_texels`` rows: ``appendix`` there).

    shape : (T, 2) int64 rows R and columns C of blocks.   origin : (T, 2) grid coordinates of
    corner 0 in block units, relative to block (0, 0).   to_grid : (T, 2, 2) block coordinates
    per barycentric: g = origin + to_grid (b1, b2); both float32-exact.
    row_cdf : (sum R + 1,) float32 each triangle's marginal CDF over its rows.
    column_cdf : (sum R (C + 1),) float32 the CDF within each row.
    polygon : (sum R C,) int64 the row of ``polygons`` of a block that the footprint's edge
        cuts, -1 for the others (inside, or outside with probability 0).
    polygons : (P, 16) float32: vertex count, then (x, y) of up to 7 vertices in the block's
        coordinates, counter-clockwise.
    """

    shape: np.ndarray
    origin: np.ndarray
    to_grid: np.ndarray
    row_cdf: np.ndarray
    column_cdf: np.ndarray
    polygon: np.ndarray
    polygons: np.ndarray

    def starts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(T + 1,)`` each: where each triangle's part of ``row_cdf``, ``column_cdf`` and
        ``polygon`` starts."""
        rows, columns = self.shape[:, 0], self.shape[:, 1]
        return tuple(np.concatenate([[0], np.cumsum(n)]) for n in (rows + 1, rows * (columns + 1),
                                                                   rows * columns))

    def probability(self, t: int) -> np.ndarray:
        """``(R, C)`` the probability of each block of triangle ``t``, as sampling draws them
        (differences of the rounded CDFs)."""
        rows, columns = self.shape[t]
        row_start, column_start, _ = self.starts()
        marginal = np.diff(self.row_cdf[row_start[t]:row_start[t + 1]].astype(np.float64))
        within = self.column_cdf[column_start[t]:column_start[t + 1]].astype(np.float64)
        within = within.reshape(rows, columns + 1)
        return marginal[:, None] * np.diff(within, axis=1)


def cdf32(weight: np.ndarray) -> np.ndarray:
    """``(n, L + 1)`` float32 CDFs of the rows of ``weight (n, L)`` >= 0 (from 0, to 1 exactly;
    uniform for a row of zeros), in which every positive weight keeps a positive-width interval:
    each is first raised to at least ``MIN_SHARE`` of its row's total (module docstring)."""
    total = weight.sum(axis=1, keepdims=True)
    weight = np.where(weight > 0.0, np.maximum(weight, MIN_SHARE * total), 0.0)
    total = weight.sum(axis=1, keepdims=True)
    cdf = np.concatenate([np.zeros((len(weight), 1)), np.cumsum(weight, axis=1)], axis=1)
    uniform = np.linspace(0.0, 1.0, weight.shape[1] + 1)
    cdf = np.where(total > 0.0, cdf / np.where(total > 0.0, total, 1.0), uniform).astype(np.float32)
    cdf[:, -1] = 1.0
    if np.any((np.diff(cdf, axis=1) <= 0.0) & (weight > 0.0)):  # not with L < 2^20 (MIN_SHARE)
        raise AssertionError("a block of positive weight lost its interval in the float32 CDF")
    return cdf


def segment_cdf32(weight: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """``cdf32`` of each of the consecutive segments of ``weight`` of ``lengths (S,)``,
    concatenated: ``(sum (L + 1),)`` float32 (segments of one length at a time)."""
    starts = np.concatenate([[0], np.cumsum(lengths)])[:-1]
    out_starts = starts + np.arange(len(lengths))
    out = np.zeros(int(np.sum(lengths + 1)), dtype=np.float32)
    for length in np.unique(lengths):
        segments = np.flatnonzero(lengths == length)
        out[out_starts[segments, None] + np.arange(length + 1)] = cdf32(
            weight[starts[segments, None] + np.arange(length)])
    return out


def texel_tables(scene, triangles: np.ndarray) -> tuple[TexelTables, np.ndarray]:
    """``(tables, mean (T, 3))`` of ``triangles`` (each ``sampled_by_texels``): their
    distributions, each within its share of ``TABLE_FLOATS`` (at most ``MAX_BLOCKS`` blocks),
    and their mean radiance."""
    grids, texture, texel_corners = footprints(scene, triangles)
    if np.any(texture < 0):
        raise ValueError("texel_tables takes triangles that are sampled_by_texels")
    count = len(triangles)
    cap = int(np.clip(TABLE_FLOATS // (3 * max(count, 1)), 4, MAX_BLOCKS))
    block = block_sizes(cell_box(texel_corners)[1], cap)
    first, shape = block_box(texel_corners, block)
    shape = shape[:, ::-1].copy()  # (rows, columns)
    blocks = shape[:, 0] * shape[:, 1]
    block_start = np.concatenate([[0], np.cumsum(blocks)])
    sums = np.zeros((int(block_start[-1]), 4))
    for t in np.unique(texture):
        mine = np.flatnonzero(texture == t)
        part = integrate(grids[t], texel_corners[mine], block[mine])
        sums[np.repeat(block_start[mine] - np.concatenate([[0], np.cumsum(blocks[mine])])[:-1], blocks[mine])
             + np.arange(len(part))] = part
    whole = np.add.reduceat(sums, block_start[:-1], axis=0) if count else np.zeros((0, 4))
    mean = whole[:, :3] / footprint_area(texel_corners)[:, None]
    # The block grid, its map from barycentrics rounded to float32 as the light table holds it:
    # the triangles clipped here are the ones the kernels map points through.
    corners = (texel_corners - (first * block[:, None])[:, None].astype(np.float64)) / block[:, None, None]
    origin = corners[:, 0].astype(np.float32).astype(np.float64)
    to_grid = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]],
                       axis=2).astype(np.float32).astype(np.float64)
    unit = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])  # corners' barycentrics (b1, b2)
    corners = counter_clockwise(origin[:, None] + unit @ to_grid.transpose(0, 2, 1))
    tri, c, r = _cells(np.zeros_like(first), shape[:, ::-1], 0, int(block_start[-1]))
    full, empty = _classify(corners[tri], c, r)
    partial = np.flatnonzero(~full & ~empty)
    poly, vertices = clip_to_cells(corners[tri[partial]], c[partial], r[partial])
    poly = poly.astype(np.float32)
    kept = (vertices >= 3) & (polygon_moments(poly.astype(np.float64), vertices)[:, 0] > 0.0)
    weight = sums[:, 3].copy()
    weight[empty] = 0.0
    weight[partial[~kept]] = 0.0  # a sliver float32 cannot hold: below ~1e-14 of a block
    row_length = np.repeat(shape[:, 1], shape[:, 0])  # each row of each triangle: C blocks
    row_weight = (np.add.reduceat(weight, np.concatenate([[0], np.cumsum(row_length)[:-1]]))
                  if count else np.zeros(0))
    polygon = np.full(len(weight), -1, dtype=np.int64)
    polygon[partial[kept]] = np.arange(int(kept.sum()))
    polygons = np.zeros((int(kept.sum()), 16), dtype=np.float32)
    polygons[:, 0] = vertices[kept]
    polygons[:, 1:15] = poly[kept, :7].reshape(-1, 14)
    tables = TexelTables(shape, origin, to_grid, segment_cdf32(row_weight, shape[:, 0]),
                         segment_cdf32(weight, row_length), polygon, polygons)
    return tables, mean
