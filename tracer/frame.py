"""Orthonormal shading frames: world <-> local, where the local z axis is the normal.

BSDF math happens in the local frame (pbrt's ``LocalFromRender``), so names carry their
space: ``wo_local``, ``wi_world``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Frame:
    """Per-lane orthonormal bases. ``s, t, n``: ``(n, 3)`` float64 unit vectors, right-handed."""

    s: np.ndarray
    t: np.ndarray
    n: np.ndarray

    @classmethod
    def from_normal(cls, n: np.ndarray) -> "Frame":
        """Branchless basis around unit normals ``n (n, 3)`` (Duff et al. 2017, JCGT 6(1))."""
        sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
        a = -1.0 / (sign + n[:, 2])
        b = n[:, 0] * n[:, 1] * a
        s = np.stack([1.0 + sign * n[:, 0] * n[:, 0] * a, sign * b, -sign * n[:, 0]], axis=1)
        t = np.stack([b, sign + n[:, 1] * n[:, 1] * a, -n[:, 1]], axis=1)
        return cls(s, t, n)

    def to_local(self, w: np.ndarray) -> np.ndarray:
        """World ``(n, 3)`` -> local ``(n, 3)``."""
        out = np.empty_like(w)
        out[:, 0] = np.einsum("ij,ij->i", w, self.s)
        out[:, 1] = np.einsum("ij,ij->i", w, self.t)
        out[:, 2] = np.einsum("ij,ij->i", w, self.n)
        return out

    def to_world(self, w: np.ndarray) -> np.ndarray:
        """Local ``(n, 3)`` -> world ``(n, 3)``."""
        return w[:, 0:1] * self.s + w[:, 1:2] * self.t + w[:, 2:3] * self.n

    def take(self, idx: np.ndarray) -> "Frame":
        """The frames of lanes ``idx``."""
        return Frame(self.s[idx], self.t[idx], self.n[idx])
