"""The ``uniform`` direction technique: directions uniform over the hemisphere, pdf 1 / (2 pi),
the material evaluated at each. A plug-in (``tracer.directions``)."""

from __future__ import annotations

from .. import warp
from ..kernels import UNBOUND, template
from ..plugins import DirectionTechnique, register

NAME = "uniform"
PLUGIN = register(DirectionTechnique(NAME, module=__name__, rank=0, dims=2,
                                     doc="uniform over the hemisphere"))


@template
def sample(kind, params, row, wo, u_lobe: float, u0: float, u1: float):
    wi = warp.uniform_hemisphere(u0, u1)
    return hemisphere_sample(kind, params, row, wo, wi, warp.uniform_hemisphere_pdf(wi[2]))


@template
def hemisphere_sample(kind, params, row, wo, wi, pdf_dir: float):
    """``(wi, weight, pdf, delta)`` of a hemisphere direction ``wi`` drawn with density
    ``pdf_dir``: weight = f |cos| / pdf (never a delta lobe: a hemisphere technique cannot
    produce one)."""
    if not pdf_dir > 0.0:
        return wi, (0.0, 0.0, 0.0), pdf_dir, False
    f = dispatch.material_eval_pdf(kind, params, row, wo, wi)[0]
    c = max(wi[2], 0.0) / pdf_dir
    return wi, (f[0] * c, f[1] * c, f[2] * c), pdf_dir, False


@template
def pdf(wi, pdf_material: float) -> float:
    return warp.uniform_hemisphere_pdf(wi[2])


dispatch = UNBOUND  # bound per build (``tracer.kernels``)
