"""``diffuse``: Lambertian reflection, f = reflectance / pi, sampled by the cosine warp.

=============  =====  =======================================
parameter      size   meaning
=============  =====  =======================================
reflectance    3      albedo per channel, in [0, 1]
=============  =====  =======================================
"""

from __future__ import annotations

from .. import warp
from ..jit import jit
from ..plugins import register
from .base import DIFFUSE, MaterialType, Param, mean3, rgb

CODE = 1  # the dispatch code (``tracer.materials``)
TYPE = register(MaterialType(module=__name__, rank=CODE, name="diffuse", code=CODE, lobes=DIFFUSE,
                    doc="Lambertian: f = reflectance / pi",
                    params=(Param("reflectance", 3, lo=0.0, hi=1.0,
                                  texture=True, doc="albedo per channel"),)))
REFLECTANCE = TYPE.column("reflectance")


@jit
def eval_pdf(params, row, wo, wi):
    """(f, pdf): reflectance / pi above the surface, and the cosine-hemisphere pdf."""
    if wi[2] <= 0.0:
        return (0.0, 0.0, 0.0), 0.0
    r, g, b = rgb(params, row, REFLECTANCE)
    return (r * warp.INV_PI, g * warp.INV_PI, b * warp.INV_PI), warp.cosine_hemisphere_pdf(wi[2])


@jit
def sample(params, row, wo, u_lobe, u0, u1):
    """Cosine-weighted wi; f cos / pdf = (reflectance / pi) cos / (cos / pi) = reflectance."""
    wi = warp.cosine_hemisphere(u0, u1)
    p = warp.cosine_hemisphere_pdf(wi[2])
    if not p > 0.0:
        return wi, (0.0, 0.0, 0.0), 0.0, 0
    return wi, rgb(params, row, REFLECTANCE), p, DIFFUSE


@jit
def lobe(params, row, wo):
    """The lobe proxy of product sampling (``tracer.lights.environment_product``): diffuse,
    weighted by the mean reflectance."""
    return mean3(params, row, REFLECTANCE), 0.0, 0.0, 1.0
