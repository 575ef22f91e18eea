"""Sampling an emitting triangle by its solid angle warped toward the receiver's cosine: the
bilinear warp of ``spherical_triangle.py`` (which says how, after pbrt-v4), a plug-in
(``tracer.lights.techniques``) for triangles under ``--light-sampling solid-angle-cos``.
"""

from __future__ import annotations

from ...jit import jit, opaque
from ...plugins import LightTechnique, register
from . import spherical_triangle
from .spherical_triangle import WIDTH, pdf_warped, sample_warped

NAME = "spherical_triangle_cos"
PLUGIN = register(LightTechnique(NAME, code=5, module=__name__, rank=5, dims=2, emitters=("triangle",),
                                 light_samplings=("solid-angle-cos",), width=WIDTH,
                                 doc="the spherical triangle warped toward the receiver's cosine"))
rows = spherical_triangle.rows


@jit
def sample(rows, k: int, x, n, u0: float, u1: float):
    """The technique's sample (``tracer.lights.techniques``), warped."""
    wi, d, le, p = sample_warped(rows, k, x, n, opaque(True), u0, u1)
    return wi, d, le, p, False


@jit
def pdf(rows, k: int, x, n, wi, dist: float) -> float:
    """The technique's pdf, warped."""
    return pdf_warped(rows, k, x, n, opaque(True), wi, dist)
