"""Point lights: a delta light of radiant intensity I (W/sr) at a position, optionally a spot.

The sample is the direction to the light, with le = I falloff / d^2 (the irradiance it gives is
le |cos theta_i|) and the ``delta`` flag: no other technique can produce it, so it takes MIS
weight 1, and its pdf is the selection probability alone.

A spot light (Mitsuba's ``spot``) shines along its axis: with theta the angle between the axis
and the direction from the light to the shading point, the falloff is 1 for theta within the
beam width, (cutoff - theta) / (cutoff - beam width) between the beam width and the cutoff, and
0 beyond (Mitsuba's cos theta > cos cutoff test, src/emitters/spot.cpp). A light that shines every
way has cos cutoff = cos beam = -2: the falloff is 1. A light may also project an image (a
textured spot, a projector: ``tracer.lights.projected_images``), whose value multiplies I.

==============  =====  ====================================================
column          size   what
==============  =====  ====================================================
POSITION        3      world position
INTENSITY       3      radiant intensity per channel, W/sr (on the axis)
AXIS            3      the spot's unit axis
COS_CUTOFF      1      cos of the cutoff angle (-2: no cone)
COS_BEAM        1      cos of the beam width (-2: no cone)
CUTOFF          1      the cutoff angle, radians
INV_TRANSITION  1      1 / (cutoff - beam width) (0 without a ramp)
IMAGE           1      the table row of its image's header (-1: no image)
==============  =====  ====================================================
"""

from __future__ import annotations

import math

import numpy as np

from ...jit import jit
from ...plugins import LightTechnique, register
from ..projected_images import MAX_TABLE_FLOATS, image_factor

NAME = "point"
POSITION, INTENSITY, AXIS, COS_CUTOFF, COS_BEAM, CUTOFF, INV_TRANSITION, IMAGE = 0, 3, 6, 9, 10, 11, 12, 13
WIDTH = 14
NO_CONE = -2.0  # the cosines of a light without a cone: every direction is inside
# Every light sampling: a point light is sampled one way whatever the others are.
PLUGIN = register(LightTechnique(NAME, code=1, module=__name__, rank=1, dims=0, emitters=("point",),
                                 light_samplings=("*",), width=WIDTH, delta=True,
                                 doc="the direction to the point (a delta light)"))


def rows(emitters) -> np.ndarray:
    """``(P, WIDTH)`` rows of P point lights (``emitters.PointEmitters``)."""
    count = len(emitters.position)
    out = np.zeros((count, WIDTH))
    out[:, POSITION:POSITION + 3] = emitters.position
    out[:, INTENSITY:INTENSITY + 3] = emitters.intensity
    out[:, AXIS:AXIS + 3] = emitters.spot_axis
    cutoff = np.asarray(emitters.cutoff, dtype=np.float64)
    beam = np.minimum(np.asarray(emitters.beam, dtype=np.float64), cutoff)
    cone = cutoff < np.pi
    out[:, COS_CUTOFF] = np.where(cone, np.cos(cutoff), NO_CONE)
    out[:, COS_BEAM] = np.where(cone, np.cos(beam), NO_CONE)
    out[:, CUTOFF] = cutoff
    ramp = cone & (cutoff > beam)
    out[:, INV_TRANSITION] = np.where(ramp, 1.0 / np.where(ramp, cutoff - beam, 1.0), 0.0)
    out[:, IMAGE] = -1.0  # linked by ``appendix``
    return out


def appendix(emitters, start: int) -> tuple[np.ndarray, np.ndarray, int]:
    """The rows of the lights' images, to follow the table's rows from row ``start``
    (``tracer.lights.build_tables``): ``(link (P,), rows (m, 16), IMAGE)``, link the row of
    light i's image header (-1 without one), written into column IMAGE of its row."""
    link = np.full(len(emitters.position), -1.0)
    blocks = []
    row = start
    for i, image in enumerate(emitters.images):
        if image is None:
            continue
        block = image.block()
        link[i] = row
        blocks.append(block)
        row += len(block)
    if row * 16 > MAX_TABLE_FLOATS:
        from ...errors import InputError

        raise InputError(f"the lights' images hold {row * 16:,} numbers with the light table; tracer's "
                         f"table holds {MAX_TABLE_FLOATS:,} (use smaller images)", "lights")
    return link, (np.concatenate(blocks) if blocks else np.zeros((0, 16), np.float32)), IMAGE


@jit
def falloff(rows, k: int, cos_theta: float) -> float:
    """The spot falloff of row ``k`` at cos theta from its axis (module docstring)."""
    if not cos_theta > rows[k, COS_CUTOFF]:
        return 0.0
    if cos_theta >= rows[k, COS_BEAM]:
        return 1.0
    return (rows[k, CUTOFF] - math.acos(min(cos_theta, 1.0))) * rows[k, INV_TRANSITION]


@jit
def sample(rows, k: int, x, n, u0: float, u1: float):
    """The direction from ``x`` to point light row ``k``: ``(wi, dist, le, 1, True)``, le = I
    falloff / d^2; le and pdf 0 if the light is at x."""
    lx, ly, lz = rows[k, POSITION] - x[0], rows[k, POSITION + 1] - x[1], rows[k, POSITION + 2] - x[2]
    d = math.sqrt(lx * lx + ly * ly + lz * lz)
    if d <= 0.0:
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0, True
    inv_d = 1.0 / d
    wi = (lx * inv_d, ly * inv_d, lz * inv_d)
    # The spot's axis against the direction from the light to x, -wi.
    scale = inv_d * inv_d * falloff(rows, k, -(rows[k, AXIS] * wi[0] + rows[k, AXIS + 1] * wi[1]
                                               + rows[k, AXIS + 2] * wi[2]))
    le = (rows[k, INTENSITY] * scale, rows[k, INTENSITY + 1] * scale, rows[k, INTENSITY + 2] * scale)
    if rows[k, IMAGE] >= 0.0 and scale > 0.0:
        r, g, b = image_factor(rows, int(rows[k, IMAGE]), -wi[0], -wi[1], -wi[2])
        le = (le[0] * r, le[1] * g, le[2] * b)
    return wi, d, le, 1.0, True


@jit
def pdf(rows, k: int, x, n, wi, dist: float) -> float:
    """No ray finds a point light: 0."""
    return 0.0
