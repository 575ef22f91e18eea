"""The shading point of a camera hit: where it is, which way its normals face, its material.

The first of the estimator's steps for every camera lane (``tracer.estimator.kernels``): from
the primitive a camera ray hit, the point (where the ray meets the triangle's plane or the
sphere, in float64: Embree's own distance is float32), the geometric normal of the primitive's
front, and, for a surface that reflects, the shading frame: z is the shading normal (the face
normal, or for a smooth mesh the interpolation of its vertex normals at the hit), flipped
toward the viewer for a two-sided material, whose hit from behind then shades with the row
``behind`` names (the material's own, or for an interface with an inside, a row of its
parameters seen from inside); a one-sided material seen from behind its shading normal
reflects nothing (``MaterialTable.twosided``, ``MaterialTable.shading``). The geometric normal,
turned toward the viewer, decides what is geometric: which side emits, where rays start, the
normal the light techniques see.
"""

from __future__ import annotations

from .. import materials
from ..frame import basis, dot, scale, to_local
from ..geometry import shading_normal, surface_point
from ..jit import jit


@jit
def at_hit(hit_table, first_sphere: int, kinds, behind, corner_normals, p: int, o, d):
    """The shading point of the ray ``o + t d`` (d unit) that hit primitive ``p``:
    ``(reflects, cos_view, x, geometric, normal, s, t, wo, material, kind)``.

    cos_view : -d . the face normal (> 0: the ray meets the front, which is what emits).
    x : the point (world).   geometric : the face normal turned toward the viewer.
    normal, s, t : the shading frame (world unit vectors; normal is its z).
    wo : the direction toward the viewer in that frame (wo.z > 0).
    material, kind : the row that shades the hit (``behind`` from behind) and its code.
    reflects : False where nothing is reflected (no material, a grazing ray, a one-sided
        material seen from behind): the frame is then not computed."""
    x, face_normal, cos_d = surface_point(hit_table, first_sphere, p, o, d)
    cos_view = -cos_d
    material = int(hit_table[p, 15])
    kind = kinds[material]
    nothing = (0.0, 0.0, 0.0)
    if kind == materials.NONE or cos_view == 0.0:
        return False, cos_view, x, nothing, nothing, nothing, nothing, nothing, material, kind
    geometric = scale(1.0 if cos_view > 0.0 else -1.0, face_normal)
    normal = shading_normal(corner_normals, hit_table, first_sphere, p, x, face_normal)
    cos_shading = -dot(d, normal)
    if cos_shading < 0.0 and behind[material] >= 0:
        normal = scale(-1.0, normal)
        material = int(behind[material])
    elif not cos_shading > 0.0:
        return False, cos_view, x, geometric, normal, nothing, nothing, nothing, material, kind
    s, t = basis(normal)
    wo = to_local(s, t, normal, scale(-1.0, d))
    return True, cos_view, x, geometric, normal, s, t, wo, material, kind
