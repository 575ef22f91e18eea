"""The ``cosine`` direction technique: cosine-weighted directions over the hemisphere (Malley's
method), pdf cos / pi, the material evaluated at each. A plug-in (``tracer.directions``)."""

from __future__ import annotations

from .. import warp
from ..kernels import UNBOUND, template
from ..plugins import DirectionTechnique, register
from .uniform import hemisphere_sample

NAME = "cosine"
PLUGIN = register(DirectionTechnique(NAME, module=__name__, rank=1, dims=2,
                                     doc="cosine-weighted over the hemisphere"))


@template
def sample(kind, params, row, wo, u_lobe: float, u0: float, u1: float):
    wi = warp.cosine_hemisphere(u0, u1)
    return hemisphere_sample(kind, params, row, wo, wi, warp.cosine_hemisphere_pdf(wi[2]))


@template
def pdf(wi, pdf_material: float) -> float:
    return warp.cosine_hemisphere_pdf(wi[2])


dispatch = UNBOUND  # bound per build (``tracer.kernels``)
