"""Directions uniform in a triangle's solid angle (``tracer.lights.spherical_triangle``) and the
bilinear warp of the square (``tracer.lights.bilinear``) against the densities they claim, plus
the deterministic identities: the solid angle against closed forms and quadrature, the inverse
maps against the forward ones, the corners of the square, the degenerate inputs.

Statistical tests: each chi-square test runs at the Sidak level ALPHA = 1 - 0.99^(1/N_STAT)
over the N_STAT statistical tests of this file, so a correct implementation fails the file with
probability <= 1 %; seeds are fixed, so a pass is reproducible and a failure is worth reading.
Deterministic tests each state their tolerance and why.

Every triangle configuration is moved by one fixed, generic rotation and offset: coordinates
that are exactly 0 or share an axis round more favourably than general ones and would make the
round-trip errors look better than they are.
"""

from __future__ import annotations

from decimal import Decimal, localcontext

import numpy as np
import pytest
from scipy import integrate, stats

from tracer.lights import bilinear, spherical_triangle

import chi2

EPS = np.finfo(np.float64).eps
N_SAMPLES = 1_000_000
GRID = (40, 80)  # (theta, phi) cells of the cap around the triangle

# Configurations (x, a, b, c) before the common rotation: a small distant triangle (5.3e-5 sr),
# a large close one (2.6 sr), a thin sliver (width 0.03 over length 2, seen from 2), a grazing
# view (x 0.01 above the plane, 0.6 away from the triangle).
CHI2_CASES = {
    "small_distant": ((0.2, -0.1, 0.05), (-0.05, -0.03, 10.0), (0.06, -0.02, 10.02), (0.01, 0.07, 9.98)),
    "large_close": ((0.1, 0.2, 0.0), (-1.0, -0.8, 0.5), (1.2, -0.6, 0.6), (0.1, 1.1, 0.45)),
    "sliver": ((0.0, 0.0, 0.0), (-1.0, 0.0, 2.0), (1.0, 0.03, 2.1), (0.9, 0.06, 1.9)),
    "grazing": ((-0.5, -0.7, 0.01), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.3, 1.0, 0.0)),
}
# Extremes for the deterministic tests only: 1e-7 rad across seen from 1e3; x 1e-7 above the
# plane; x 1e-3 above the interior (solid angle 2 pi - 0.02).
EXTREME_CASES = {
    "tiny_far": ((0.0, 0.0, 0.0), (1e3, 0.0, 0.0), (1e3, 1e-4, 0.0), (1e3, 0.0, 1e-4)),
    "grazing_1e-7": ((-0.5, -0.7, 1e-7), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.3, 1.0, 0.0)),
    "near_hemisphere": ((0.3, 0.3, 1e-3), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.3, 1.0, 0.0)),
}
BILINEAR_WEIGHTS = {
    "ramp": (1.0, 2.0, 3.0, 4.0),
    "steep": (0.01, 1.0, 0.01, 5.0),  # a clamped cosine: ratio 500 between corners
    "near_equal": (1.0, 1.0 + 1e-7, 1.0 - 1e-7, 1.0),
}
BILINEAR_GRID = (32, 32)

# Statistical tests in this file: chi-square of the spherical triangle (one per case) and of
# the bilinear warp (one per weight set).
N_STAT = len(CHI2_CASES) + len(BILINEAR_WEIGHTS)
ALPHA = chi2.sidak(N_STAT)


def rng(*key: int) -> np.random.Generator:
    """A fixed, independent stream per test (and per case)."""
    return np.random.default_rng([20240917, *key])


def _rotation() -> np.ndarray:
    """Rotation by 0.9 rad about (1, 2, 3) (Rodrigues' formula)."""
    k = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(0.9) * kx + (1.0 - np.cos(0.9)) * kx @ kx


ROTATION, OFFSET = _rotation(), np.array([0.3, -1.7, 2.2])


def config(name: str) -> tuple[np.ndarray, ...]:
    """(x, a, b, c) of a case, rotated and offset."""
    points = {**CHI2_CASES, **EXTREME_CASES}[name]
    return tuple(ROTATION @ np.array(p) + OFFSET for p in points)


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def solid_angle(x, a, b, c) -> float:
    return spherical_triangle.solid_angle(*(tuple(map(float, p)) for p in (x, a, b, c)))


def ray_barycentrics(x, a, b, c, w):
    """Moller-Trumbore: (b1, b2, t) where the rays x + t w (w (n, 3)) meet the triangle's plane,
    the point being a + b1 (b - a) + b2 (c - a). Independent of the code under test."""
    e1, e2 = b - a, c - a
    p = np.cross(w, e2)
    det = p @ e1
    tvec = x - a
    q = np.cross(tvec, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (p @ tvec) / det, (w @ q) / det, (q @ e2) / det


def inside(x, a, b, c, w) -> np.ndarray:
    b1, b2, t = ray_barycentrics(x, a, b, c, w)
    return (b1 >= 0.0) & (b2 >= 0.0) & (b1 + b2 <= 1.0) & (t > 0.0)


def inverse_condition(x, a, b, c, u: np.ndarray, step: float = 1e-7) -> np.ndarray:
    """(n,) factor by which ``invert`` may amplify a rounding error (~eps) at the samples u,
    the sum of two terms:

    - 1 / sigma_min of the Jacobian J of u -> wi (3 x 2): the error already in wi. The map is
      uniform, so sigma_min sigma_max = |det| = Omega, and sigma_max <= |J e0| + |J e1|;
    - 1 / |dC'/du0|: ``invert`` goes through the point C' on the arc AC (``sample(u0, 1)``),
      and an error eps in C' is an error eps / |dC'/du0| in u0. This is not part of the map's
      conditioning but of the construction: it matters where C' crowds (a triangle of nearly
      2 pi sr, where most u0 put C' near the antipode of B).

    Derivatives are central differences with step 1e-7 (rounding of the directions, eps / step
    ~ 2e-9, is far below the smallest of them, ~1e-7 for the tiny triangle); u must lie
    ``step`` inside [0, 1]^2."""
    cols = []
    for e in ((step, 0.0), (0.0, step)):
        plus, _ = spherical_triangle.sample_lanes(x, a, b, c, u + e)
        minus, _ = spherical_triangle.sample_lanes(x, a, b, c, u - e)
        cols.append(np.linalg.norm(plus - minus, axis=1) / (2.0 * step))
    on_arc = np.stack([u[:, 0], np.ones(len(u))], axis=1)
    plus, _ = spherical_triangle.sample_lanes(x, a, b, c, on_arc + (step, 0.0))
    minus, _ = spherical_triangle.sample_lanes(x, a, b, c, on_arc - (step, 0.0))
    arc = np.linalg.norm(plus - minus, axis=1) / (2.0 * step)
    return (cols[0] + cols[1]) / solid_angle(x, a, b, c) + 1.0 / arc


def ray_tolerance(x, a, b, c) -> float:
    """Barycentric tolerance of the ray test for a direction off by ~eps: the hit point moves
    by eps r / sin(elevation) = eps r^2 / d (d the distance from x to the plane, r to the
    farthest corner), over the triangle's smallest altitude; times 64 for the few roundings."""
    normal = np.cross(b - a, c - a)
    d = abs((a - x) @ normal) / np.linalg.norm(normal)
    r = max(np.linalg.norm(v - x) for v in (a, b, c))
    altitude = np.linalg.norm(normal) / max(np.linalg.norm(p - q) for p, q in ((a, b), (b, c), (c, a)))
    return 64.0 * EPS * r * r / (d * altitude)


# ---------------------------------------------------------------------------------------------
# Spherical triangle: distribution


def cap_cell_probabilities(x, a, b, c, axis, theta_max: float, shape) -> np.ndarray:
    """Exact probabilities ``(na, nb)`` of the (theta, phi) cells of ``chi2.spherical_domain(axis,
    theta_max, "theta")`` under the uniform density on the spherical triangle, axis inside it.

    The spherical triangle is where m . w >= 0 for the three inward normals m of the planes
    through x and an edge. Along the meridian at phi, w = cos(theta) n + sin(theta) e(phi), each
    m . w is a sinusoid that is > 0 at theta = 0 (the axis is inside) and first vanishes at
    theta_m = atan2(m . n, -m . e(phi)); the meridian leaves the triangle at the smallest of
    them, theta_b(phi). A cell [theta0, theta1] x [phi0, phi1] therefore holds the solid angle
    integral over phi of max(0, cos(theta0) - cos(min(theta1, theta_b(phi)))), a continuous
    function of phi: scipy's adaptive quad_vec integrates it (all rows of a column at once) to
    ~1e-12, with the vertices' phi as break points. Divided by the solid angle (from
    ``solid_angle``; the sum of the probabilities then checks it)."""
    s_ax, t_ax, n_ax = chi2._basis(axis)
    verts = unit([a - x, b - x, c - x])
    normals = []
    for i in range(3):
        p, q, r = verts[i], verts[(i + 1) % 3], verts[(i + 2) % 3]
        m = np.cross(p, q)
        normals.append(m if m @ r > 0.0 else -m)
    m = np.array(normals)
    mn, ms, mt = m @ n_ax, m @ s_ax, m @ t_ax
    assert np.all(mn > 0.0), "the cap's axis must lie inside the spherical triangle"
    na, nb = shape
    theta_edges = np.linspace(0.0, theta_max, na + 1)
    phi_edges = np.linspace(-np.pi, np.pi, nb + 1)
    cos_lo, theta_hi = np.cos(theta_edges[:-1]), theta_edges[1:]

    def column(phi):
        theta_b = np.min(np.arctan2(mn, -(ms * np.cos(phi) + mt * np.sin(phi))))
        return np.maximum(cos_lo - np.cos(np.minimum(theta_hi, theta_b)), 0.0)

    vertex_phi = np.arctan2(verts @ t_ax, verts @ s_ax)
    out = np.zeros(shape)
    for j in range(nb):
        breaks = [p for p in vertex_phi if phi_edges[j] < p < phi_edges[j + 1]]
        out[:, j], _ = integrate.quad_vec(column, phi_edges[j], phi_edges[j + 1], epsabs=1e-14,
                                          epsrel=1e-12, points=breaks or None)
    return out / solid_angle(x, a, b, c)


@pytest.mark.parametrize("name", list(CHI2_CASES))
def test_spherical_triangle_chi2(name):
    """Directions from ``sample`` vs. the density 1/Omega inside the triangle's projection and 0
    outside, on (theta, phi) cells of a cap around the normalized sum of the vertex directions
    (a point of the spherical triangle) whose radius is 1.05 x the largest vertex angle (a cap
    narrower than a hemisphere is convex, so it holds the triangle); directions outside it go
    to an extra cell that expects 0. Pearson's X^2 after pooling cells expecting < 5
    (``chi2.pooled_chi2``), level ALPHA (Sidak over the file's N_STAT statistical tests).

    The expected counts are exact (``cap_cell_probabilities``), not the adaptive cubature of
    ``chi2.goodness_of_fit``: that integrates the discontinuous indicator with Gauss nodes that
    sit on the same meridians in every row, so an edge of a sliver or grazing triangle that
    runs along a meridian (through the cap's axis) is missed coherently; measured here, the
    grazing case's cubature put 1.020 +- 0.002 of the mass on the cap and a correct sampler
    failed at p ~ 0. The exact probabilities must sum to 1 (atol 1e-9): that checks
    ``solid_angle`` against the area of the region bounded by the three edge planes. The region
    itself is checked against a ray-triangle test (Moller-Trumbore, ``inside``) on 20 000
    directions of the cap."""
    x, a, b, c = config(name)
    omega = solid_angle(x, a, b, c)
    u = rng(1, list(CHI2_CASES).index(name)).random((N_SAMPLES, 2))
    w, pdf = spherical_triangle.sample_lanes(x, a, b, c, u)
    assert np.all(pdf == 1.0 / omega)
    dirs = unit([a - x, b - x, c - x])
    axis = unit(dirs.sum(axis=0))
    theta_max = 1.05 * float(np.max(np.arccos(np.clip(dirs @ axis, -1.0, 1.0))))
    assert theta_max < np.pi / 2
    domain = chi2.spherical_domain(axis, theta_max, polar="theta")

    # The region of the exact probabilities is the ray test's (away from its boundary).
    gen = rng(9, list(CHI2_CASES).index(name))
    params = np.stack([theta_max * np.sqrt(gen.random(20000)), gen.uniform(-np.pi, np.pi, 20000)], axis=1)
    probe = domain.forward(params)
    s_ax, t_ax, n_ax = chi2._basis(axis)
    normals = [np.cross(dirs[i], dirs[(i + 1) % 3]) * np.sign(np.cross(dirs[i], dirs[(i + 1) % 3])
                                                               @ dirs[(i + 2) % 3]) for i in range(3)]
    side = np.min(np.stack([probe @ unit(m) for m in normals]), axis=0)
    clear = np.abs(side) > 1e-9
    np.testing.assert_array_equal(inside(x, a, b, c, probe)[clear], side[clear] > 0.0)

    prob = cap_cell_probabilities(x, a, b, c, axis, theta_max, GRID)
    assert abs(prob.sum() - 1.0) < 1e-9, prob.sum() - 1.0
    observed, rest = chi2.histogram(w, domain, GRID)
    stat, dof, _ = chi2.pooled_chi2(np.append(observed, rest), np.append(N_SAMPLES * prob, 0.0))
    p = float(stats.chi2.sf(stat, dof))
    print(f"spherical triangle {name}: Omega={omega:.4g} sr, X^2={stat:.1f} dof={dof} p={p:.3g} "
          f"vs alpha={ALPHA:.3g}; sum of cell probabilities - 1 = {prob.sum() - 1.0:.1e}; "
          f"outside the cap: {rest}")
    assert p >= ALPHA, (stat, dof, p)


def test_spherical_triangle_samples_are_unit_and_inside():
    """On every case (extremes included), on random u and on the square's corners and edges:
    directions are finite unit vectors (atol 4 eps: a normalized sum), their rays hit the
    triangle (barycentrics >= -``ray_tolerance``: ~2e-12 for the moderate cases, ~6e-7 for the
    view 1e-7 above the plane, where the ray test itself amplifies an ulp of direction by
    1 / elevation), and the pdf is exactly 1/Omega (both are 1 / (2 atan2(...)) of the same
    numbers)."""
    edge = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [0.5, 0.0], [0.5, 1.0],
                     [0.0, 0.5], [1.0, 0.5], [1e-300, 1e-300], [1 - EPS / 2, 1 - EPS / 2]])
    u = np.concatenate([rng(2).random((20000, 2)), edge])
    for name in [*CHI2_CASES, *EXTREME_CASES]:
        x, a, b, c = config(name)
        w, pdf = spherical_triangle.sample_lanes(x, a, b, c, u)
        assert np.all(np.isfinite(w)), name
        np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, rtol=0, atol=4 * EPS, err_msg=name)
        b1, b2, t = ray_barycentrics(x, a, b, c, w)
        worst = min(b1.min(), b2.min(), (1.0 - b1 - b2).min())
        assert worst >= -ray_tolerance(x, a, b, c), (name, worst)
        assert np.all(t > 0.0), name
        assert np.all(pdf == 1.0 / solid_angle(x, a, b, c)), name


def test_spherical_triangle_corners():
    """The square's corners go to the vertices: u1 = 0 to B for any u0, (0, 1) to A, (1, 1) to
    C, and invert sends A to (0, 1) and C to (1, 1) (A is where the branch of the arc's angle
    must not flip to pi). Angles atol 1e-12 rad and u atol 1e-9: the cases are moderate, the
    vertex directions are rounded to ~1e-16 and ``invert`` amplifies that by at most ~1e3
    here (``inverse_condition``)."""
    for name in CHI2_CASES:
        x, a, b, c = config(name)
        ua, ub, uc = unit(a - x), unit(b - x), unit(c - x)
        u = np.array([[0.0, 0.0], [0.3, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
        w, _ = spherical_triangle.sample_lanes(x, a, b, c, u)
        expected = np.stack([ub, ub, ub, ua, uc])
        angle = 2.0 * np.arctan2(np.linalg.norm(w - expected, axis=1), np.linalg.norm(w + expected, axis=1))
        assert np.all(angle < 1e-12), (name, angle)
        back = spherical_triangle.invert_lanes(x, a, b, c, np.stack([ua, uc]))
        np.testing.assert_allclose(back, [[0.0, 1.0], [1.0, 1.0]], rtol=0, atol=1e-9, err_msg=name)


def test_spherical_triangle_degenerate():
    """Where the solid angle is 0 or undefined, ``sample`` returns ((0, 0, 1), 0) and
    ``solid_angle`` 0: x in the triangle's plane (inside, outside, on an edge, at a corner),
    collinear or coincident corners, non-finite input."""
    a, b, c = (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    cases = [((0.2, 0.2, 0.0), a, b, c), ((3.0, -1.0, 0.0), a, b, c), ((0.5, 0.0, 0.0), a, b, c),
             (a, a, b, c), ((0.1, 0.2, 1.0), a, b, (2.0, 0.0, 0.0)), ((0.1, 0.2, 1.0), a, a, c),
             ((0.1, 0.2, np.nan), a, b, c), ((0.1, 0.2, 1.0), a, b, (np.inf, 0.0, 0.0))]
    for x, p, q, r in cases:
        assert spherical_triangle.solid_angle(x, p, q, r) == 0.0, (x, p, q, r)
        assert spherical_triangle.sample(x, p, q, r, 0.3, 0.6) == ((0.0, 0.0, 1.0), 0.0), (x, p, q, r)


# ---------------------------------------------------------------------------------------------
# Solid angle


def test_solid_angle_closed_forms():
    """Closed forms, rtol 8 eps unless said (a handful of roundings of well-conditioned terms):

    - the octant triangle (1,0,0), (0,1,0), (0,0,1) from the origin: pi/2, in all 8 octants
      and all 6 vertex orders (orientation does not matter);
    - a face of the regular tetrahedron from its centre: pi (4 pi / 4 faces), where Van
      Oosterom's denominator is 0;
    - a rectangle of sides p, q at height h above one corner, split in two triangles:
      atan(p q / (h sqrt(h^2 + p^2 + q^2))), tall, flat, thin and, at h = 1e6, 1e-12 sr, which
      only keeps its digits if no 1 - cos of a small angle is formed;
    - the four faces of a tetrahedron seen from any interior point sum to 4 pi, down to
      points 1e-9 from a face (whose solid angle is then ~2 pi) and 1e-6 from a corner; atol
      64 eps x 4 pi, divided by the distance to the nearest corner when that is < 1 (the
      corner's direction is only known to eps |x| / distance).
    """
    for sx in (1.0, -1.0):
        for sy in (1.0, -1.0):
            for sz in (1.0, -1.0):
                v = [(sx, 0.0, 0.0), (0.0, sy, 0.0), (0.0, 0.0, sz)]
                for order in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
                    got = spherical_triangle.solid_angle((0.0, 0.0, 0.0), *(v[i] for i in order))
                    assert abs(got - np.pi / 2) <= 8 * EPS * np.pi / 2, (sx, sy, sz, order, got)
    tet = [(1.0, 1.0, 1.0), (1.0, -1.0, -1.0), (-1.0, 1.0, -1.0), (-1.0, -1.0, 1.0)]
    for i in range(4):
        face = [tet[j] for j in range(4) if j != i]
        got = spherical_triangle.solid_angle((0.0, 0.0, 0.0), *face)
        assert abs(got - np.pi) <= 8 * EPS * np.pi, got
    for p, q, h in ((1.0, 1.0, 1.0), (2.0, 0.5, 1e-3), (1.0, 1.0, 1e6), (1e-6, 1.0, 1.0), (3.0, 7.0, 0.25)):
        ref = np.arctan(p * q / (h * np.sqrt(h * h + p * p + q * q)))
        o, c0, c1, c2, c3 = (0.0, 0.0, 0.0), (0.0, 0.0, h), (p, 0.0, h), (p, q, h), (0.0, q, h)
        got = spherical_triangle.solid_angle(o, c0, c1, c2) + spherical_triangle.solid_angle(o, c0, c2, c3)
        assert abs(got - ref) <= 16 * EPS * ref, (p, q, h, got, ref)
    corners = [np.array(v) for v in [(0.0, 0.0, 0.0), (1.3, 0.1, -0.2), (0.2, 1.1, 0.3), (0.4, 0.3, 0.9)]]
    faces = [[corners[j] for j in range(4) if j != i] for i in range(4)]
    centroid = sum(corners) / 4.0
    normal = unit(np.cross(corners[2] - corners[1], corners[3] - corners[1]))
    gen = rng(3)
    points = [centroid, corners[1] + (centroid - corners[1]) * 1e-6]
    points += [corners[1] + 0.3 * (corners[2] - corners[1]) + 0.3 * (corners[3] - corners[1])
               + d * normal * np.sign(normal @ (centroid - corners[1])) for d in (1e-3, 1e-9)]
    points += [sum(wt * v for wt, v in zip(gen.dirichlet(np.ones(4)), corners, strict=True))
               for _ in range(20)]
    for x in points:
        total = sum(solid_angle(x, *f) for f in faces)
        # Near a corner the directions to it are known only to eps |x| / distance.
        near = min(np.linalg.norm(x - v) for v in corners)
        assert abs(total - 4 * np.pi) <= 64 * EPS * 4 * np.pi / min(near, 1.0), (x, total)


@pytest.mark.parametrize("name", [*CHI2_CASES, "tiny_far", "grazing_1e-7"])
def test_solid_angle_quadrature(name):
    """``solid_angle`` against the quadrature Omega = integral over the triangle of d / r^3 dA
    (d the distance from x to the plane, r from x to the point; scipy's adaptive dblquad over
    barycentrics, epsrel 1e-11: the integrand is smooth, since x is never close to the triangle
    relative to its height above the plane). rtol 1e-9 allows for the quadrature's error and the
    conditioning of the configurations (the rotated corners carry ~1e-16 relative errors,
    amplified by 1 / elevation ~ 1e7 in the grazing view)."""
    x, a, b, c = config(name)
    e1, e2 = b - a, c - a
    cross = np.cross(e1, e2)
    dist = abs((a - x) @ cross) / np.linalg.norm(cross)
    jac = np.linalg.norm(cross)

    def integrand(t, s):
        r = a + s * e1 + t * e2 - x
        return dist / np.sqrt(r @ r) ** 3 * jac

    ref, err = integrate.dblquad(integrand, 0.0, 1.0, 0.0, lambda s: 1.0 - s, epsabs=0.0, epsrel=1e-11)
    got = solid_angle(x, a, b, c)
    assert spherical_triangle.solid_angle_lanes(x[None, :], a, b, c)[0] == got  # same code
    print(f"{name}: Omega={got:.17g} quadrature={ref:.17g} (+-{err:.1e}) rel diff={got / ref - 1:.2e}")
    assert abs(got - ref) <= 1e-9 * ref, (got, ref, err)


# ---------------------------------------------------------------------------------------------
# Spherical triangle: inverse


@pytest.mark.parametrize("name", [*CHI2_CASES, *EXTREME_CASES])
def test_spherical_triangle_round_trip(name):
    """invert(sample(u)) == u on 200 000 random u, u within 1e-6 of the square's boundary left
    out (there the finite differences of ``inverse_condition`` would leave the square, and at
    u1 -> 0 every u0 meets at B, so u0 is not determined at all). The direction handed to
    ``invert`` carries ~eps of rounding, which the inverse amplifies by ``inverse_condition``
    (~1/sqrt(u1) near B, 1 / thickness for thin triangles, 1 / crowding of C' for the
    near-hemisphere one: up to ~1e10 for the 1e-7 rad triangle near u1 = 1e-6); the tolerance
    is 16 eps (1 + that factor) per coordinate. The worst error and the worst ratio of the
    error to eps x factor are printed."""
    x, a, b, c = config(name)
    u = rng(4, list({**CHI2_CASES, **EXTREME_CASES}).index(name)).random((200_000, 2))
    u = u[np.all((u > 1e-6) & (u < 1.0 - 1e-6), axis=1)]
    w, _ = spherical_triangle.sample_lanes(x, a, b, c, u)
    back = spherical_triangle.invert_lanes(x, a, b, c, w)
    err = np.abs(back - u)
    cond = inverse_condition(x, a, b, c, u)
    ratio = err / (EPS * cond[:, None])
    print(f"{name}: worst |du0|={err[:, 0].max():.2e} |du1|={err[:, 1].max():.2e}; worst "
          f"error / (eps cond)={ratio.max():.3g}; cond from {cond.min():.3g} to {cond.max():.3g}")
    assert np.all(err <= 16 * EPS * (1.0 + cond[:, None])), (name, err.max(), ratio.max())


# ---------------------------------------------------------------------------------------------
# Bilinear warp


def bilinear_cell_probabilities(w, shape) -> np.ndarray:
    """Exact probability of each cell of a uniform grid on [0, 1]^2: a bilinear function's mean
    over a rectangle is its value at the rectangle's centre."""
    na, nb = shape
    c0 = (np.arange(na) + 0.5) / na
    c1 = (np.arange(nb) + 0.5) / nb
    s0, s1 = np.meshgrid(c0, c1, indexing="ij")
    return bilinear.pdf_lanes(np.stack([s0.ravel(), s1.ravel()], axis=1), np.asarray(w, float)) / (na * nb)


@pytest.mark.parametrize("name", list(BILINEAR_WEIGHTS))
def test_bilinear_chi2(name):
    """Points from ``bilinear.sample`` vs. the bilinear density on a 32 x 32 grid of [0, 1]^2
    (exact expected counts: the density is bilinear, so a cell's probability is the density at
    its centre times its area; their sum is checked to be 1), Pearson's X^2 after pooling cells
    expecting < 5 (``chi2.pooled_chi2``), points outside the square in an extra cell expecting
    0; level ALPHA."""
    w = np.asarray(BILINEAR_WEIGHTS[name])
    s = bilinear.sample_lanes(rng(5, list(BILINEAR_WEIGHTS).index(name)).random((N_SAMPLES, 2)), w)
    prob = bilinear_cell_probabilities(w, BILINEAR_GRID)
    assert abs(prob.sum() - 1.0) < 1e-12
    ok = np.all((s >= 0.0) & (s <= 1.0), axis=1)
    na, nb = BILINEAR_GRID
    ia = np.minimum((s[ok, 0] * na).astype(np.int64), na - 1)
    ib = np.minimum((s[ok, 1] * nb).astype(np.int64), nb - 1)
    observed = np.bincount(ia * nb + ib, minlength=na * nb)
    stat, dof, _ = chi2.pooled_chi2(np.append(observed, (~ok).sum()), np.append(N_SAMPLES * prob, 0.0))
    p = float(stats.chi2.sf(stat, dof))
    print(f"bilinear {name}: X^2={stat:.1f} dof={dof} p={p:.3g} vs alpha={ALPHA:.3g}")
    assert np.all(ok)
    assert p >= ALPHA, (stat, dof, p)


@pytest.mark.parametrize("name", list(BILINEAR_WEIGHTS))
def test_bilinear_pdf_inverse_and_round_trip(name):
    """Deterministic identities of the bilinear warp:

    - the pdf integrates to 1 (a 2 x 2 Gauss-Legendre rule is exact on a bilinear function;
      atol 1e-14) and is 0 outside the square;
    - ``invert`` is the distribution function, so the determinant of its Jacobian (triangular:
      u1 depends on s1 only) is the pdf: central differences with step 1e-5 (truncation ~1e-10
      on these cubics, round-off ~1e-11), rtol 1e-7;
    - invert(sample(u)) == u and sample(invert(s)) == s on 100 000 random points: the linear
      inversions amplify rounding at most by the ratio of the largest density to the smallest
      (<= 250 for these weights), so atol 1e-12."""
    w = np.asarray(BILINEAR_WEIGHTS[name])
    g, gw = np.polynomial.legendre.leggauss(2)
    nodes = 0.5 * (g + 1.0)
    s0, s1 = np.meshgrid(nodes, nodes, indexing="ij")
    weights = np.outer(gw, gw).ravel() * 0.25
    total = weights @ bilinear.pdf_lanes(np.stack([s0.ravel(), s1.ravel()], axis=1), w)
    assert abs(total - 1.0) < 1e-14
    outside = np.array([[-1e-12, 0.5], [0.5, 1.0 + 1e-12], [2.0, 2.0], [0.5, -3.0]])
    assert np.all(bilinear.pdf_lanes(outside, w) == 0.0)

    gen = rng(6, list(BILINEAR_WEIGHTS).index(name))
    s = 0.01 + 0.98 * gen.random((2000, 2))
    step = 1e-5
    d0 = (bilinear.invert_lanes(s + [step, 0.0], w)[:, 0] - bilinear.invert_lanes(s - [step, 0.0], w)[:, 0])
    d1 = (bilinear.invert_lanes(s + [0.0, step], w)[:, 1] - bilinear.invert_lanes(s - [0.0, step], w)[:, 1])
    np.testing.assert_allclose(d0 * d1 / (2 * step) ** 2, bilinear.pdf_lanes(s, w), rtol=1e-7)

    u = gen.random((100_000, 2))
    s = bilinear.sample_lanes(u, w)
    err_u = np.abs(bilinear.invert_lanes(s, w) - u).max()
    t = gen.random((100_000, 2))
    err_s = np.abs(bilinear.sample_lanes(bilinear.invert_lanes(t, w), w) - t).max()
    print(f"bilinear {name}: worst |invert(sample(u)) - u| = {err_u:.2e}, "
          f"|sample(invert(s)) - s| = {err_s:.2e}")
    assert err_u <= 1e-12 and err_s <= 1e-12


def test_bilinear_equal_weights_is_identity():
    """Equal weights (any common value, tiny or huge): ``sample`` and ``invert`` are exactly
    the identity and the pdf is exactly 1 (the code returns u itself when the two endpoint
    weights of a linear inversion are equal, and a + t (b - a) keeps equal weights equal)."""
    u = np.concatenate([rng(7).random((10000, 2)), [[0.0, 0.0], [1.0, 1.0], [0.0, 1.0]]])
    for v in (1.0, 0.37, 1e-200, 1e200):
        w = np.full(4, v)
        np.testing.assert_array_equal(bilinear.sample_lanes(u, w), u)
        np.testing.assert_array_equal(bilinear.invert_lanes(u, w), u)
        assert np.all(bilinear.pdf_lanes(u, w) == 1.0)


def _linear_reference(u: float, a: float, b: float) -> float:
    """The root of F(x) = u by the textbook quadratic formula in 60-digit decimals, where its
    cancellation as b -> a costs nothing."""
    with localcontext() as ctx:
        ctx.prec = 60
        du, da, db = Decimal(u), Decimal(a), Decimal(b)
        return float(((da * da + du * (db * db - da * da)).sqrt() - da) / (db - da))


def test_bilinear_linear_inversion_near_equal_weights():
    """The linear inversion for endpoint weights b = a (1 + d), d from 1e-3 down to 1e-15,
    against the textbook formula evaluated in 60-digit decimals: rtol 4 eps (the form used has
    only positive terms, so its error is a few roundings however small d is). For comparison,
    the same textbook formula in float64 loses ~1/d of its digits; its error is printed."""
    gen = rng(8)
    worst = worst_naive = 0.0
    for d in (1e-3, 1e-6, 1e-9, 1e-12, 1e-15, -1e-9):
        for a in (1.0, 0.3, 7.0):
            b = a * (1.0 + d)
            for u in gen.random(50):
                ref = _linear_reference(float(u), a, b)
                got = bilinear.linear_sample(float(u), a, b)
                worst = max(worst, abs(got - ref) / ref)
                naive = (np.sqrt(a * a + u * (b * b - a * a)) - a) / (b - a)
                worst_naive = max(worst_naive, abs(naive - ref) / ref)
                assert abs(got - ref) <= 4 * EPS * ref, (d, a, u, got, ref)
                assert abs(bilinear.linear_invert(got, a, b) - u) <= 8 * EPS
    print(f"linear inversion near equal weights: worst rel error {worst:.2e} "
          f"(textbook formula in float64: {worst_naive:.2e})")
