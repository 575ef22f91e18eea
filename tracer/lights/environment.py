"""The environment light in the kernels: its radiance along a direction, and sampling it by
inverting a piecewise-constant 2-D distribution.

**Lookup** (:func:`radiance`), as Mitsuba 3's ``envmap`` (``tracer.scene.environment`` gives
the convention): the direction into the map's frame, (u, t) from it, bilinear interpolation
of the texels, periodic in u and clamped in t.

**Sampling** (:func:`sample`, :func:`pdf`). The map is cut into R = H - 1 rows by W columns of
*cells* whose corners are texel centres: cell (r, c) spans t in [r, r + 1] / (H - 1) and u in
[c + 1/2, c + 3/2] / W (wrapping), so the lookup is bilinear inside each cell between four
texels. A cell's weight is the mean luminance of those four texels times the cell's solid
angle, Delta phi (cos theta_r - cos theta_{r+1}): an estimate of the radiance it sends, which is
positive wherever the lookup is (a cell that can send light can be sampled: the light-only
estimator stays unbiased). A sample inverts the marginal CDF over rows with u0, then the
conditional CDF within the row with u1 (the course notes' inversion method; pbrt-v4's
``PiecewiseConstant2D`` is the same construction over pixels), and places the direction
uniformly in solid angle inside the chosen cell with what is left of u0 and u1 (cos theta and
phi uniform). So the pdf is constant on each cell,

    p(w) = P(cell) / Omega(cell)        (per steradian),

with no 1 / sin theta at the poles (a pixel-based map sampled uniformly in (u, t) has
p(w) = p(u, t) / (2 pi^2 sin theta) instead). Luminance is Rec. 709's Y.

**Techniques** (``tracer.strategy.ENVIRONMENT_SAMPLINGS``, a strategy's
``environment_sampling``): the same inversion over other cell weights, so every one has an exact
pdf and one kernel serves them all:

- ``luminance`` (the default): the weights above;
- ``uniform``: weight = the cell's solid angle, so p(w) = 1 / (4 pi) everywhere (the baseline
  the others are measured against);
- ``compensated``: Karlik et al.'s MIS compensation ("MIS Compensation: Optimizing Sampling
  Techniques in Multiple Importance Sampling", SIGGRAPH Asia 2019): the cell's mean luminance
  less the map's solid-angle mean, clamped at 0, times its solid angle. Cells dimmer than the
  mean are never light-sampled, which leaves them to BSDF sampling: the estimate stays unbiased
  only where MIS with BSDF samples covers them, so a strategy without BSDF samples cannot take
  it (``tracer.strategy``). A map with no cell above its mean (a constant one) keeps the
  ``luminance`` weights, as pbrt-v4 falls back;
- ``product``: the luminance cells, chosen through a hierarchy of blocks weighted by the shading
  point's BSDF lobe (``tracer.lights.environment_product``: :func:`sample_product`,
  :func:`pdf_product`), so the pdf depends on the shading point and its material.

The environment is one light candidate, the last (``tracer.lights.emitters``), whose flux for
the ``power`` selection is pi r^2 times the integral of its mean radiance over the sphere, r
the radius of the scene's bounding sphere (what a disk of the scene's size would catch, as
pbrt-v4 estimates an infinite light's power), whatever the technique.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..frame import rotate
from ..jit import jit
from ..strategy import ENVIRONMENT_SAMPLINGS
from . import environment_product as product_sampling

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


class EnvironmentTable(NamedTuple):
    """What the kernels read of the environment (a table of zero cells without one).

    texels : (H, W, 3) float32 radiance.   to_map : (3, 3) float64, world to the map's frame
    (rows).   to_world : its transpose.   row_cdf : (R + 1,) float64 the marginal CDF over the
    R = H - 1 rows of cells.   column_cdf : (R, W + 1) float64 the CDF within each row.
    cell_pdf : (R, W) float64 the solid-angle pdf on each cell, P(cell) / Omega(cell).
    cos_edge : (R + 1,) cos theta at the rows' edges.   candidate : the environment's light
    candidate (-1: none, it is not light-sampled).   product : the blocks of ``product``
    sampling (``environment_product.ProductTable``; a one-block table for other samplings).
    """

    texels: np.ndarray
    to_map: np.ndarray
    to_world: np.ndarray
    row_cdf: np.ndarray
    column_cdf: np.ndarray
    cell_pdf: np.ndarray
    cos_edge: np.ndarray
    candidate: int
    product: product_sampling.ProductTable


def cell_weights(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(weight (R, W), solid_angle (R, W))`` of the cells of a map of scalar ``values (H, W)``
    (module docstring): weight = the mean of the cell's four values x its solid angle."""
    height, width = values.shape
    values = np.maximum(np.asarray(values, dtype=np.float64), 0.0)
    rows = values[:-1] + values[1:]  # rows r and r + 1
    mean = 0.25 * (rows + np.roll(rows, -1, axis=1))  # columns c and c + 1
    cos_edge = _cos_edges(height)
    band = (cos_edge[:-1] - cos_edge[1:]) * (2.0 * np.pi / width)
    solid_angle = np.repeat(band[:, None], width, axis=1)
    return mean * solid_angle, solid_angle


def sampling_weights(luminance: np.ndarray, sampling: str = "luminance") -> tuple[np.ndarray, np.ndarray]:
    """``(weight (R, W), solid_angle (R, W))``: the cells' weights under technique ``sampling``
    (``ENVIRONMENT_SAMPLINGS``, module docstring) of a map of luminance ``(H, W)``."""
    if sampling not in ENVIRONMENT_SAMPLINGS:
        raise ValueError(f"unknown environment sampling {sampling!r}; expected one of "
                         f"{', '.join(ENVIRONMENT_SAMPLINGS)}")
    weight, solid_angle = cell_weights(luminance)
    if sampling == "uniform":
        return solid_angle.copy(), solid_angle
    if sampling == "compensated":
        mean = weight.sum() / solid_angle.sum()  # the map's mean luminance over the sphere
        compensated = np.maximum(weight / solid_angle - mean, 0.0) * solid_angle
        if compensated.sum() > 0.0:
            return compensated, solid_angle
    return weight, solid_angle


def table(environment, candidate: int, sampling: str = "luminance") -> EnvironmentTable:
    """The kernels' table of ``environment`` (``tracer.scene.environment.Environment``, or None
    for a table that nothing reads), light candidate ``candidate`` (-1: not sampled), sampled
    by technique ``sampling`` (``ENVIRONMENT_SAMPLINGS``)."""
    if environment is None:
        return EnvironmentTable(np.zeros((2, 2, 3), dtype=np.float32), np.eye(3), np.eye(3), np.zeros(2),
                                np.zeros((1, 3)), np.zeros((1, 2)), np.ones(2), -1, product_sampling.empty())
    texels = environment.texels
    height, width = texels.shape[:2]
    weight, solid_angle = sampling_weights(texels.astype(np.float64) @ LUMINANCE, sampling)
    row_weight = weight.sum(axis=1)
    total = row_weight.sum()
    row_cdf = running_cdf(row_weight)
    column_cdf = np.empty((height - 1, width + 1))
    for r in range(height - 1):
        column_cdf[r] = running_cdf(weight[r])
    cell_pdf = weight / total / solid_angle if total > 0.0 else np.zeros_like(weight)
    cos_edge = _cos_edges(height)
    to_world = np.ascontiguousarray(environment.to_world, dtype=np.float64)
    blocks = (product_sampling.table(cell_pdf * solid_angle, cos_edge) if sampling == "product"
              else product_sampling.empty())
    return EnvironmentTable(np.ascontiguousarray(texels, dtype=np.float32), np.ascontiguousarray(to_world.T),
                            to_world, row_cdf, column_cdf, cell_pdf, cos_edge, int(candidate), blocks)


def power_integral(environment) -> float:
    """The integral over the sphere of the environment's mean (over channels) radiance, by the
    cells (each its four texels' mean x its solid angle): what ``flux`` scales."""
    weight, _ = cell_weights(environment.texels.astype(np.float64).mean(axis=2))
    return float(weight.sum())


def flux(environment, radius: float) -> float:
    """The environment's flux for the ``power`` selection: pi r^2 x :func:`power_integral`."""
    return math.pi * radius * radius * power_integral(environment)


def _cos_edges(height: int) -> np.ndarray:
    """(H,) cos theta at the rows of a map of H rows, which are the edges of its cells' rows."""
    return np.cos(np.pi * np.arange(height) / (height - 1))


def running_cdf(weight: np.ndarray) -> np.ndarray:
    """(n + 1,) the normalized running sum of ``weight (n,)`` from 0; uniform if it sums to 0
    (a row that is never chosen still gets a valid CDF)."""
    total = weight.sum()
    if not total > 0.0:
        return np.linspace(0.0, 1.0, len(weight) + 1)
    cdf = np.concatenate([[0.0], np.cumsum(weight)]) / total
    cdf[-1] = 1.0
    return cdf


@jit
def _invert(cdf, u: float):
    """``(i, rest)``: the interval i of ``cdf (n + 1,)`` that holds u (cdf[i] <= u < cdf[i+1],
    one of positive width) and where in it u lies, in [0, 1)."""
    n = len(cdf) - 1
    lo, hi = 0, n
    # cdf[lo] <= u < cdf[hi] throughout (cdf[0] = 0 <= u < 1 = cdf[n]), so the interval found
    # has positive width.
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if cdf[mid] <= u:
            lo = mid
        else:
            hi = mid
    rest = (u - cdf[lo]) / (cdf[lo + 1] - cdf[lo])
    return lo, min(max(rest, 0.0), 0.9999999999999999)  # rounding may reach 1


@jit
def map_coordinates(env, wi):
    """``(u, t)`` of the world unit direction ``wi`` in the map: u in [0, 1), t in [0, 1]."""
    v = rotate(env.to_map, wi)
    u = math.atan2(v[0], -v[2]) * (0.5 / math.pi)
    u -= math.floor(u)
    return u, math.acos(min(max(v[1], -1.0), 1.0)) / math.pi


@jit
def radiance(env, wi):
    """RGB radiance arriving from the environment along the world unit direction ``-wi``, that
    is seen looking along ``wi`` (the bilinear lookup of the module docstring)."""
    texels = env.texels
    height, width = texels.shape[0], texels.shape[1]
    u, t = map_coordinates(env, wi)
    x = u * width - 0.5
    i0 = int(math.floor(x))
    fx = x - i0
    i0 %= width
    i1 = (i0 + 1) % width
    y = t * (height - 1)
    j0 = min(int(y), height - 2)
    fy = y - j0
    j1 = j0 + 1
    out0 = (1.0 - fy) * ((1.0 - fx) * texels[j0, i0, 0] + fx * texels[j0, i1, 0]) \
        + fy * ((1.0 - fx) * texels[j1, i0, 0] + fx * texels[j1, i1, 0])
    out1 = (1.0 - fy) * ((1.0 - fx) * texels[j0, i0, 1] + fx * texels[j0, i1, 1]) \
        + fy * ((1.0 - fx) * texels[j1, i0, 1] + fx * texels[j1, i1, 1])
    out2 = (1.0 - fy) * ((1.0 - fx) * texels[j0, i0, 2] + fx * texels[j0, i1, 2]) \
        + fy * ((1.0 - fx) * texels[j1, i0, 2] + fx * texels[j1, i1, 2])
    return out0, out1, out2


@jit
def cell_of(env, wi):
    """``(r, c)`` the sampling cell that holds the world unit direction ``wi``."""
    width = env.cell_pdf.shape[1]
    rows = env.cell_pdf.shape[0]
    u, t = map_coordinates(env, wi)
    c = int(math.floor(u * width - 0.5)) % width
    r = min(int(t * rows), rows - 1)
    return r, c


@jit
def pdf(env, wi) -> float:
    """Solid-angle pdf with which :func:`sample` picks the world unit direction ``wi``."""
    r, c = cell_of(env, wi)
    return env.cell_pdf[r, c]


@jit
def direction_in_cell(env, r: int, c: int, a: float, b: float):
    """The world unit direction at (a, b) in [0, 1)^2 of cell (r, c), uniform in solid angle:
    cos theta = lerp(cos_edge[r], cos_edge[r + 1], a), phi from the cell's first column edge by
    b. The inverse of :func:`cell_of` with the fractions (tests round-trip it)."""
    width = env.cell_pdf.shape[1]
    cos_theta = env.cos_edge[r] + a * (env.cos_edge[r + 1] - env.cos_edge[r])
    sin_theta = math.sqrt(max(1.0 - cos_theta * cos_theta, 0.0))
    phi = 2.0 * math.pi * (c + 0.5 + b) / width
    # Mitsuba's uv_to_direction: u = phi / 2 pi, (sin phi sin theta, cos theta, -cos phi sin theta).
    local = (math.sin(phi) * sin_theta, cos_theta, -math.cos(phi) * sin_theta)
    return rotate(env.to_world, local)


@jit
def sample(env, u0: float, u1: float):
    """A direction toward the environment: ``(wi, le, pdf)``, wi world unit, le the radiance
    arriving along it, pdf per steradian (0 if the environment sends nothing)."""
    r, a = _invert(env.row_cdf, u0)
    c, b = _invert(env.column_cdf[r], u1)
    p = env.cell_pdf[r, c]
    wi = direction_in_cell(env, r, c, a, b)
    if not p > 0.0:
        return wi, (0.0, 0.0, 0.0), 0.0
    return wi, radiance(env, wi), p


@jit
def sample_product(env, lobe, u0: float, u1: float):
    """:func:`sample` by ``product`` sampling for the shading point whose lobe proxy (in the
    map's frame) is ``lobe`` (``environment_product.lobe_in_map``): ``(wi, le, pdf)``. u0 walks
    the blocks and then places the direction within its cell in theta; u1 picks the cell within
    the block and places it in phi."""
    blocks = env.product
    i, j, p_tree, a = product_sampling.descend(blocks, lobe, u0)
    b = (i * (len(blocks.column_edge) - 1) + j)
    start = blocks.cdf_start[b]
    r0, c0 = blocks.row_edge[i], blocks.column_edge[j]
    columns = blocks.column_edge[j + 1] - c0
    cells = (blocks.row_edge[i + 1] - r0) * columns
    k, rest = _invert(blocks.cell_cdf[start:start + cells + 1], u1)
    r, c = r0 + k // columns, c0 + k % columns
    wi = direction_in_cell(env, r, c, a, rest)
    finest = blocks.level_start[len(blocks.level_start) - 2] + b
    p = p_tree * env.cell_pdf[r, c] / blocks.block[finest, product_sampling.ENERGY]
    if not p > 0.0:
        return wi, (0.0, 0.0, 0.0), 0.0
    return wi, radiance(env, wi), p


@jit
def pdf_product(env, lobe, wi) -> float:
    """Solid-angle pdf with which :func:`sample_product` picks the world unit direction ``wi``
    for the same ``lobe``: p_lum(wi) P_tree(block) / E_block (``environment_product``)."""
    r, c = cell_of(env, wi)
    p_cell = env.cell_pdf[r, c]
    if not p_cell > 0.0:
        return 0.0
    blocks = env.product
    i, j = blocks.row_block[r], blocks.column_block[c]
    finest = blocks.level_start[len(blocks.level_start) - 2] + i * (len(blocks.column_edge) - 1) + j
    return (product_sampling.tree_probability(blocks, lobe, i, j) * p_cell
            / blocks.block[finest, product_sampling.ENERGY])
