"""Directions uniform in the solid angle that a triangle subtends: the solid angle itself, the
sampling map from the unit square, and its inverse.

Arguments: the shading point ``x`` and the triangle's corners ``a, b, c`` are ``(x, y, z)``
tuples of float64 in world space; a direction ``wi`` is a unit tuple leaving ``x``; solid
angles are in steradians (sr) and pdfs are densities with respect to solid angle (1/sr). The
corners may come in either winding: only the spherical triangle matters. Write A, B, C for the
unit vectors from x toward a, b, c.

Solid angle (Van Oosterom and Strackee 1983, "The solid angle of a plane triangle", IEEE Trans.
Biomed. Eng. 30(2)):

    tan(Omega / 2) = |A . (B x C)| / (1 + A.B + B.C + C.A),

evaluated as Omega = 2 atan2(numerator, denominator), which stays right when the denominator is
0 or negative (Omega >= pi) and never takes an acos of a rounded cosine. The triple product is
taken as (a - x) . ((b - a) x (c - a)) / (|a - x| |b - x| |c - x|): the edge vectors do not
depend on x, so a view that grazes the plane (a small triple product) keeps its relative digits.

Sampling (Arvo 1995, "Stratified sampling of spherical triangles", SIGGRAPH 95): u0 picks the
point C' on the arc from A to C such that the sub-triangle (A, B, C') has area u0 Omega; u1 then
picks the direction on the arc from B to C' with 1 - cos(angle from B) uniform in
[0, 1 - B.C'], which is uniform in solid angle inside the thin wedge at B. The composition is
uniform on the spherical triangle: pdf = 1 / Omega.

Arvo solves for C' through the vertex angles (area = alpha + beta + gamma - pi) and a ratio of
differences that both lose their digits on small or thin triangles (the area is a small
difference of angles near pi; his u = cos(phi) - cos(alpha) cancels as u0 -> 0). Here the
sub-area is written with Van Oosterom's formula instead. With T the unit tangent at A toward C,
C' = cos(theta) A + sin(theta) T and h = theta / 2, the sub-triangle (A, B, C') has

    |A . (B x C')| = sin(theta) m,     1 + A.B + B.C' + C'.A = (1 + cos(theta)) P + sin(theta) Q,

with m = |A . (B x T)| = |A . (B x C)| / |A x C|, P = 1 + A.B = |A + B|^2 / 2, Q = B.T. Dividing
both by 2 cos(h) > 0, the sub-area is psi' = Omega' / 2 = atan2(sin(h) m, cos(h) P + sin(h) Q),
and setting psi' = u0 Omega / 2 = psi solves in closed form:

    h = atan2(P sin(psi), m cos(psi) - Q sin(psi)),

where the second argument is proportional to m cos(h) P >= 0 at the solution (clamped at 0).
The second step uses half angles: with sin(l / 2) = |C' - B| / 2 for the arc length l from B
to C', the sampled angle d from B has sin(d / 2) = sqrt(u1) |C' - B| / 2, so no 1 - cos of a
small angle is ever formed. Differences of unit vectors (B - A, C - A) are formed from the world
edges as q/|q| - p/|p| = ((q - p) - (p/|p|)(|q| - |p|)) / |q| with
|q| - |p| = (q - p).(q + p) / (|p| + |q|), so a small, distant triangle keeps its digits too.

Inversion (the map that pbrt-v4 calls InvertSphericalTriangleSample, derived here from the
construction above): C' is where the great circle through B and wi meets the arc AC. With
n1 = B x (wi - B) normal to that circle, n1 . C'(theta) = cos(theta) n1.A + sin(theta) n1.T = 0
gives theta = atan2(-n1.A, n1.T) modulo pi, taken within pi/2 of the arc's midpoint (so that
rounding cannot send wi = A to theta = pi); then u0 = psi'(theta / 2) / (Omega / 2) and
u1 = (1 - B.wi) / (1 - B.C') = |wi - B|^2 / |C' - B|^2.

Conditioning: u0 is ill-conditioned where u1 -> 0 (all u0 lead to B there) and on triangles
that are thin as seen from x (the great circles through B fan out over a small angle): an
error e in wi moves u0 by about e / (thickness sqrt(u1)). Both maps pass through C', which
costs digits of its own where C' crowds: on a triangle of nearly 2 pi sr (x just above its
interior) most u0 put C' near the antipode of B, and an ulp of C' there is ~eps / (the width
of that crowd) in u0 and in the direction of the arc at B (measured: u0 to 2.5e-13 at
2 pi - 0.02 sr, where the map itself is conditioned to ~1).

Array versions for tests and tools: ``solid_angle_lanes``, ``sample_lanes``, ``invert_lanes``.
"""

from __future__ import annotations

import math

import numpy as np

from ..frame import cross, dot, normalized, sub
from ..jit import jit

NO_DIRECTION = (0.0, 0.0, 1.0)


@jit
def _unit_difference(p, p_unit, lp: float, lq: float, q_minus_p):
    """q/|q| - p/|p| without cancellation, from the exact-as-given world difference q - p."""
    s = dot(q_minus_p, (2.0 * p[0] + q_minus_p[0], 2.0 * p[1] + q_minus_p[1],
                        2.0 * p[2] + q_minus_p[2])) / (lp + lq)  # |q| - |p|
    inv = 1.0 / lq
    return ((q_minus_p[0] - s * p_unit[0]) * inv, (q_minus_p[1] - s * p_unit[1]) * inv,
            (q_minus_p[2] - s * p_unit[2]) * inv)


@jit
def _setup(x, a, b, c):
    """(A, B, C, B - A, C - A, Omega / 2, |A . (B x C)|) for the triangle seen from x."""
    pa, pb, pc = sub(a, x), sub(b, x), sub(c, x)
    ua, la = normalized(pa)
    ub, lb = normalized(pb)
    uc, lc = normalized(pc)
    eab, eac = sub(b, a), sub(c, a)
    dab = _unit_difference(pa, ua, la, lb, eab)
    dac = _unit_difference(pa, ua, la, lc, eac)
    triple = abs(dot(pa, cross(eab, eac))) / (la * lb * lc)
    if not (triple > 0.0):  # x in the plane, a corner, a degenerate triangle, or nan
        return ua, ub, uc, dab, dac, 0.0, 0.0
    den = 1.0 + dot(ua, ub) + dot(ub, uc) + dot(uc, ua)
    return ua, ub, uc, dab, dac, math.atan2(triple, den), triple


@jit
def solid_angle(x, a, b, c) -> float:
    """Solid angle (sr, in [0, 2 pi)) of triangle (a, b, c) seen from x. 0 where it is not
    defined or the triangle is seen edge-on: x in the triangle's plane (a corner included), a
    degenerate triangle, non-finite input. (Seen from just off the plane, inside the triangle,
    the solid angle tends to 2 pi; exactly in the plane it is 0.)"""
    pa, pb, pc = sub(a, x), sub(b, x), sub(c, x)
    ua, la = normalized(pa)
    ub, lb = normalized(pb)
    uc, lc = normalized(pc)
    triple = abs(dot(pa, cross(sub(b, a), sub(c, a)))) / (la * lb * lc)
    if not (triple > 0.0):
        return 0.0
    den = 1.0 + dot(ua, ub) + dot(ub, uc) + dot(uc, ua)
    return 2.0 * math.atan2(triple, den)


@jit
def _arc_terms(ua, dab, dac, triple):
    """(T, m, P, Q, half arc length A to C) of the module docstring."""
    along = dot(dac, ua)
    t, sin_ac = normalized((dac[0] - along * ua[0], dac[1] - along * ua[1], dac[2] - along * ua[2]))
    m = triple / sin_ac
    s = (2.0 * ua[0] + dab[0], 2.0 * ua[1] + dab[1], 2.0 * ua[2] + dab[2])  # A + B
    p = 0.5 * dot(s, s)
    q = dot(dab, t)
    # Half the arc A to C: atan2(|C - A|, |C + A|).
    s2 = (2.0 * ua[0] + dac[0], 2.0 * ua[1] + dac[1], 2.0 * ua[2] + dac[2])
    half_ac = math.atan2(math.sqrt(dot(dac, dac)), math.sqrt(dot(s2, s2)))
    return t, m, p, q, half_ac


@jit
def _c_prime_minus_b(ua, t, dab, h: float):
    """C' - B for C' = cos(2h) A + sin(2h) T: (C' - A) - (B - A), C' - A = -2 sin^2(h) A + sin(2h) T."""
    sh, ch = math.sin(h), math.cos(h)
    k1, k2 = -2.0 * sh * sh, 2.0 * sh * ch
    return (k1 * ua[0] + k2 * t[0] - dab[0], k1 * ua[1] + k2 * t[1] - dab[1],
            k1 * ua[2] + k2 * t[2] - dab[2])


@jit
def sample(x, a, b, c, u0: float, u1: float):
    """A direction ``wi`` from x uniform in the solid angle of triangle (a, b, c), and its pdf
    1 / Omega (1/sr); ``((0, 0, 1), 0)`` if the solid angle is 0 or not finite."""
    ua, ub, uc, dab, dac, half_omega, triple = _setup(x, a, b, c)
    if not (half_omega > 0.0 and half_omega < math.inf):
        return NO_DIRECTION, 0.0
    t, m, p, q, half_ac = _arc_terms(ua, dab, dac, triple)
    psi = u0 * half_omega
    sp, cp = math.sin(psi), math.cos(psi)
    h = min(math.atan2(p * sp, max(m * cp - q * sp, 0.0)), half_ac)
    e = _c_prime_minus_b(ua, t, dab, h)  # C' - B
    le2 = dot(e, e)
    # Tangent at B toward C': the part of C' - B orthogonal to B.
    along = dot(e, ub)
    t2, _ = normalized((e[0] - along * ub[0], e[1] - along * ub[1], e[2] - along * ub[2]))
    s = math.sqrt(u1 * le2) * 0.5  # sin(d / 2), d the angle from B
    s = min(s, 1.0)
    one_minus_cos = 2.0 * s * s
    sin_d = 2.0 * s * math.sqrt(max(0.0, 1.0 - s * s))
    wi, _ = normalized((ub[0] + sin_d * t2[0] - one_minus_cos * ub[0],
                        ub[1] + sin_d * t2[1] - one_minus_cos * ub[1],
                        ub[2] + sin_d * t2[2] - one_minus_cos * ub[2]))
    return wi, 0.5 / half_omega


@jit
def invert(x, a, b, c, wi):
    """The ``(u0, u1)`` in [0, 1]^2 that :func:`sample` maps to the unit direction ``wi`` (which
    should point into the triangle); (0, 0) if the solid angle is 0 or not finite."""
    ua, ub, uc, dab, dac, half_omega, triple = _setup(x, a, b, c)
    if not (half_omega > 0.0 and half_omega < math.inf):
        return 0.0, 0.0
    t, m, p, q, half_ac = _arc_terms(ua, dab, dac, triple)
    w, _ = normalized(wi)
    dbw = sub(w, ub)  # wi - B
    n1 = cross(ub, dbw)  # normal of the great circle through B and wi
    # n1 . A = n1 . (B - (B - A)) = -n1 . (B - A): no rounding of B.A enters.
    y = dot(n1, dab)  # = -n1 . A
    xx = dot(n1, t)
    # theta = atan2(y, xx) modulo pi; the representative in (half_ac - pi/2, half_ac + pi/2]
    # (atan2 of the pair rotated by -half_ac, with the second argument made >= 0) keeps the
    # branch cut away from the arc [0, 2 half_ac], so that theta = 0 (wi on the arc BA) does
    # not jump to pi when rounding flips the sign of y.
    sb, cb = math.sin(half_ac), math.cos(half_ac)
    y, xx = y * cb - xx * sb, y * sb + xx * cb
    if xx < 0.0:
        y, xx = -y, -xx
    h = min(max(0.5 * (half_ac + math.atan2(y, xx)), 0.0), half_ac)
    sh, ch = math.sin(h), math.cos(h)
    u0 = math.atan2(sh * m, ch * p + sh * q) / half_omega
    e = _c_prime_minus_b(ua, t, dab, h)
    le2 = dot(e, e)
    u1 = dot(dbw, dbw) / le2 if le2 > 0.0 else 0.0
    return min(max(u0, 0.0), 1.0), min(max(u1, 0.0), 1.0)


# ---------------------------------------------------------------------------------------------
# Over arrays (tests, tools)


@jit
def _tuple(v):
    return (float(v[0]), float(v[1]), float(v[2]))


@jit
def solid_angle_lanes(x: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``x (n, 3)`` points, corners ``a, b, c (3,)`` -> ``(n,)`` solid angles (sr)."""
    ta, tb, tc = _tuple(a), _tuple(b), _tuple(c)
    out = np.empty(len(x))
    for i in range(len(x)):
        out[i] = solid_angle(_tuple(x[i]), ta, tb, tc)
    return out


@jit
def sample_lanes(x: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, u: np.ndarray):
    """One point ``x (3,)``, corners ``a, b, c (3,)``, ``u (n, 2)`` -> (wi ``(n, 3)`` unit
    directions, pdf ``(n,)`` in 1/sr)."""
    tx, ta, tb, tc = _tuple(x), _tuple(a), _tuple(b), _tuple(c)
    wi = np.empty((len(u), 3))
    pdf = np.empty(len(u))
    for i in range(len(u)):
        w, p = sample(tx, ta, tb, tc, u[i, 0], u[i, 1])
        wi[i, 0], wi[i, 1], wi[i, 2] = w
        pdf[i] = p
    return wi, pdf


@jit
def invert_lanes(x: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray,
                 wi: np.ndarray) -> np.ndarray:
    """One point ``x (3,)``, corners ``a, b, c (3,)``, unit ``wi (n, 3)`` -> ``u (n, 2)``."""
    tx, ta, tb, tc = _tuple(x), _tuple(a), _tuple(b), _tuple(c)
    out = np.empty((len(wi), 2))
    for i in range(len(wi)):
        out[i, 0], out[i, 1] = invert(tx, ta, tb, tc, _tuple(wi[i]))
    return out
