"""What the estimator's kernels read and write: the scene's arrays, the strategy's settings and
the ray buffers between the wavefront's stages.

Plain arrays in named tuples, read by field once before each kernel's loop over lanes: reading
an array out of a tuple inside the loop costs a reference-count update (about 25 ns, measured
when the kernels were written), and arrays of floats are what Embree takes and returns.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..textures import Textures


class Surfaces(NamedTuple):
    """The scene as the kernels read it.

    hit_table : (F + S, 16) per primitive (``Scene.hit_table``): geometry, emission, material row.
    material_kind : (K,) int8 material codes.   material_params : (K, W) their parameters.
    behind : (K,) int64, the row that shades a hit seen from behind a material's shading
        normal: its own, -1 (black from behind), or its other side's (``MaterialTable.shading``).
    eps : ray offset along the normal (``Scene.ray_epsilon``).
    first_sphere : F, the primitive id of the first analytic sphere.
    corner_normals : (F, 9) vertex normals of smooth triangles, or (0, 9) (``Scene.corner_normals``).
    textures : the textures and what they feed (``tracer.textures.Textures``), read where the
        build has textures (``FeatureSet.textures``).
    transmits : (K,) bool, the row's type transmits with a density (``MaterialType.transmits``):
        its light samples take |cos theta_i| and no receiver bound (read where the build has
        such a type, ``TRANSMITS``).
    """

    hit_table: np.ndarray
    material_kind: np.ndarray
    material_params: np.ndarray
    behind: np.ndarray
    eps: float
    first_sphere: int
    corner_normals: np.ndarray
    textures: Textures
    transmits: np.ndarray


class Plan(NamedTuple):
    """A strategy's numbers as the kernels read them (its plug-ins are compiled in:
    ``tracer.kernels``).

    n_light, n_dir : samples per shading point of each technique (0 if unused); ris: candidates.
    heuristic : MIS heuristic code (``tracer.mis``).
    one_sample : one-sample MIS.   c_light : probability of the light technique in it.
    optimal : add up optimal MIS's control variate C per lane (``tracer.tuning``).
    adaptive : each pixel's expected light count comes from the tuning (``tracer.tuning``).
    total : technique samples per camera sample N (1 with one-sample MIS).
    light_slots : light samples a camera sample may take at most (where direction samples'
        dimensions begin).
    """

    n_light: int
    n_dir: int
    heuristic: int
    one_sample: bool
    c_light: float
    optimal: bool
    adaptive: bool
    total: float
    light_slots: int


class RayBuffer(NamedTuple):
    """Rays from shading points, written by the ``shade`` kernel, one row per sample that may
    contribute. Shadow and direction rays share the layout; each leaves the other's fields
    unwritten.

    origin, dir : (c, 3) float32 for Embree (dir unit length, world).
    tmax : (c,) float32 shadow-ray length (shadow rays only).
    value : (c, 3) what the sample adds if its ray is unblocked (shadow) or hits an emitter
        (direction; then times the emitter's radiance and the MIS weight).
    point, normal, shading : (c, 3) float64 shading point the ray leaves, its geometric and
        its shading normal (direction rays only): the light pdf of the direction is measured
        from them, as light sampling does.
    pdf : (c,) count-scaled pdf of the direction technique (direction rays only, for MIS).
    lane : (c,) camera lane the sample belongs to.   delta : (c,) a delta sample (weight 1).
    other : (c,) the (expected) light sample count of the shading point: the MIS weights of
        direction samples scale the light pdf by it.
    env_pdf : (c,) the environment's product-sampling pdf of the direction at its shading point
        (direction rays only, written only under product sampling: ``tracer.lights.
        environment_product``, whose pdf needs the point's material, which the ray does not carry).
    control, v2, t : (c,) what an unblocked light sample adds to ``tracer.tuning``'s statistics
        (its term of C, the mean square of its balance value over channels, p_l / (p_l + p_b));
        written only when the estimator learns.
    """

    origin: np.ndarray
    dir: np.ndarray
    tmax: np.ndarray
    value: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    shading: np.ndarray
    pdf: np.ndarray
    lane: np.ndarray
    delta: np.ndarray
    other: np.ndarray
    control: np.ndarray
    v2: np.ndarray
    t: np.ndarray
    env_pdf: np.ndarray

    @classmethod
    def empty(cls, count: int) -> "RayBuffer":
        f32 = np.float32
        return cls(np.empty((count, 3), dtype=f32), np.empty((count, 3), dtype=f32),
                   np.empty(count, dtype=f32), np.empty((count, 3)), np.empty((count, 3)),
                   np.empty((count, 3)), np.empty((count, 3)), np.empty(count),
                   np.empty(count, dtype=np.int64), np.empty(count, dtype=np.bool_),
                   np.empty(count), np.empty(count), np.empty(count), np.empty(count), np.empty(count))


class Reservoirs(NamedTuple):
    """Per camera lane, the candidates ris has seen (the kept one's ray is the lane's row of the
    shadow buffer): weight (n,) their sum of w_j; u (n,) the rescaled resampling uniform."""

    weight: np.ndarray
    u: np.ndarray

    @classmethod
    def empty(cls, count: int) -> "Reservoirs":
        return cls(np.empty(count), np.empty(count))


class CameraHits(NamedTuple):
    """A batch's camera lanes as the ``shade`` kernel reads them: prim (n,) int32 the primitive
    each camera ray hit (-1: none), origins and dirs (n, 3) float32, pixel and sample (n,) int64
    the lane's pixel and sample index."""

    prim: np.ndarray
    origins: np.ndarray
    dirs: np.ndarray
    pixel: np.ndarray
    sample: np.ndarray


class Outputs(NamedTuple):
    """What the ``shade`` kernel writes: radiance (n, 3), the shadow and direction rays, ris's
    reservoirs, and the learning's lane statistics ((0, ...) unless the estimator learns)."""

    radiance: np.ndarray
    shadow: RayBuffer
    direction: RayBuffer
    reservoirs: Reservoirs
    lane_stats: np.ndarray
