"""A material plug-in: Lambertian reflection, f = reflectance / pi, like ``diffuse``, but sampled
uniformly over the hemisphere (pdf 1 / (2 pi)) instead of by the cosine: the same image, other
noise."""

from __future__ import annotations

from tracer import warp
from tracer.jit import jit
from tracer.materials.base import DIFFUSE, MaterialType, Param, rgb
from tracer.plugins import register

CODE = 101
TYPE = register(MaterialType("lambert_uniform", code=CODE, module=__name__, lobes=DIFFUSE,
                             doc="Lambertian, sampled uniformly over the hemisphere",
                             params=(Param("reflectance", 3, lo=0.0, hi=1.0, doc="albedo per channel"),)))
REFLECTANCE = TYPE.column("reflectance")


@jit
def eval_pdf(params, row, wo, wi):
    if wi[2] <= 0.0:
        return (0.0, 0.0, 0.0), 0.0
    r, g, b = rgb(params, row, REFLECTANCE)
    return (r * warp.INV_PI, g * warp.INV_PI, b * warp.INV_PI), warp.uniform_hemisphere_pdf(wi[2])


@jit
def sample(params, row, wo, u_lobe, u0, u1):
    wi = warp.uniform_hemisphere(u0, u1)
    f, p = eval_pdf(params, row, wo, wi)
    if not p > 0.0:
        return wi, (0.0, 0.0, 0.0), 0.0, 0
    c = wi[2] / p
    return wi, (f[0] * c, f[1] * c, f[2] * c), p, DIFFUSE
