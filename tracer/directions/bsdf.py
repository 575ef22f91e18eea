"""The ``bsdf`` direction technique: the material's own sampling (``tracer.materials``: its lobe
chosen by ``u_lobe``, its direction by ``u0, u1``), whose pdf is the material's. A plug-in
(``tracer.directions``)."""

from __future__ import annotations

from .. import materials
from ..kernels import UNBOUND, template
from ..plugins import DirectionTechnique, register

NAME = "bsdf"
PLUGIN = register(DirectionTechnique(NAME, module=__name__, rank=2, dims=3,
                                     doc="the material's own sampling"))


@template
def sample(kind, params, row, wo, u_lobe: float, u0: float, u1: float):
    wi, weight, pdf_dir, flags = dispatch.material_sample(kind, params, row, wo, u_lobe, u0, u1)
    return wi, weight, pdf_dir, (flags & materials.DELTA) != 0


@template
def pdf(wi, pdf_material: float) -> float:
    return pdf_material


dispatch = UNBOUND  # bound per build (``tracer.kernels``)
