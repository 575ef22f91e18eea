"""``blendbsdf``: a linear blend of two materials, f = (1 - weight) f_first + weight f_second.

As Mitsuba 3.9.1's ``blendbsdf`` (src/bsdfs/blendbsdf.cpp): ``weight`` (a number or a texture,
in [0, 1]) mixes the two materials' values and pdfs; a sample picks the second with
probability ``weight`` (the lobe number, rescaled, then picks within it), and a sample of a
non-delta lobe is weighted with the blend of both materials' f and pdf in its direction, so
that its pdf is the one ``eval_pdf`` gives (what MIS needs). A delta lobe's sample keeps its
material's weight: the blend's weight and the probability of picking that material cancel.

=============  =====  ===============================================================
parameter      size   meaning
=============  =====  ===============================================================
weight         1      in [0, 1]: 0 is the first material, 1 the second
first, second  1, 1   the two materials' type codes (set by the reader, ``parts``)
=============  =====  ===============================================================

A blend is a *composite* type: its two materials are ordinary rows of the table, right after
the blend's own (rows ``row + 1`` and ``row + 2``: ``parts`` lays them out), evaluated through
``dispatch.part_eval_pdf`` and ``dispatch.part_sample``, the dispatch chains over the scene's
non-composite types (``tracer.kernels.dispatch``). Its functions are therefore templates, built
per feature set like the kernels. A blend's parts only reflect (no dielectrics, no blends):
Mitsuba allows more, and tracer refuses it in one line.
"""

from __future__ import annotations

from ..kernels import UNBOUND, template
from ..plugins import register
from .base import DELTA, DIFFUSE, GLOSSY, MaterialType, Param, weighted

CODE = 11  # the dispatch code (``tracer.materials``)
TYPE = register(MaterialType(module=__name__, rank=CODE, name="blendbsdf", code=CODE,
                             lobes=DELTA | GLOSSY | DIFFUSE, rows=3,
                             doc="a blend of two materials: (1 - weight) f_first + weight f_second",
                             params=(Param("weight", 1, lo=0.0, hi=1.0, default=0.5, texture=True,
                                           doc="0: the first material, 1: the second"),
                                     Param("first", 1, lo=1.0, internal=True,
                                           doc="the first material's type code"),
                                     Param("second", 1, lo=1.0, internal=True,
                                           doc="the second material's type code"))))
WEIGHT, FIRST, SECOND = TYPE.column("weight"), TYPE.column("first"), TYPE.column("second")


def parts(name: str, weight: object, first: tuple[str, dict[str, object]],
          second: tuple[str, dict[str, object]]) -> list[tuple[str, str, dict[str, object]]]:
    """The table triples of a blend named ``name``: its own row, then its two materials'
    ``(type name, values)`` rows, in the order the kernels read them (module docstring)."""
    from . import TYPES

    own = {"weight": weight, "first": float(TYPES[first[0]].code), "second": float(TYPES[second[0]].code)}
    return [(name, TYPE.name, own), (f"{name}/first", *first), (f"{name}/second", *second)]


@template
def eval_pdf(params, row, wo, wi):
    """(f, pdf): the blend of the two materials' values and pdfs."""
    w = params[row, WEIGHT]
    f0, p0 = dispatch.part_eval_pdf(int(params[row, FIRST]), params, row + 1, wo, wi)
    f1, p1 = dispatch.part_eval_pdf(int(params[row, SECOND]), params, row + 2, wo, wi)
    v = 1.0 - w
    return (v * f0[0] + w * f1[0], v * f0[1] + w * f1[1], v * f0[2] + w * f1[2]), v * p0 + w * p1


@template
def sample(params, row, wo, u_lobe, u0, u1):
    """The second material with probability weight (u_lobe < weight), else the first, with
    u_lobe rescaled to [0, 1) for the picked material's own lobe choice."""
    w = params[row, WEIGHT]
    if u_lobe < w:
        code, part, u = int(params[row, SECOND]), row + 2, u_lobe / w
    else:
        code, part, u = int(params[row, FIRST]), row + 1, (u_lobe - w) / (1.0 - w)
    wi, weight, p, flags = dispatch.part_sample(code, params, part, wo, min(u, _BELOW_ONE), u0, u1)
    if flags == 0 or (flags & DELTA) != 0:
        return wi, weight, p, flags
    f, p_blend = eval_pdf(params, row, wo, wi)
    return weighted(wi, f, p_blend, flags)


# The largest float below 1: a rescaled lobe number stays in [0, 1) where rounding reaches 1.
_BELOW_ONE = 1.0 - 2.0**-53

dispatch = UNBOUND  # bound per build (``tracer.kernels``)
