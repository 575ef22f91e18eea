"""``dielectric``: a smooth interface between two indices of refraction, Mitsuba 3's model.

Two delta lobes: reflection about the normal, and refraction by Snell's law. Sampling picks
reflection with probability F (the exact unpolarized Fresnel reflectance at cos theta_o) and
refraction with 1 - F, so each lobe's weight is its scale alone: specular_reflectance, or
specular_transmittance / eta^2 for refraction. The 1 / eta^2 is radiance's solid-angle
compression across the interface (radiance mode: light arriving from inside a denser medium
is dimmer outside; Mitsuba's ``dielectric.cpp`` applies the same factor). Under total internal
reflection F = 1 and every sample reflects.

A dielectric has an inside: the shading frame is turned toward the viewer (``wo.z > 0``, as for
every material), so a hit seen from behind the normal shades with the row of the same material
with eta inverted (``MaterialType.behind``, the estimator's ``behind`` rows). Light arrives
through it only along the delta refraction from the camera's first hit (tracer's estimator, as
Mitsuba's ``direct`` integrator): emitter sampling gives 0 for a delta material.

=======================  =====  ===================================================
parameter                size   meaning
=======================  =====  ===================================================
specular_reflectance     3      reflection scale, in [0, 1] (default 1)
specular_transmittance   3      refraction scale, in [0, 1] (default 1)
int_ior, ext_ior         1, 1   indices inside and outside (bk7 1.5046, air 1.000277)
=======================  =====  ===================================================
"""

from __future__ import annotations

import math

from ..jit import jit
from ..plugins import register
from . import microfacet
from .base import DELTA, MaterialType, Param, no_density, rgb
from .plastic import MAX_IOR, MIN_IOR

CODE = 7  # the dispatch code (``tracer.materials``)
# Mitsuba 3's defaults: BK7 glass inside, air outside (src/bsdfs/dielectric.cpp).
DIELECTRIC_PARAMS = (
    Param("specular_reflectance", 3, lo=0.0, hi=1.0, default=1.0, doc="reflection scale"),
    Param("specular_transmittance", 3, lo=0.0, hi=1.0, default=1.0, doc="transmission scale"),
    Param("int_ior", 1, lo=MIN_IOR, hi=MAX_IOR, default=1.5046, doc="index inside"),
    Param("ext_ior", 1, lo=MIN_IOR, hi=MAX_IOR, default=1.000277, doc="index outside"),
)


def relative_eta(values: dict[str, object]) -> dict[str, object]:
    """The derived eta = int_ior / ext_ior."""
    return {"eta": float(values["int_ior"]) / float(values["ext_ior"])}


def seen_from_inside(values: dict[str, object]) -> dict[str, object]:
    """The parameters of the interface seen from inside: the two indices swapped."""
    return dict(values, int_ior=values["ext_ior"], ext_ior=values["int_ior"])


TYPE = register(MaterialType(module=__name__, rank=CODE, name="dielectric", code=CODE, lobes=DELTA,
                    doc="smooth glass: delta reflection and refraction",
                    params=DIELECTRIC_PARAMS, derived=(Param("eta", 1),), derive=relative_eta,
                    behind=seen_from_inside))
SPECULAR_REFLECTANCE = TYPE.column("specular_reflectance")
SPECULAR_TRANSMITTANCE = TYPE.column("specular_transmittance")
ETA = TYPE.column("eta")


eval_pdf = no_density  # delta lobes only


@jit
def sample(params, row, wo, u_lobe, u0, u1):
    """Reflection with probability F(cos_o), else the refracted direction."""
    eta = params[row, ETA]
    cos_o = wo[2]
    reflected = microfacet.fresnel_dielectric(cos_o, eta)
    if u_lobe < reflected:
        return (-wo[0], -wo[1], cos_o), rgb(params, row, SPECULAR_REFLECTANCE), 0.0, DELTA
    # Snell: the tangential part shrinks by 1 / eta; F < 1 here, so sin2_t < 1.
    inv_eta = 1.0 / eta
    sin2_t = (1.0 - cos_o * cos_o) * inv_eta * inv_eta
    cos_t = math.sqrt(max(0.0, 1.0 - sin2_t))
    scale = inv_eta * inv_eta
    t = rgb(params, row, SPECULAR_TRANSMITTANCE)
    weight = (t[0] * scale, t[1] * scale, t[2] * scale)
    return (-wo[0] * inv_eta, -wo[1] * inv_eta, -cos_t), weight, 0.0, DELTA
