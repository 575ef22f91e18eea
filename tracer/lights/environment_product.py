"""Product sampling of the environment: directions in proportion to (an approximation of) the
environment's luminance times the receiver's BSDF lobe, with an exact pdf.

Luminance sampling (``tracer.lights.environment``) follows the map alone: under a sky it sends
half its samples below a diffuse receiver's horizon, and a glossy receiver's lobe takes only the
few that fall inside it. This technique multiplies the map by the shading point's lobe on a
hierarchy of blocks of cells, descends it, then picks a cell inside the final block by the map's
luminance as luminance sampling does. It is the product sampling of Clarberg and
Akenine-Möller ("Practical product importance sampling for direct illumination", Eurographics
2008: a quadtree over the environment whose children are chosen by map sum x BSDF value, built
per shading point), with two changes that keep it cheap: the tree is walked, not built (each
level weighs only the four children of the block chosen above it: 2 + 4 L lobe evaluations a
sample, 22 at the finest level 32 x 64), and the lobe is a closed-form proxy of the material,
not the material itself.

**Blocks.** Level 0 is 1 x 2 blocks (the map's two halves in u); level l is 2^l x 2^(l+1);
block (i, j) of level l holds the cell rows [floor(i R / 2^l), floor((i + 1) R / 2^l)) and the
columns [floor(j W / 2^(l+1)), ...) of the map's R x W cells, so each block's four children at
level l + 1 partition it. The finest level L is at most ``MAX_LEVEL`` (32 x 64 blocks, 5.6
degrees) and no finer than the map's cells. A block stores its luminance share E (the sum of its
cells' luminance-sampling probabilities: E of a block is P_lum(block)), its centre direction c
and the angular radius rho of a cone around c that holds it (in the map's frame).

**The lobe proxy** (``lobe``: from the material's ``lobe(params, row, wo) -> (kd, ks, ku,
alpha)``, a plug-in function; a material without one gets ku = 1, so the product is luminance
sampling) is, with x = 1 - r . w for the mirror direction r of wo,

    g(w) = kd max(0, cos theta) / pi + ks (1 + 2 lambda) / (4 pi (1 + lambda x)^2) + ku / (4 pi) + floor,

a diffuse part; a glossy part of sharpness lambda = 1 / (2 alpha^2), normalized over the sphere,
which is the GGX distribution's shape carried to reflected directions (GGX's D is alpha^2 /
(pi (alpha^2 + (1 - alpha^2) (1 - cos theta_h^2))^2), and 1 - cos theta_h^2 = x / 2 where wo is
along the normal); a uniform part (transmission, or a material the proxy does not know); and a
floor of ``FLOOR`` times their sum. Its heavy tails are deliberate: with a Gaussian of the same
width (Beckmann's shape) the glossy sphere of ``environment_studio.xml`` had 2.7x the error
under MIS, since a bright region just outside the lobe was then almost never sampled. A child's
weight is E x g, g taken at the block's centre and widened over the block: the cosine averaged
over a cap of half-width sin rho across the horizon (Karis's smooth horizon), the glossy part
widened (1 / lambda_b = 1 / lambda + rho^2 / 2) and kept only if some of the block is above the
horizon. Coarse blocks thus see a broad lobe and fine blocks the real one; a lobe between two
block centres is not lost. Where every child weighs 0 the level falls back to E alone.

**pdf.** The descent picks the finest block b with probability P_tree(b) (the product of each
level's w_chosen / sum of w), then a cell c of b with probability P_lum(c) / E_b, then a
direction uniformly in the cell's solid angle, so

    p(w) = P_tree(b) P_lum(c) / (E_b Omega(c)) = p_lum(w) P_tree(b) / E_b     (per steradian),

a pure function of the shading point's lobe and w, which ``environment.pdf_product``
recomputes by walking the levels down to w's block. p > 0 wherever p_lum > 0 (the floor), so
light sampling alone stays unbiased with it; the proxy's quality only changes the variance.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..frame import rotate
from ..jit import jit

# 32 x 64 blocks at the finest level (5.6 degrees), 22 lobe evaluations per sample or pdf.
MAX_LEVEL = 5
# Every block keeps at least this share of the proxy's mean density (a density > 0 wherever the
# map sends light: no cell is left to other techniques).
FLOOR = 1e-3
# Sharpest glossy lobe the proxy uses (alpha ~ 2e-3): sharper lobes are as good as delta lobes to
# a block of cells.
MAX_SHARPNESS = 1e5
INV_4PI = 0.25 / math.pi
INV_PI = 1.0 / math.pi
# The columns of ``ProductTable.block``.
ENERGY, CENTRE, HALF_RHO2, COS_RHO, SIN_RHO = 0, 1, 4, 5, 6
# What a material without a ``lobe`` function gives: the uniform part alone.
NO_LOBE = (0.0, 0.0, 1.0, 1.0)


class ProductTable(NamedTuple):
    """The block hierarchy of one map (module docstring), for levels 0 .. L.

    level_start : (L + 2,) int64, where level l's blocks begin in ``block`` (level l has
        2^l x 2^(l+1) blocks, row-major).
    block : (B, 8) float64, a row per block (one 64-byte cache line; one array, so that the
        descent reads it through the table once, not once per field): E (``ENERGY``, P_lum of
        the block), the unit centre direction in the map's frame (``CENTRE``, 3), rho^2 / 2 of
        the angular radius rho of the bounding cone about it (``HALF_RHO2``), cos rho and
        sin rho.
    row_edge : (2^L + 1,) int64, column_edge : (2^(L+1) + 1,) int64, the cell rows and columns
        where the finest blocks begin.   row_block : (R,) int64, column_block : (W,) int64, the
        finest block row and column of each cell row and column.
    """

    level_start: np.ndarray
    block: np.ndarray
    row_edge: np.ndarray
    column_edge: np.ndarray
    row_block: np.ndarray
    column_block: np.ndarray
    cell_cdf: np.ndarray
    cdf_start: np.ndarray


def finest_level(rows: int, columns: int) -> int:
    """L for a map of ``rows`` x ``columns`` cells: at most ``MAX_LEVEL``, and blocks of at
    least one cell each way where the map allows (level 0 always)."""
    level = 0
    while level < MAX_LEVEL and 2 ** (level + 1) <= rows and 2 ** (level + 2) <= columns:
        level += 1
    return level


def empty() -> ProductTable:
    """The table of a render that does not sample by product (nothing reads it)."""
    return table(np.ones((1, 2)), np.array([1.0, -1.0]))


def table(cell_probability: np.ndarray, cos_edge: np.ndarray) -> ProductTable:
    """The blocks of a map whose R x W cells have luminance-sampling probabilities
    ``cell_probability (R, W)`` (summing to 1, or all 0) and rows edged at ``cos_edge (R + 1,)``
    (cos theta, from +1 down)."""
    from .environment import running_cdf  # (that module builds these tables: imported here)

    rows, columns = cell_probability.shape
    top = finest_level(rows, columns)
    starts, energy, centre, rho = [0], [], [], []
    theta_edge = np.arccos(np.clip(cos_edge, -1.0, 1.0))
    for level in range(top + 1):
        n_rows, n_columns = 2 ** level, 2 ** (level + 1)
        row_edge = (np.arange(n_rows + 1) * rows) // n_rows
        column_edge = (np.arange(n_columns + 1) * columns) // n_columns
        # E: the cells' probabilities summed over each block's rows, then its columns.
        by_rows = np.add.reduceat(cell_probability, row_edge[:-1], axis=0) if rows else cell_probability
        by_rows[row_edge[:-1] == row_edge[1:]] = 0.0  # reduceat gives an empty block one row
        block = np.add.reduceat(by_rows, column_edge[:-1], axis=1)
        block[:, column_edge[:-1] == column_edge[1:]] = 0.0
        energy.append(block.ravel())
        # Cell column c spans phi in 2 pi [c + 1/2, c + 3/2] / W (cells start at texel centres).
        phi_edge = 2.0 * np.pi * (column_edge + 0.5) / columns
        cones = [_cone(theta_edge[row_edge[i]], theta_edge[row_edge[i + 1]], phi_edge[j], phi_edge[j + 1])
                 for i in range(n_rows) for j in range(n_columns)]
        centre.extend(c for c, _ in cones)
        rho.extend(r for _, r in cones)
        starts.append(starts[-1] + n_rows * n_columns)
    block = np.zeros((starts[-1], 8))
    block[:, ENERGY] = np.concatenate(energy)
    block[:, CENTRE:CENTRE + 3] = centre
    block[:, HALF_RHO2] = 0.5 * np.square(rho)
    block[:, COS_RHO], block[:, SIN_RHO] = np.cos(rho), np.sin(np.minimum(rho, 0.5 * np.pi))
    finest_rows = (np.arange(2 ** top + 1) * rows) // 2 ** top
    finest_columns = (np.arange(2 ** (top + 1) + 1) * columns) // 2 ** (top + 1)
    row_block = np.searchsorted(finest_rows, np.arange(rows), side="right") - 1
    column_block = np.searchsorted(finest_columns, np.arange(columns), side="right") - 1
    cdfs, cdf_start, at = [], [], 0
    for i in range(2 ** top):
        for j in range(2 ** (top + 1)):
            cells = cell_probability[finest_rows[i]:finest_rows[i + 1],
                                     finest_columns[j]:finest_columns[j + 1]].ravel()
            cdfs.append(running_cdf(cells))
            cdf_start.append(at)
            at += len(cells) + 1
    return ProductTable(np.asarray(starts, dtype=np.int64), block, finest_rows.astype(np.int64),
                        finest_columns.astype(np.int64), row_block.astype(np.int64),
                        column_block.astype(np.int64), np.concatenate(cdfs),
                        np.asarray(cdf_start, dtype=np.int64))



def _map_direction(theta, phi) -> np.ndarray:
    """Unit directions in the map's frame (``environment.direction_in_cell``'s convention)."""
    return np.stack([np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)], axis=-1)


def _cone(theta0: float, theta1: float, phi0: float, phi1: float) -> tuple[np.ndarray, float]:
    """``(centre (3,), rho)``: a cone about the block's middle direction that holds the block
    theta in [theta0, theta1], phi in [phi0, phi1], rho measured over a 9 x 9 grid of the
    block's points (edges included) plus the grid's spacing, so that no point between them
    lies outside."""
    centre = _map_direction(0.5 * (theta0 + theta1), 0.5 * (phi0 + phi1))
    theta, phi = np.meshgrid(np.linspace(theta0, theta1, 9), np.linspace(phi0, phi1, 9))
    points = _map_direction(theta, phi).reshape(-1, 3)
    angle = np.arccos(np.clip(points @ centre, -1.0, 1.0)).max()
    spacing = max(theta1 - theta0, (phi1 - phi0) * math.sin(min(0.5 * (theta0 + theta1), math.pi / 2))) / 8
    return centre, float(min(angle + spacing, math.pi))


@jit
def lobe_in_map(to_map, material_lobe, normal, mirror):
    """The shading point's lobe proxy in the map's frame: ``(normal, mirror, kd, ks, ku,
    spread, floor)`` from ``material_lobe = (kd, ks, ku, alpha)`` (module docstring; spread =
    1 / lambda = 2 alpha^2), the world unit shading ``normal`` and ``mirror`` direction (wo
    reflected about it), and the map's ``to_map (3, 3)`` rotation."""
    kd, ks, ku, alpha = material_lobe
    kd, ks, ku = max(kd, 0.0), max(ks, 0.0), max(ku, 0.0)
    if not kd + ks + ku > 0.0:
        kd, ks, ku = 0.0, 0.0, 1.0
    spread = max(2.0 * alpha * alpha, 1.0 / MAX_SHARPNESS)
    floor = FLOOR * (kd + ks + ku) * INV_4PI
    return (rotate(to_map, normal), rotate(to_map, mirror), kd, ks, ku, spread, floor)


@jit
def block_weight(block, b: int, lobe) -> float:
    """E x g of block row ``b`` of ``block`` (module docstring): g the proxy made no smaller
    over the block."""
    e = block[b, ENERGY]
    if not e > 0.0:
        return 0.0
    normal, mirror, kd, ks, ku, spread, floor = lobe
    c0, c1, c2 = block[b, CENTRE], block[b, CENTRE + 1], block[b, CENTRE + 2]
    g = floor + ku * INV_4PI
    cos_n = normal[0] * c0 + normal[1] * c1 + normal[2] * c2
    # The clamped cosine over the block, by Karis's smooth horizon for a cap of half-width
    # sin rho about the centre ("Real shading in Unreal Engine 4", SIGGRAPH 2013 course notes,
    # sphere lights): cos theta above the horizon, (cos theta + sin rho)^2 / (4 sin rho) across
    # it, 0 only where the whole cap is below (no block the surface sees is dropped).
    spread_n = block[b, SIN_RHO]
    if cos_n >= spread_n:
        horizon = cos_n
    elif cos_n > -spread_n:
        horizon = (cos_n + spread_n) * (cos_n + spread_n) / (4.0 * spread_n)
    else:
        horizon = 0.0
    if horizon > 0.0:
        g += kd * horizon * INV_PI
        if ks > 0.0:
            # The glossy lobe widened by the block: 1 / lambda_b = 1 / lambda + rho^2 / 2.
            sharpness = 1.0 / (spread + block[b, HALF_RHO2])
            d = 1.0 + sharpness * (1.0 - (mirror[0] * c0 + mirror[1] * c1 + mirror[2] * c2))
            g += ks * (1.0 + 2.0 * sharpness) * INV_4PI / (d * d)
    return e * g


@jit
def _weights4(block, lobe, first: int, step: int):
    """The weights of blocks first, first + 1, first + step, first + step + 1 (a node's four
    children, row-major in a level ``step`` blocks wide); by E alone where all four are 0 (the
    lobe sees none of them)."""
    w0 = block_weight(block, first, lobe)
    w1 = block_weight(block, first + 1, lobe)
    w2 = block_weight(block, first + step, lobe)
    w3 = block_weight(block, first + step + 1, lobe)
    if not w0 + w1 + w2 + w3 > 0.0:
        w0, w1 = block[first, ENERGY], block[first + 1, ENERGY]
        w2, w3 = block[first + step, ENERGY], block[first + step + 1, ENERGY]
    return w0, w1, w2, w3


@jit
def _root_weights(block, lobe):
    """The weights of level 0's two halves (by E alone where both are 0)."""
    w0 = block_weight(block, 0, lobe)
    w1 = block_weight(block, 1, lobe)
    if not w0 + w1 > 0.0:
        return block[0, ENERGY], block[1, ENERGY]
    return w0, w1


@jit
def _pick(w0: float, w1: float, w2: float, w3: float, u: float):
    """``(which, probability, u rescaled)`` of one of four weights (some may be 0) for u."""
    total = w0 + w1 + w2 + w3
    scaled = u * total
    if scaled < w0:
        which, below, w = 0, 0.0, w0
    elif scaled < w0 + w1:
        which, below, w = 1, w0, w1
    elif scaled < w0 + w1 + w2:
        which, below, w = 2, w0 + w1, w2
    else:
        which, below, w = 3, w0 + w1 + w2, w3
        # Rounding may put u past the last nonempty weight: take that one.
        if not w3 > 0.0:
            which, below, w = 2, w0 + w1, w2
            if not w2 > 0.0:
                which, below, w = 1, w0, w1
                if not w1 > 0.0:
                    which, below, w = 0, 0.0, w0
    return which, w / total, min(max((scaled - below) / w, 0.0), 0.9999999999999999)


@jit
def descend(product, lobe, u: float):
    """The finest block the descent picks with ``u``: ``(i, j, P_tree, u rescaled)``."""
    block, level_start = product.block, product.level_start
    w0, w1 = _root_weights(block, lobe)
    j, p, u = _pick(w0, w1, 0.0, 0.0, u)
    i = 0
    for level in range(1, len(level_start) - 1):
        width = 2 << level  # 2^(level + 1) blocks across
        w0, w1, w2, w3 = _weights4(block, lobe, level_start[level] + (2 * i) * width + 2 * j, width)
        which, share, u = _pick(w0, w1, w2, w3, u)
        i, j = 2 * i + which // 2, 2 * j + which % 2
        p *= share
    return i, j, p, u


@jit
def tree_probability(product, lobe, i: int, j: int) -> float:
    """P_tree of finest block (i, j): the product of each level's share down to it (0 for a
    block the descent cannot reach)."""
    block, level_start = product.block, product.level_start
    top = len(level_start) - 2
    w0, w1 = _root_weights(block, lobe)
    w = w0 if (j >> top) == 0 else w1
    if not w > 0.0:
        return 0.0
    p = w / (w0 + w1)
    for level in range(1, top + 1):
        shift = top - level
        bi, bj = i >> shift, j >> shift
        width = 2 << level
        w0, w1, w2, w3 = _weights4(block, lobe, level_start[level] + (bi & ~1) * width + (bj & ~1), width)
        which = 2 * (bi & 1) + (bj & 1)
        w = w0 if which == 0 else w1 if which == 1 else w2 if which == 2 else w3
        if not w > 0.0:  # a block the descent never reaches (no light in it)
            return 0.0
        p *= w / (w0 + w1 + w2 + w3)
    return p
