"""Sampling a textured emitting triangle by area x texel luminance: the ``triangle_texels``
technique (``--light-sampling area``, for emitters of kind ``textured_triangle``: the triangles
of a shape whose ``radiance`` is a bitmap or a checkerboard, ``tracer.lights.emitters``).

A triangle's (u, v) map is affine, so its points map one to one onto its footprint in texture
space, and the lookup's cells there (texels, or the cells between texel centres of a bilinear
lookup) carry a piecewise-constant distribution in proportion to the luminance integrated over
each cell's part of the footprint (``tracer.lights.textured_area``: built exactly, in blocks of
cells where the footprint is large). A sample inverts the marginal CDF over rows with u0 and the
conditional CDF within the row with u1 (``environment._invert``, the environment's inversion),
then places the point uniformly in the chosen block's part of the footprint with what is left
of u0 and u1 (the whole block, or the polygon the triangle's edge leaves of it: a triangle of its
fan by area, then Heitz's barycentrics), and maps it back to the surface. So the density is

    p_A(y) = P(block) / area_g(block ∩ F) x |det d(g)/d(b)| / |e1 x e2|

(g block coordinates, b = (b1, b2) barycentrics, e1 x e2 twice the triangle's area), and in
solid angle p = p_A d^2 / cos theta_light, front side only; the selection probability is
multiplied in by ``tracer.lights``. ``pdf`` finds the block of a hit point from its
barycentrics with the same numbers, so it is the density ``sample`` draws from (MIS). The
radiance returned is the triangle's mean (the estimator looks the texture up at the sampled
point, ``lookup.sampled_emission``).

=========  =====  ==========================================================
column     size   what
=========  =====  ==========================================================
V0         3      first vertex (world)
V1, V2     3, 3   the other vertices
NORMAL     3      unit front normal
EMISSION   3      the triangle's mean radiance (``textured_area.mean_radiance``)
TABLE      1      the row of its distribution's header (``appendix``)
=========  =====  ==========================================================

Its distribution follows the candidates' rows (``appendix``): a header row (``ORIGIN`` ...
columns), then the CDFs and the block -> polygon links packed 16 floats a row, then one row per
block the footprint's edge cuts (vertex count, then (x, y) of up to 7 vertices in the block's
coordinates).
"""

from __future__ import annotations

import math

import numpy as np

from ... import warp
from ...frame import add_scaled, cross, dot, sub
from ...jit import jit
from ...plugins import LightTechnique, register
from ..environment import _invert
from ..projected_images import MAX_TABLE_FLOATS

NAME = "triangle_texels"
V0, V1, V2, NORMAL, EMISSION, TABLE = 0, 3, 6, 9, 12, 15
WIDTH = 16
# Header columns: g = ORIGIN + TO_GRID (b1, b2) (row-major 2 x 2); rows and columns of blocks;
# flat indices (into the table's float32 view) of the row CDF, the column CDFs and the links.
ORIGIN, TO_GRID, ROWS, COLUMNS, ROW_CDF, COLUMN_CDF, LINKS = 0, 2, 6, 7, 8, 9, 10
HEADER_WIDTH = 16
PLUGIN = register(LightTechnique(NAME, code=9, module=__name__, rank=9, dims=2,
                                 emitters=("textured_triangle",), light_samplings=("area",), width=WIDTH,
                                 doc="a point by area x the texture's luminance"))


def rows(emitters) -> np.ndarray:
    """``(T, WIDTH)`` rows of T textured triangles (``emitters.TexturedTriangleEmitters``)."""
    out = np.zeros((len(emitters.area), WIDTH))
    out[:, V0:V0 + 9] = emitters.corners.reshape(len(emitters.area), 9)
    out[:, NORMAL:NORMAL + 3] = emitters.normal
    out[:, EMISSION:EMISSION + 3] = emitters.emission
    out[:, TABLE] = -1.0  # linked by ``appendix``
    return out


def _layout(tables) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(packed, polygons, owner)``: each triangle's rows of CDFs and links (16 floats a row),
    its count of polygon rows, and the triangle each block belongs to."""
    block_rows, columns = tables.shape[:, 0], tables.shape[:, 1]
    link_start = tables.starts()[2]
    packed = -(-((block_rows + 1) + block_rows * (columns + 1) + block_rows * columns) // 16)
    owner = np.repeat(np.arange(len(block_rows)), np.diff(link_start))
    polygons = np.bincount(owner[tables.polygon >= 0], minlength=len(block_rows))
    return packed, polygons, owner


def table_floats(emitters) -> int:
    """The floats the triangles' distributions take in the light table (:func:`appendix`)."""
    packed, polygons, _ = _layout(emitters.tables)
    return 16 * int(np.sum(1 + packed + polygons))


def appendix(emitters, start: int) -> tuple[np.ndarray, np.ndarray, int]:
    """The rows of the triangles' distributions (``textured_area.TexelTables``), to follow the
    table's rows from row ``start`` (``tracer.lights.build_tables``): ``(link (T,), rows (m, 16),
    TABLE)``, link the row of triangle t's header. Each triangle's rows: its header, its CDFs
    and links packed 16 floats a row, its polygons."""
    tables = emitters.tables
    block_rows, columns = tables.shape[:, 0], tables.shape[:, 1]
    row_start, column_start, link_start = tables.starts()
    packed, polygons, owner = _layout(tables)
    header = start + np.concatenate([[0], np.cumsum(1 + packed + polygons)])
    total = int(header[-1])
    if total * 16 > MAX_TABLE_FLOATS:
        from ...errors import InputError

        raise InputError(f"the textured emitters' distributions hold {total * 16:,} numbers with the light "
                         f"table; tracer's table holds {MAX_TABLE_FLOATS:,}", "lights")
    header = header[:-1]
    out = np.zeros((total - start, 16))
    flat = out.reshape(-1)
    body = (header + 1) * 16  # flat index (in the whole table) of each triangle's CDFs
    out[header - start, ORIGIN:ORIGIN + 2] = tables.origin
    out[header - start, TO_GRID:TO_GRID + 4] = tables.to_grid.reshape(-1, 4)
    out[header - start, ROWS], out[header - start, COLUMNS] = block_rows, columns
    out[header - start, ROW_CDF] = body
    out[header - start, COLUMN_CDF] = body + block_rows + 1
    out[header - start, LINKS] = body + block_rows + 1 + block_rows * (columns + 1)
    for values, starts, column in ((tables.row_cdf, row_start, ROW_CDF),
                                   (tables.column_cdf, column_start, COLUMN_CDF)):
        mine = np.repeat(np.arange(len(block_rows)), np.diff(starts))
        flat[out[header - start, column].astype(np.int64)[mine] - 16 * start + np.arange(len(values))
             - starts[mine]] = values
    # A cut block links to its polygon's row in the table, the others to -1.
    first_polygon = np.concatenate([[0], np.cumsum(polygons)])[:-1]
    polygon_row = header + 1 + packed
    links = np.where(tables.polygon >= 0, polygon_row[owner] + tables.polygon - first_polygon[owner], -1)
    flat[out[header - start, LINKS].astype(np.int64)[owner] - 16 * start + np.arange(len(links))
         - link_start[owner]] = links
    cut = tables.polygon >= 0
    out[links[cut] - start] = tables.polygons[tables.polygon[cut]]
    return header.astype(np.float64), out.astype(np.float32), TABLE


@jit
def _vertex(rows, q: int, v: int):
    return np.float64(rows[q, 1 + 2 * v]), np.float64(rows[q, 2 + 2 * v])


@jit
def _fan_area(rows, q: int, v: int) -> float:
    """Twice the area of the fan triangle (vertex 0, v, v + 1) of polygon row ``q``."""
    x0, y0 = _vertex(rows, q, 0)
    x1, y1 = _vertex(rows, q, v)
    x2, y2 = _vertex(rows, q, v + 1)
    return (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)


@jit
def polygon_area(rows, q: int) -> float:
    """The area of polygon row ``q``, in block units (the sum of its fan's triangles)."""
    total = 0.0
    for v in range(1, int(rows[q, 0]) - 1):
        total += _fan_area(rows, q, v)
    return 0.5 * total


@jit
def polygon_point(rows, q: int, a: float, b: float):
    """A point uniform in polygon row ``q`` for (a, b) uniform in [0, 1)^2: a fan triangle by
    area with a, then a point in it by Heitz's barycentrics of (what is left of a, b)."""
    count = int(rows[q, 0])
    target = a * 2.0 * polygon_area(rows, q)
    done = 0.0
    v = 1
    twice = _fan_area(rows, q, 1)
    while v < count - 2 and target >= done + twice:
        done += twice
        v += 1
        twice = _fan_area(rows, q, v)
    rest = min(max((target - done) / twice, 0.0), 0.9999999999999999) if twice > 0.0 else 0.0
    b1, b2 = warp.triangle_barycentric(rest, b)
    x0, y0 = _vertex(rows, q, 0)
    x1, y1 = _vertex(rows, q, v)
    x2, y2 = _vertex(rows, q, v + 1)
    return x0 + b1 * (x1 - x0) + b2 * (x2 - x0), y0 + b1 * (y1 - y0) + b2 * (y2 - y0)


@jit
def block_density(rows, h: int, r: int, c: int) -> float:
    """Probability per unit block area of block (r, c) of the distribution whose header is row
    ``h``: its probability from the rounded CDFs, over its area inside the footprint."""
    flat = rows.reshape(-1)
    columns = int(rows[h, COLUMNS])
    row_cdf = int(rows[h, ROW_CDF]) + r
    column_cdf = int(rows[h, COLUMN_CDF]) + r * (columns + 1) + c
    p = ((np.float64(flat[row_cdf + 1]) - np.float64(flat[row_cdf]))
         * (np.float64(flat[column_cdf + 1]) - np.float64(flat[column_cdf])))
    q = int(flat[int(rows[h, LINKS]) + r * columns + c])
    if q < 0 or not p > 0.0:
        return p
    area = polygon_area(rows, q)
    return p / area if area > 0.0 else 0.0


@jit
def _edges(rows, k: int):
    v0 = (np.float64(rows[k, V0]), np.float64(rows[k, V0 + 1]), np.float64(rows[k, V0 + 2]))
    e1 = (np.float64(rows[k, V1]) - v0[0], np.float64(rows[k, V1 + 1]) - v0[1], np.float64(rows[k, V1 + 2]) - v0[2])
    e2 = (np.float64(rows[k, V2]) - v0[0], np.float64(rows[k, V2 + 1]) - v0[1], np.float64(rows[k, V2 + 2]) - v0[2])
    return v0, e1, e2


@jit
def _grid(rows, h: int):
    """``(ox, oy, m00, m01, m10, m11)``: g = origin + M (b1, b2)."""
    return (np.float64(rows[h, ORIGIN]), np.float64(rows[h, ORIGIN + 1]), np.float64(rows[h, TO_GRID]),
            np.float64(rows[h, TO_GRID + 1]), np.float64(rows[h, TO_GRID + 2]), np.float64(rows[h, TO_GRID + 3]))


@jit
def _area_density(rows, h: int, r: int, c: int, e1, e2) -> float:
    """The density per unit surface area at a point of block (r, c) of a triangle with edges
    ``e1``, ``e2`` whose distribution's header is row ``h``."""
    _, _, m00, m01, m10, m11 = _grid(rows, h)
    normal = cross(e1, e2)
    return block_density(rows, h, r, c) * abs(m00 * m11 - m01 * m10) / math.sqrt(dot(normal, normal))


@jit
def _toward(rows, k: int, x, y, p_area: float):
    """``(wi, dist, le, pdf)`` toward point ``y`` of triangle row ``k`` with area density
    ``p_area``; 0 from the back side or at x."""
    lx, ly, lz = y[0] - x[0], y[1] - x[1], y[2] - x[2]
    d2 = lx * lx + ly * ly + lz * lz
    d = math.sqrt(d2)
    if not (d > 0.0 and p_area > 0.0):
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0
    wi = (lx / d, ly / d, lz / d)
    cos_light = -(rows[k, NORMAL] * wi[0] + rows[k, NORMAL + 1] * wi[1] + rows[k, NORMAL + 2] * wi[2])
    if cos_light <= 0.0:  # front side only
        return wi, d, (0.0, 0.0, 0.0), 0.0
    le = (np.float64(rows[k, EMISSION]), np.float64(rows[k, EMISSION + 1]), np.float64(rows[k, EMISSION + 2]))
    return wi, d, le, p_area * d2 / cos_light


@jit
def sample(rows, k: int, x, n, u0: float, u1: float):
    """A point on textured triangle row ``k`` by its texel distribution (module docstring):
    ``(wi, dist, le, pdf, False)``, pdf in solid angle, 0 from the back side."""
    h = int(rows[k, TABLE])
    flat = rows.reshape(-1)
    block_rows, columns = int(rows[h, ROWS]), int(rows[h, COLUMNS])
    row_cdf = int(rows[h, ROW_CDF])
    r, a = _invert(flat[row_cdf:row_cdf + block_rows + 1], u0)
    column_cdf = int(rows[h, COLUMN_CDF]) + r * (columns + 1)
    c, b = _invert(flat[column_cdf:column_cdf + columns + 1], u1)
    q = int(flat[int(rows[h, LINKS]) + r * columns + c])
    if q >= 0:
        a, b = polygon_point(rows, q, a, b)
    ox, oy, m00, m01, m10, m11 = _grid(rows, h)
    gx, gy = c + a - ox, r + b - oy
    det = m00 * m11 - m01 * m10
    b1 = (m11 * gx - m01 * gy) / det
    b2 = (m00 * gy - m10 * gx) / det
    v0, e1, e2 = _edges(rows, k)
    y = (v0[0] + b1 * e1[0] + b2 * e2[0], v0[1] + b1 * e1[1] + b2 * e2[1], v0[2] + b1 * e1[2] + b2 * e2[2])
    wi, d, le, p = _toward(rows, k, x, y, _area_density(rows, h, r, c, e1, e2))
    return wi, d, le, p, False


@jit
def pdf(rows, k: int, x, n, wi, dist: float) -> float:
    """Solid-angle pdf with which :func:`sample` picks the direction ``wi`` from ``x`` that hits
    textured triangle row ``k`` at distance ``dist``: the block of the hit point, found from
    its barycentrics; 0 from the back side."""
    cos_light = -(rows[k, NORMAL] * wi[0] + rows[k, NORMAL + 1] * wi[1] + rows[k, NORMAL + 2] * wi[2])
    if not cos_light > 0.0:
        return 0.0
    h = int(rows[k, TABLE])
    v0, e1, e2 = _edges(rows, k)
    # Barycentrics of the hit as tracer.geometry.barycentrics finds them: q = b1 e1 + b2 e2.
    q = sub(add_scaled(x, dist, wi), v0)
    normal = cross(e1, e2)
    area2 = dot(normal, normal)
    b1, b2 = dot(cross(q, e2), normal) / area2, dot(cross(e1, q), normal) / area2
    ox, oy, m00, m01, m10, m11 = _grid(rows, h)
    c = min(max(int(math.floor(ox + m00 * b1 + m01 * b2)), 0), int(rows[h, COLUMNS]) - 1)
    r = min(max(int(math.floor(oy + m10 * b1 + m11 * b2)), 0), int(rows[h, ROWS]) - 1)
    return _area_density(rows, h, r, c, e1, e2) * dist * dist / cos_light
