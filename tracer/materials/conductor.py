"""``conductor``: a smooth metal, ideal specular reflection scaled by a conductor's Fresnel term.

A delta BSDF like ``mirror``: f and pdf are 0 for every given direction; ``sample`` returns the
reflection of wo with weight reflectance x F(cos theta_o; eta + i k) (``microfacet``, exact
unpolarized Fresnel per channel) and the ``DELTA`` flag. ``eta = 0, k = 1`` (the defaults) is a
perfect mirror, Mitsuba's ``material="none"``; named metals are in ``presets.CONDUCTORS``.

=============  =====  =================================================================
parameter      size   meaning
=============  =====  =================================================================
reflectance    3      scale per channel, in [0, 1] (Mitsuba's ``specular_reflectance``)
eta            3      real part of the complex index of refraction per channel, >= 0
k              3      imaginary part (absorption) per channel, >= 0
=============  =====  =================================================================
"""

from __future__ import annotations

from ..jit import jit, jit_called
from ..plugins import register
from . import microfacet
from .base import DELTA, MaterialType, Param, no_density, rgb

CODE = 4  # the dispatch code (``tracer.materials``)
# Up to MAX_INDEX: 100 times the largest of Mitsuba's measured metals (Al: k 9.2), where F is 1
# to within 4e-3 at every angle; the Fresnel term stays finite to about 1e10 (measured), so every
# accepted value renders.
MAX_INDEX = 1000.0
ETA_PARAM = Param("eta", 3, lo=0.0, hi=MAX_INDEX, default=0.0,
                  texture=True, doc="real part of the complex index of refraction")
K_PARAM = Param("k", 3, lo=0.0, hi=MAX_INDEX, default=1.0,
                texture=True, doc="imaginary part of the complex index of refraction")
TYPE = register(MaterialType(module=__name__, rank=CODE, name=
    "conductor", code=CODE, lobes=DELTA, doc="smooth metal: specular reflection times conductor Fresnel",
    params=(Param("reflectance", 3, lo=0.0, hi=1.0, default=1.0, texture=True, doc="scale per channel"),
            ETA_PARAM, K_PARAM)))
REFLECTANCE, ETA, K = TYPE.column("reflectance"), TYPE.column("eta"), TYPE.column("k")


@jit_called
def fresnel_rgb(params, row, eta_column: int, k_column: int, cos: float):
    """Per-channel conductor Fresnel of the material in ``row`` at cos (its eta and k at the
    given columns); exactly 1 for the default eta = 0, k = 1, without computing it."""
    eta, k = rgb(params, row, eta_column), rgb(params, row, k_column)
    if eta[0] == 0.0 and eta[1] == 0.0 and eta[2] == 0.0 and k[0] == 1.0 and k[1] == 1.0 and k[2] == 1.0:
        return 1.0, 1.0, 1.0
    return (microfacet.fresnel_conductor(cos, eta[0], k[0]), microfacet.fresnel_conductor(cos, eta[1], k[1]),
            microfacet.fresnel_conductor(cos, eta[2], k[2]))


eval_pdf = no_density  # delta lobes only


@jit
def sample(params, row, wo, u_lobe, u0, u1):
    """The mirror direction of wo, weighted by reflectance x Fresnel."""
    f = fresnel_rgb(params, row, ETA, K, wo[2])
    r, g, b = rgb(params, row, REFLECTANCE)
    return (-wo[0], -wo[1], wo[2]), (r * f[0], g * f[1], b * f[2]), 0.0, DELTA
