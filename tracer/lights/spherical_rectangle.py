"""Uniform sampling of the solid angle that a rectangle subtends, and the inverse map.

Reference: C. Ureña, M. Fajardo and A. King, "An Area-Preserving Parametrization for
Spherical Rectangles", Computer Graphics Forum 32(4) (Proc. EGSR 2013), 59-66. The map is
theirs: the spherical rectangle is cut by planes through the shading point that contain the
direction of the second edge; u0 chooses the cut by the solid angle on its near side, u1 the
point on the cut, uniformly in the sine of its elevation within the cut. The formulas are
derived again below in forms that avoid the paper's cancellations (the solid angle as a sum
of four interior angles minus 2 pi, from ``acos`` of dot products of normals, which keeps no
correct digit for a light of 1e-14 sr).

Geometry. The rectangle is ``corner + s edge_u + t edge_v``, s, t in [0, 1], ``edge_u``
perpendicular to ``edge_v``; vectors are tuples of 3 floats in world space; ``x`` is the
shading point. Local frame: x at the origin, axes along edge_u and edge_v (lengths W, H) and
their normal; the rectangle is [x0, x1] x [y0, y1] at height h = |(corner - x) . normal|, so
it is sampled as seen from x on whichever side of its plane x lies. Each axis is reversed
when x's projection is nearer the far edge, so that x0, y0 (measured from x) belong to the
corner nearest that projection, and x1 = x0 + W, y1 = y0 + H are the far edges: an edge
close to x is then never a difference of two large numbers. Lengths are divided by
|corner - x| + W + H (solid angles are scale-free), so nothing overflows.

Solid angle (:func:`solid_angle`, steradians). Van Oosterom and Strackee's formula for a
triangle seen from the origin (IEEE Trans. Biomed. Eng. 30(2), 1983), tan(Omega / 2) =
[a b c] / (|a||b||c| + (a.b)|c| + (a.c)|b| + (b.c)|a|), on a split of the rectangle chosen by
where the foot of the perpendicular from x falls. Outside the rectangle: the two triangles of
the diagonal from (x0, y0) to (x1, y1), whose triple products both equal h W H exactly; the
denominator is a sum of positive terms for a small triangle, so a tiny distant light keeps
full relative precision. Inside: the four triangles (foot, corner, next corner), all of the
same sign; the common factor h cancels, leaving tan = (p x q)_z / (|p||q| + p.q + h(|p| +
|q|)), with |p||q| + p.q formed as |p x q|^2 / (|p||q| - p.q) when p.q < 0. (A diagonal split
would fail here: when the foot lies near the diagonal and h is small, each triangle subtends
nearly pi, its denominator cancels, and the error grows like eps / h.) atan2 keeps triangles
wider than pi. Measured: within 4e-16 relative of closed forms from 1e-14 sr to 2 pi - 6e-12.

Sampling (:func:`sample`). Let A(X) be the solid angle of the part [x0, X] x [y0, y1]. Along
the cut at X, the solid angle per unit y is h / (d^2 + y^2)^(3/2), d^2 = X^2 + h^2, whose
primitive is (h / d^2) hv(y), hv(y) = y / sqrt(d^2 + y^2), so dA/dX = h / d^2 (hv(y1) -
hv(y0)). With sin(phi) = X / d and b_j = y_j / sqrt(y_j^2 + h^2) this integrates to
A = G(sin phi) - G(sin phi0), G(s) = asin(b1 s) - asin(b0 s) (the paper expresses the same
partial area through the interior angles of the part), and G(s) = T has the closed-form root
s = sin T / sqrt(b0^2 + b1^2 - 2 b0 b1 cos T), X = h s / sqrt(1 - s^2) (the paper's x_u).
With T = G(s0) + u0 Omega, an O(1) angle plus a small one, X loses ~eps |G(s0)| / Omega of
the edge for a small light, and s rounds to +-1 once |X| >> h. So the closed form is only
the first guess of Newton's method on A(X) = u0 Omega, with A from the triangle formula:
one step when the guess is good (a step below 1e-8 d is final), bisection of the bracket
[x0, x1] whenever a step leaves it (near the foot of x, A is a sigmoid of width h, on which
plain Newton diverges); at most MAX_ITERATIONS steps. Measured: one step on average, unless
h is below ~1e-6 of the rectangle's size (3 to 21 steps on average for h = 1e-6 to 1e-9).

Then hv(Y) = hv(y0) + u1 (hv(y1) - hv(y0)) is inverted: Y = d hv / sqrt(1 - hv^2) (the
paper's y_v), computed without cancellation when the cut is far along y: hv(a) - hv(b) as
d^2 (a - b)(a + b) / (ra rb (a rb + b ra)), ra = sqrt(d^2 + a^2), when a b > 0; 1 -+ hv as
the convex combinations (1 - u1)(1 -+ hv(y0)) + u1 (1 -+ hv(y1)) of endpoint values formed
as d^2 / (r (r +- y)); the offset Y - y0 = r0 sin(psi - psi0) / cos(psi) from the elevation
angles psi (sin psi = hv).

Inverse (:func:`invert`). The map is area preserving, so u0 = A(X) / Omega (the solid angle
on the near side of the point's cut) and u1 = (hv(Y) - hv(y0)) / (hv(y1) - hv(y0)) (its
place along the cut), both clamped to [0, 1]. invert(sample(u)) returns u to within the
conditioning of the rounded point (tests/test_spherical_rectangle.py).

Measures and degenerate input: :func:`sample` returns a point on the rectangle and the
density 1 / Omega of the direction from x to it, in solid angle. x in the plane of the
rectangle, an edge of length 0 or NaN input give Omega = 0, ``sample`` -> ``(corner, 0.0)``
and ``invert`` -> ``(0.0, 0.0)``. For x very near the plane, Omega carries the relative
error ~eps |corner - x| / h of forming h in float64 (exact for inputs moved by an ulp).

The ``*_lanes`` functions run the same compiled code over arrays, for tests and tools.
"""

from __future__ import annotations

import math

import numpy as np

from ..frame import add_scaled, dot, sub
from ..jit import jit

MAX_ITERATIONS = 64  # bound on the safeguarded Newton steps that solve for the cut
# The closed form alone is accurate to ~eps (|G(s0)| / Omega + (X / h)^2) of the edge
# (measured: within 3.5e-9 of the refined point on a grazing view, 1e-14 elsewhere) when
# Omega >= 1e-4 sr and h >= 1e-3 of the distance to the far edge. There
# ``sample_given(..., refine=False)`` skips the Newton steps (each a solid angle of two to
# four triangles): the renderer's light technique (``tracer.lights.rectangle``, which samples
# smaller rectangles by area anyway) takes that path, 500 -> 170 ns a sample on cornell's
# light; ``sample`` always refines.
CLOSED_FORM_MIN_SOLID_ANGLE = 1e-4
CLOSED_FORM_MIN_HEIGHT = 1e-3


# ---------------------------------------------------------------------------------------------
# Local geometry


@jit
def _local(x, corner, edge_u, edge_v):
    """``(x0, y0, h, w, hgt, flip_u, flip_v, origin)``: the rectangle is
    [x0, x0 + w] x [y0, y0 + hgt] at height h >= 0 in the frame with x at the origin, whose
    axes are edge_u and edge_v, each reversed (``flip_u``, ``flip_v``) when x's projection is
    nearer the far edge, so that ``origin``, the corner at (x0, y0), is the corner nearest to
    x's projection: the edges close to x are then measured from x directly, not as a
    difference x0 + w that would lose their distance to x. Lengths are divided by
    |origin - x| + |edge_u| + |edge_v|."""
    w = math.sqrt(dot(edge_u, edge_u))
    hgt = math.sqrt(dot(edge_v, edge_v))
    d = sub(corner, x)
    flip_u = dot(d, edge_u) / w + 0.5 * w < 0.0
    flip_v = dot(d, edge_v) / hgt + 0.5 * hgt < 0.0
    origin = (float(corner[0]), float(corner[1]), float(corner[2]))
    if flip_u:
        origin = add_scaled(origin, 1.0, edge_u)
    if flip_v:
        origin = add_scaled(origin, 1.0, edge_v)
    d = sub(origin, x)
    x0 = dot(d, edge_u) / w
    y0 = dot(d, edge_v) / hgt
    if flip_u:
        x0 = -x0
    if flip_v:
        y0 = -y0
    nx = edge_u[1] * edge_v[2] - edge_u[2] * edge_v[1]
    ny = edge_u[2] * edge_v[0] - edge_u[0] * edge_v[2]
    nz = edge_u[0] * edge_v[1] - edge_u[1] * edge_v[0]
    h = abs(d[0] * nx + d[1] * ny + d[2] * nz) / math.sqrt(nx * nx + ny * ny + nz * nz)
    inv = 1.0 / (math.sqrt(dot(d, d)) + w + hgt)
    return x0 * inv, y0 * inv, h * inv, w * inv, hgt * inv, flip_u, flip_v, origin


@jit
def _foot_triangle(px: float, py: float, qx: float, qy: float, h: float, lp: float, lq: float) -> float:
    """Half the signed solid angle of the triangle (f, p, q), f = (0, 0, h) the foot of the
    perpendicular from the origin, p = (px, py, h), q = (qx, qy, h), |p| = lp, |q| = lq:
    Van Oosterom and Strackee's formula with the common factor h taken out. Where p and q are
    more than 90 degrees apart, |p||q| + p.q is formed as |p x q|^2 / (|p||q| - p.q)."""
    cross = px * qy - py * qx
    pq = px * qx + py * qy + h * h
    if pq < 0.0:
        cx = h * (py - qy)
        cy = h * (qx - px)
        den = (cx * cx + cy * cy + cross * cross) / (lp * lq - pq) + h * (lp + lq)
    else:
        den = lp * lq + pq + h * (lp + lq)
    return math.atan2(cross, den)


@jit
def _rect_solid_angle(x0: float, w: float, y0: float, hgt: float, h: float) -> float:
    """Solid angle of [x0, x0 + w] x [y0, y0 + hgt] at height h > 0 seen from the origin, by
    Van Oosterom and Strackee's formula (module docstring): four triangles from the foot of
    the perpendicular when it falls inside, else two triangles split along the diagonal ac."""
    x1 = x0 + w
    y1 = y0 + hgt
    h2 = h * h
    la = math.sqrt(x0 * x0 + y0 * y0 + h2)
    lb = math.sqrt(x1 * x1 + y0 * y0 + h2)
    lc = math.sqrt(x1 * x1 + y1 * y1 + h2)
    le = math.sqrt(x0 * x0 + y1 * y1 + h2)
    if x0 <= 0.0 <= x1 and y0 <= 0.0 <= y1:
        return 2.0 * (_foot_triangle(x0, y0, x1, y0, h, la, lb) + _foot_triangle(x1, y0, x1, y1, h, lb, lc)
                      + _foot_triangle(x1, y1, x0, y1, h, lc, le) + _foot_triangle(x0, y1, x0, y0, h, le, la))
    triple = h * w * hgt  # [a b c] = [a c e] = h w hgt
    ab = x0 * x1 + y0 * y0 + h2
    ac = x0 * x1 + y0 * y1 + h2
    bc = x1 * x1 + y0 * y1 + h2
    ae = x0 * x0 + y0 * y1 + h2
    ce = x0 * x1 + y1 * y1 + h2
    den_abc = la * lb * lc + ab * lc + ac * lb + bc * la
    den_ace = la * lc * le + ac * le + ae * lc + ce * la
    return 2.0 * (math.atan2(triple, den_abc) + math.atan2(triple, den_ace))


@jit
def _hv_diff(a: float, b: float, a_minus_b: float, d2: float) -> float:
    """hv(a) - hv(b), hv(y) = y / sqrt(d2 + y^2), without cancellation when a and b are close:
    ``a_minus_b`` is a - b as known exactly by the caller."""
    ra = math.sqrt(d2 + a * a)
    rb = math.sqrt(d2 + b * b)
    if a * b > 0.0:
        return d2 * a_minus_b * (a + b) / (ra * rb * (a * rb + b * ra))
    return a / ra - b / rb


@jit
def _one_minus_hv(y: float, r: float, d2: float) -> float:
    """1 - y / r for r = sqrt(d2 + y^2), accurate when y / r is close to 1."""
    return d2 / (r * (r + y)) if y > 0.0 else (r - y) / r


@jit
def _asin(a: float) -> float:
    """asin of ``a`` clamped to [-1, 1]."""
    return math.asin(min(max(a, -1.0), 1.0))


@jit
def _clamp(value: float, hi: float) -> float:
    """``value`` in [0, hi]; NaN gives 0."""
    if not value >= 0.0:
        return 0.0
    return value if value <= hi else hi


# ---------------------------------------------------------------------------------------------
# The two steps of the map and their inverses (local, scaled coordinates)


@jit
def _cut(x0: float, w: float, y0: float, hgt: float, h: float, omega: float, u0: float,
         refine: bool) -> float:
    """xi = X - x0 in [0, w] of the cut whose near side subtends u0 omega; without ``refine``
    the closed form alone where it is accurate (CLOSED_FORM_MIN_*)."""
    if not u0 > 0.0:
        return 0.0
    if u0 >= 1.0:
        return w
    x1 = x0 + w
    y1 = y0 + hgt
    h2 = h * h
    s0 = x0 / math.sqrt(x0 * x0 + h2)
    s1 = x1 / math.sqrt(x1 * x1 + h2)
    b0 = y0 / math.sqrt(y0 * y0 + h2)
    b1 = y1 / math.sqrt(y1 * y1 + h2)
    # Closed form (first guess): G(s) = T, with b0^2 + b1^2 - 2 b0 b1 cos T written as
    # (b1 - b0)^2 + 4 b0 b1 sin^2(T / 2) when b0 b1 > 0, a sum of positive terms. Rounding can
    # put |b s| or |s| a hair above 1: arguments of asin and sqrt are clamped.
    target = _asin(b1 * s0) - _asin(b0 * s0) + u0 * omega
    if b0 * b1 > 0.0:
        half = math.sin(0.5 * target)
        db = _hv_diff(y1, y0, hgt, h2)  # b1 - b0
        den = db * db + 4.0 * b0 * b1 * half * half
    else:
        den = b0 * b0 + b1 * b1 - 2.0 * b0 * b1 * math.cos(target)
    s = math.sin(target) / math.sqrt(max(den, 1e-300))
    if not s >= s0:  # also NaN
        s = s0
    if s > s1:
        s = s1
    xi = _clamp(h * s / math.sqrt(max((1.0 - s) * (1.0 + s), 0.0)) - x0, w)
    if not refine and omega >= CLOSED_FORM_MIN_SOLID_ANGLE and h >= CLOSED_FORM_MIN_HEIGHT * (abs(x0) + w):
        return xi
    # Safeguarded Newton on A(x0 + xi) = u0 omega. A increases strictly from 0 to omega on
    # [0, w] with A' = h / d^2 (hv(y1) - hv(y0)), d^2 = X^2 + h^2, and varies on the length
    # scale d: a step below 1e-8 d leaves an error ~ step^2 / d below 1e-16 d, so it is the
    # last. A step leaving the bracket [lo, hi] (A's sigmoid near the foot of x when h is
    # tiny) is replaced by bisection.
    goal = u0 * omega
    lo = 0.0
    hi = w
    for _ in range(MAX_ITERATIONS):
        big_x = x0 + xi
        d2 = big_x * big_x + h2
        residual = _rect_solid_angle(x0, xi, y0, hgt, h) - goal
        if residual > 0.0:
            hi = xi
        elif residual < 0.0:
            lo = xi
        else:
            break
        step = residual / (h / d2 * _hv_diff(y1, y0, hgt, d2))
        nxt = xi - step
        if abs(step) <= 1e-8 * math.sqrt(d2):
            xi = min(max(nxt, lo), hi)
            break
        if not (nxt > lo and nxt < hi):
            nxt = 0.5 * (lo + hi)
        if nxt == xi:
            break
        xi = nxt
    return xi


@jit
def _height(big_x: float, y0: float, hgt: float, h: float, u1: float) -> float:
    """eta = Y - y0 in [0, hgt] on the cut at big_x with hv(Y) = hv(y0) + u1 (hv(y1) - hv(y0))."""
    y1 = y0 + hgt
    d2 = big_x * big_x + h * h
    r0 = math.sqrt(d2 + y0 * y0)
    r1 = math.sqrt(d2 + y1 * y1)
    hv0 = y0 / r0
    delta = u1 * _hv_diff(y1, y0, hgt, d2)
    hv = hv0 + delta
    # cos(psi) = sqrt((1 - hv)(1 + hv)), both factors convex combinations of exact endpoints.
    one_minus = (1.0 - u1) * _one_minus_hv(y0, r0, d2) + u1 * _one_minus_hv(y1, r1, d2)
    one_plus = (1.0 - u1) * _one_minus_hv(-y0, r0, d2) + u1 * _one_minus_hv(-y1, r1, d2)
    cos_psi = math.sqrt(one_minus * one_plus)
    cos_psi0 = math.sqrt(d2) / r0
    # sin(psi - psi0) = hv cos(psi0) - cos(psi) hv0, rewritten when the two terms could cancel.
    if hv * hv0 > 0.0:
        sin_diff = delta * (hv + hv0) / (hv * cos_psi0 + cos_psi * hv0)
    else:
        sin_diff = hv * cos_psi0 - cos_psi * hv0
    return _clamp(r0 * sin_diff / cos_psi, hgt)


# ---------------------------------------------------------------------------------------------
# Per-lane interface


@jit
def solid_angle(x, corner, edge_u, edge_v) -> float:
    """Solid angle (sr) of the rectangle ``corner + s edge_u + t edge_v`` seen from ``x``;
    0 if x lies in its plane."""
    x0, y0, h, w, hgt, _, _, _ = _local(x, corner, edge_u, edge_v)
    if not h > 0.0:
        return 0.0
    return _rect_solid_angle(x0, w, y0, hgt, h)


@jit
def sample(x, corner, edge_u, edge_v, u0: float, u1: float):
    """``(point, pdf)``: a point on the rectangle whose direction from ``x`` is uniform in the
    solid angle Omega it subtends, and pdf = 1 / Omega (solid angle measure). u0 = 0 and 1 give
    the edges s = 0 and s = 1, u1 likewise for t. Degenerate (Omega 0 or not finite):
    ``(corner, 0.0)``."""
    x0, y0, h, w, hgt, flip_u, flip_v, origin = _local(x, corner, edge_u, edge_v)
    omega = _rect_solid_angle(x0, w, y0, hgt, h) if h > 0.0 else 0.0
    return sample_given(x, corner, edge_u, edge_v, omega, u0, u1, True)


@jit
def sample_given(x, corner, edge_u, edge_v, omega: float, u0: float, u1: float, refine: bool):
    """:func:`sample` for a caller that has computed ``omega = solid_angle(x, corner, edge_u,
    edge_v)`` already (to choose between techniques), so that it is not computed twice; without
    ``refine``, the closed-form cut where it is accurate (CLOSED_FORM_MIN_*)."""
    x0, y0, h, w, hgt, flip_u, flip_v, origin = _local(x, corner, edge_u, edge_v)
    if not (omega > 0.0 and omega < math.inf):
        return (float(corner[0]), float(corner[1]), float(corner[2])), 0.0
    # A reversed axis measures the same cut and height from the other edge.
    xi = _cut(x0, w, y0, hgt, h, omega, 1.0 - u0 if flip_u else u0, refine)
    eta = _height(x0 + xi, y0, hgt, h, 1.0 - u1 if flip_v else u1)
    s = min(xi / w, 1.0)
    t = min(eta / hgt, 1.0)
    point = add_scaled(add_scaled(origin, -s if flip_u else s, edge_u), -t if flip_v else t, edge_v)
    return point, 1.0 / omega


@jit
def invert(x, corner, edge_u, edge_v, point):
    """``(u0, u1)`` in [0, 1]^2 with ``sample(x, corner, edge_u, edge_v, u0, u1)`` at ``point``
    (a point of the rectangle; others are first projected onto its plane and clamped to it).
    Degenerate (Omega 0 or not finite): ``(0.0, 0.0)``."""
    x0, y0, h, w, hgt, flip_u, flip_v, origin = _local(x, corner, edge_u, edge_v)
    omega = _rect_solid_angle(x0, w, y0, hgt, h) if h > 0.0 else 0.0
    if not (omega > 0.0 and omega < math.inf):
        return 0.0, 0.0
    q = sub(point, origin)
    s = dot(q, edge_u) / dot(edge_u, edge_u)
    t = dot(q, edge_v) / dot(edge_v, edge_v)
    xi = _clamp(-s if flip_u else s, 1.0) * w
    eta = _clamp(-t if flip_v else t, 1.0) * hgt
    u0 = _rect_solid_angle(x0, xi, y0, hgt, h) / omega
    big_x = x0 + xi
    d2 = big_x * big_x + h * h
    full = _hv_diff(y0 + hgt, y0, hgt, d2)
    u1 = _hv_diff(y0 + eta, y0, eta, d2) / full if full > 0.0 else 0.0
    u0 = _clamp(u0, 1.0)
    u1 = _clamp(u1, 1.0)
    return (1.0 - u0 if flip_u else u0), (1.0 - u1 if flip_v else u1)


# ---------------------------------------------------------------------------------------------
# The same over arrays (tests, tools): x, corner, edge_u, edge_v are float64 arrays (3,)


@jit
def _vec(a):
    return (a[0], a[1], a[2])


@jit
def sample_lanes(x, corner, edge_u, edge_v, u: np.ndarray, refine: bool = True):
    """``u (n, 2)`` -> ``(points (n, 3), pdf (n,))`` of :func:`sample` (``refine``) or of the
    renderer's ``sample_given(..., refine=False)``."""
    xt, ct, et_u, et_v = _vec(x), _vec(corner), _vec(edge_u), _vec(edge_v)
    omega = solid_angle(xt, ct, et_u, et_v)
    points = np.empty((len(u), 3))
    pdf = np.empty(len(u))
    for i in range(len(u)):
        p, pdf[i] = sample_given(xt, ct, et_u, et_v, omega, u[i, 0], u[i, 1], refine)
        points[i, 0], points[i, 1], points[i, 2] = p
    return points, pdf


@jit
def invert_lanes(x, corner, edge_u, edge_v, points: np.ndarray) -> np.ndarray:
    """``points (n, 3)`` -> ``u (n, 2)`` of :func:`invert`."""
    xt, ct, et_u, et_v = _vec(x), _vec(corner), _vec(edge_u), _vec(edge_v)
    out = np.empty((len(points), 2))
    for i in range(len(points)):
        out[i, 0], out[i, 1] = invert(xt, ct, et_u, et_v, _vec(points[i]))
    return out


@jit
def solid_angle_lanes(x: np.ndarray, corner, edge_u, edge_v) -> np.ndarray:
    """Shading points ``x (n, 3)`` -> ``(n,)`` :func:`solid_angle` of one rectangle."""
    ct, et_u, et_v = _vec(corner), _vec(edge_u), _vec(edge_v)
    out = np.empty(len(x))
    for i in range(len(x)):
        out[i] = solid_angle(_vec(x[i]), ct, et_u, et_v)
    return out
