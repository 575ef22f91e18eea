"""``mirror``: ideal specular reflection, a delta BSDF.

f and pdf are 0 for every direction (no other technique can hit the lobe); ``sample`` returns
the reflection of wo with weight = reflectance and the ``DELTA`` flag.

=============  =====  =======================================
parameter      size   meaning
=============  =====  =======================================
reflectance    3      reflectance per channel, in [0, 1]
=============  =====  =======================================
"""

from __future__ import annotations

from ..jit import jit
from ..plugins import register
from .base import DELTA, MaterialType, Param, no_density, rgb

CODE = 3  # the dispatch code (``tracer.materials``)
TYPE = register(MaterialType(module=__name__, rank=CODE, name="mirror", code=CODE, lobes=DELTA,
                    doc="ideal specular reflection (delta)",
                    params=(Param("reflectance", 3, lo=0.0, hi=1.0,
                                  texture=True, doc="reflectance per channel"),)))
REFLECTANCE = TYPE.column("reflectance")


eval_pdf = no_density  # delta lobes only


@jit
def sample(params, row, wo, u_lobe, u0, u1):
    """The mirror direction of wo about the normal."""
    return (-wo[0], -wo[1], wo[2]), rgb(params, row, REFLECTANCE), 0.0, DELTA
