"""``thindielectric``: a thin pane of glass (two parallel interfaces), Mitsuba 3's model.

Two delta lobes: reflection about the normal, and transmission straight through (``wi = -wo``:
the two refractions cancel). With R the single interface's Fresnel reflectance at cos theta_o,
the light that bounces between the two faces sums to the pane's reflectance R' = 2R / (1 + R),
and T' = 1 - R' (no absorption). Sampling picks reflection with probability R', so each lobe's
weight is its scale alone (specular_reflectance or specular_transmittance). The pane is the
same from both sides: no ``behind`` row.

=======================  =====  ===================================================
parameter                size   meaning
=======================  =====  ===================================================
specular_reflectance     3      reflection scale, in [0, 1] (default 1)
specular_transmittance   3      transmission scale, in [0, 1] (default 1)
int_ior, ext_ior         1, 1   indices of the pane and around it (bk7, air)
=======================  =====  ===================================================
"""

from __future__ import annotations

from ..jit import jit
from ..plugins import register
from . import microfacet
from .base import DELTA, MaterialType, Param, no_density, rgb
from .dielectric import DIELECTRIC_PARAMS, relative_eta

CODE = 8  # the dispatch code (``tracer.materials``)
TYPE = register(MaterialType(module=__name__, rank=CODE, name="thindielectric", code=CODE, lobes=DELTA,
                    doc="thin glass pane: delta reflection and straight transmission",
                    params=DIELECTRIC_PARAMS, derived=(Param("eta", 1),), derive=relative_eta))
SPECULAR_REFLECTANCE = TYPE.column("specular_reflectance")
SPECULAR_TRANSMITTANCE = TYPE.column("specular_transmittance")
ETA = TYPE.column("eta")


@jit
def pane_reflectance(cos_o: float, eta: float) -> float:
    """R' = 2R / (1 + R): the reflectance of both faces with every inner bounce summed."""
    r = microfacet.fresnel_dielectric(cos_o, eta)
    return 2.0 * r / (1.0 + r)


eval_pdf = no_density  # delta lobes only


@jit
def sample(params, row, wo, u_lobe, u0, u1):
    """Reflection with probability R', else straight through."""
    if u_lobe < pane_reflectance(wo[2], params[row, ETA]):
        return (-wo[0], -wo[1], wo[2]), rgb(params, row, SPECULAR_REFLECTANCE), 0.0, DELTA
    return (-wo[0], -wo[1], -wo[2]), rgb(params, row, SPECULAR_TRANSMITTANCE), 0.0, DELTA
