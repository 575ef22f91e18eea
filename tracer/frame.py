"""3-vectors as tuples and orthonormal shading frames, for per-lane compiled code.

A vector is a ``(x, y, z)`` tuple of floats: numba keeps it in registers. BSDF math happens in
the local frame whose z axis is the normal (pbrt's ``LocalFromRender``), so names carry
their space: ``wo_local``, ``wi_world``.
"""

from __future__ import annotations

import math

from .jit import jit


@jit
def dot(a, b) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@jit
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@jit
def add_scaled(a, s: float, b):
    """a + s b."""
    return (a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2])


@jit
def scale(s: float, a):
    return (s * a[0], s * a[1], s * a[2])


@jit
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@jit
def basis(n):
    """(s, t): unit vectors completing unit ``n`` to a right-handed frame (s, t, n), without
    branches on the normal's direction (Duff et al. 2017, JCGT 6(1))."""
    sign = 1.0 if n[2] >= 0.0 else -1.0
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    s = (1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0])
    t = (b, sign + n[1] * n[1] * a, -n[1])
    return s, t


@jit
def rotate(m, v):
    """``m v`` for a (3, 3) array ``m`` (a rotation between frames, rows the new axes)."""
    return (m[0, 0] * v[0] + m[0, 1] * v[1] + m[0, 2] * v[2],
            m[1, 0] * v[0] + m[1, 1] * v[1] + m[1, 2] * v[2],
            m[2, 0] * v[0] + m[2, 1] * v[1] + m[2, 2] * v[2])


@jit
def to_local(s, t, n, w):
    """World ``w`` in the frame (s, t, n)."""
    return (dot(w, s), dot(w, t), dot(w, n))


@jit
def to_world(s, t, n, w):
    """Local ``w`` of the frame (s, t, n) in world space."""
    return (w[0] * s[0] + w[1] * t[0] + w[2] * n[0],
            w[0] * s[1] + w[1] * t[1] + w[2] * n[1],
            w[0] * s[2] + w[1] * t[2] + w[2] * n[2])


@jit
def normalized(a):
    """``a / |a|``, and the length; a zero vector stays zero."""
    length = math.sqrt(dot(a, a))
    inv = 1.0 / length if length > 0.0 else 0.0
    return (a[0] * inv, a[1] * inv, a[2] * inv), length
