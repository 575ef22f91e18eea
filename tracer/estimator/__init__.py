"""The direct-lighting estimator: every strategy as a setting of one estimator.

    L(x, wo) = Le(x, wo) + integral f(x, wi, wo) Le(y(x, wi), -wi) |cos theta_i| dwi

Two techniques sample ``wi`` at a shading point: the *light* technique (``tracer.lights``:
choose an emitter, sample a direction toward it) and a *direction* technique
(``tracer.directions``: the hemisphere, or the material's own sampling), followed by a ray that
may hit an emitter. A strategy (``tracer.strategy``) is their counts, the direction technique,
the light selection and sampling, and the **combiner** that adds them up
(``tracer.estimator.combiners``: one technique alone, multi-sample MIS with Veach's weights
w_l = h(N p_l, M p_d), one-sample MIS, or RIS); with a single technique the weight is 1, and
whatever a technique cannot see (a point light from direction sampling, a mirror's reflection
from light sampling) contributes 0.

The package, by concern:

======================  ================================================================
module                  what
======================  ================================================================
``__init__.py``         :class:`DirectLighting`: the tables, the build, one batch's stages
``buffers.py``          what the kernels read and write (scene arrays, plan, ray buffers)
``shading_point.py``    a camera hit's point, normals, shading frame and material
``light_samples.py``    emitter sampling: one light sample and its value
``direction_samples.py``  direction sampling: one direction sample; what its hit adds
``counts.py``           how many samples of each technique a shading point takes
``cutouts.py``          rays through surfaces that stop a fraction of the light (masks)
``combiners/``          sum, mis, one_sample, ris: the plug-ins that combine them
``kernels.py``          the wavefront kernels ``shade`` and ``gather``
======================  ================================================================

Every random number is ``u(seed, pixel, sample index, dimension)`` from the render's sampler,
with the dimensions of ``tracer.samplers.dimensions``. The kernels are templates built for the
render's feature set (``tracer.kernels``): a scene of diffuse walls under one quad light
compiles no microfacet model, Sobol sampler, light BVH or resampling.
"""

from __future__ import annotations

import numpy as np

from .. import mis, plugins, samplers, tuning
from ..camera import lane_camera_rays
from ..embree import RayCaster
from ..geometry import SceneRays
from ..kernels import Build, FeatureSet, shared_builds
from ..kernels import build as build_kernels
from ..lights import LightSampler, technique_names
from ..samplers import dimensions
from ..scene import Scene
from ..strategy import Strategy
from ..tuning import Tuning
from . import kernels as estimator_kernels
from .buffers import CameraHits, Outputs, Plan, RayBuffer, Reservoirs, Surfaces
from .combiners import ris
from .cutouts import Cutouts, present

__all__ = ["DirectLighting", "Plan", "Surfaces", "combiner_of"]


def combiner_of(strategy: Strategy) -> str:
    """The combiner plug-in that runs ``strategy``: ``ris``; ``one_sample`` or ``mis`` where both
    techniques take samples; else ``sum`` (one technique alone)."""
    if strategy.name == "ris":
        return "ris"
    if strategy.light_count and strategy.direction_count:
        return "one_sample" if strategy.one_sample_mis else "mis"
    return "sum"


class DirectLighting:
    """The estimator for one scene and strategy, shared by all render threads (read-only)."""

    def __init__(self, scene: Scene, strategy: Strategy, caster: RayCaster | None = None):
        if strategy.name == "auto":
            raise ValueError("auto is a choice among strategies, not one: tracer.auto.choose makes it")
        self.scene = scene
        self.strategy = strategy
        self.rays = SceneRays(scene, caster)
        self.caster = self.rays.caster
        self.lights = LightSampler(scene, strategy.light_selection, strategy.light_sampling,
                                   strategy.environment_sampling)
        self.combiner = plugins.get("combiner", combiner_of(strategy))
        # ris's BSDF candidates find their emitter without the occluders.
        self.emitter_rays = SceneRays(scene, emitters_only=True) \
            if self.combiner.resamples and strategy.direction_count else None
        types = plugins.by_code("material")
        kind, params, behind = scene.materials.shading(types)
        own = len(scene.materials.kind)  # rows after these are inside rows (MaterialTable.shading)
        transmits = np.array([getattr(types.get(int(k)), "transmits", False) for k in kind], dtype=np.bool_)
        self.surfaces = Surfaces(np.ascontiguousarray(scene.hit_table), kind, params, behind,
                                 float(scene.ray_epsilon), int(scene.triangle_count),
                                 np.ascontiguousarray(scene.corner_normals),
                                 scene.textures.arrays(len(kind), scene.corner_uv, scene.sphere_frame,
                                                       {int(behind[m]): m for m in range(own)
                                                        if behind[m] >= own},
                                                       [getattr(types.get(int(k)), "rows", 1) for k in kind],
                                                       scene.textures.emission_by_primitive(
                                                           scene.shape_of_triangle, scene.shape_of_sphere)),
                                 transmits)
        # Rows past the table's (a two-sided type's inside) are never a primitive's own row.
        opacity = np.ones(len(kind))
        opacity[:len(scene.materials.opacity)] = scene.materials.opacity
        self.cutouts = Cutouts(self.rays, self.surfaces.hit_table, self.surfaces.first_sphere,
                               self.surfaces.eps, opacity, self.surfaces.textures) \
            if present(opacity, self.surfaces.textures.opacity) else None
        n_light, n_dir = strategy.light_count, strategy.direction_count
        one_sample = strategy.one_sample_mis
        total = 1.0 if one_sample else float(n_light + n_dir)
        self.plan = Plan(n_light, n_dir, mis.code(strategy.heuristic), one_sample,
                         n_light / (n_light + n_dir), strategy.learns_control_variate, strategy.adaptive,
                         total, n_light + n_dir if strategy.adaptive else n_light)

    @property
    def learns(self) -> bool:
        """Whether the render loop must learn between passes (``tracer.tuning``)."""
        return self.strategy.learns

    def features(self, sampler: str) -> FeatureSet:
        """What this estimator's kernels need with the sampler called ``sampler``."""
        by_code = plugins.by_code("material")
        materials = tuple(by_code[k].name for k in sorted(set(self.surfaces.material_kind.tolist()))
                          if k in by_code)
        strategy = self.strategy
        features = FeatureSet(materials, technique_names(self.lights.tables), self.lights.selection,
                              sampler, strategy.direction_technique if strategy.direction_count else None,
                              self.combiner.name, bool(strategy.light_count), bool(strategy.direction_count),
                              strategy.learns, textures=self.scene.textures.shading,
                              environment=self.scene.environment is not None,
                              environment_product=self.lights.tables.environment.candidate >= 0
                              and strategy.environment_sampling == "product" and bool(strategy.light_count))
        return features.widened() if shared_builds() else features

    def build(self, sampler: samplers.SamplerParams) -> Build:
        """The kernels' build for ``sampler`` (``tracer.kernels``; made once per feature set)."""
        return build_kernels(self.features(samplers.name_of(sampler)))

    def camera_rays(self, sampler: samplers.SamplerParams, pixel: np.ndarray,
                    sample: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The camera rays of lanes ``(pixel[i], sample[i])`` (``Camera.lane_rays``)."""
        rays = self.build(sampler).function(lane_camera_rays)
        return self.scene.camera.lane_rays(rays, sampler, pixel, sample, self.lens_dimension)

    @property
    def lens_dimension(self) -> int:
        """The sampler dimension of a thin lens's point: the pair after the most light and
        direction samples a camera sample takes (``samplers.dimensions``)."""
        plan = self.plan
        directions = max(plan.n_dir, plan.light_slots) if plan.adaptive else plan.n_dir
        return dimensions.lens(plan.light_slots, directions)

    def radiance(self, origins: np.ndarray, dirs: np.ndarray, seed: int = 0, pixel: np.ndarray | None = None,
                 sample: np.ndarray | None = None, sampler: str = "independent") -> np.ndarray:
        """Radiance along rays ``origins, dirs (n, 3)`` (dirs unit length): emission seen
        directly plus direct lighting, one Monte Carlo sample per ray, ``(n, 3)`` float64.

        Lane i draws its random numbers as sample ``sample[i]`` of pixel ``pixel[i]`` (``(n,)``
        int64; defaults: pixel = 0 .. n - 1, sample = 0, so every lane is independent) from
        ``sampler`` seeded with ``seed``, as a render of samples 0 .. max(sample) would (which
        sizes ``stratified``'s grid). Non-finite values are returned as they are.
        """
        n = len(origins)
        pixel = np.arange(n, dtype=np.int64) if pixel is None else np.asarray(pixel, dtype=np.int64)
        sample = np.broadcast_to(np.asarray(0 if sample is None else sample, dtype=np.int64), (n,))
        spp = int(sample.max()) + 1 if n else 1
        return self.shade_lanes(np.ascontiguousarray(origins, dtype=np.float32),
                                np.ascontiguousarray(dirs, dtype=np.float32),
                                samplers.make(sampler, seed, 0, spp), pixel, np.ascontiguousarray(sample))[0]

    def outputs(self, n: int, tuned: Tuning) -> Outputs:
        """What the ``shade`` kernel of ``n`` camera lanes writes, allocated (``buffers.py``)."""
        plan, resamples = self.plan, self.combiner.resamples
        slots = plan.light_slots
        shadow = RayBuffer.empty(n if plan.one_sample or resamples else n * slots)
        direction = RayBuffer.empty(n if plan.one_sample else n * (slots if plan.adaptive else plan.n_dir))
        # Optimal MIS needs each lane's C in every pass; the rest only while it is collected.
        wanted = plan.optimal or (plan.adaptive and tuned.collect)
        return Outputs(np.empty((n, 3)), shadow, direction, Reservoirs.empty(n if resamples else 0),
                       np.empty((n if wanted else 0, tuning.LANE_COLUMNS)))

    def shade_lanes(self, origins: np.ndarray, dirs: np.ndarray, sampler: samplers.SamplerParams,
                    pixel: np.ndarray, sample: np.ndarray,
                    tuned: Tuning | None = None,
                    rays: list | None = None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`radiance` for the render loop: float32 rays, a built sampler, int64 lanes,
        and what the pass applies (``tracer.tuning``; None: the pilot's settings). Returns the
        radiance ``(n, 3)`` (for optimal MIS, the balance estimate V, to which the render loop
        adds a C) and the lane statistics ``(n, tuning.LANE_COLUMNS)`` ((0, ...) unless the
        estimator learns). ``rays``, if given, has (shadow rays, direction rays) the lanes cast
        appended: the counts ``tracer.auto`` prices a strategy by."""
        made = self.build(sampler)
        tuned = tuned if tuned is not None else tuning.no_tuning()
        out = self.outputs(len(origins), tuned)
        radiance, shadow, direction, reservoirs, lane_stats = out
        tables = self.lights.tables
        prim = self.rays.first_hit(origins, dirs)
        if self.cutouts is not None:
            origins = np.array(origins)  # moved past the cutouts the lanes pass: the caller's stay
            self.cutouts.camera(prim, origins, dirs, pixel, sample, sampler.seed_key)
        n_shadow, n_direction = made.function(estimator_kernels.shade)(
            CameraHits(prim, origins, dirs, pixel, sample), sampler, self.surfaces, tables, self.plan, tuned,
            out)
        d = slice(0, n_direction)
        if self.combiner.resamples:
            # The BSDF candidates meet their emitters; one shadow ray per lane for the kept one.
            found = self.emitter_rays.first_hit(direction.origin[d], direction.dir[d]) if n_direction \
                else np.zeros(0, dtype=np.int32)
            n_shadow = made.function(ris.resample)(radiance, self.surfaces, tables, self.plan, direction,
                                                   found, shadow, reservoirs)
            d, found = slice(0, 0), found[:0]
        s = slice(0, n_shadow)
        blocked = self.rays.occluded(shadow.origin[s], shadow.dir[s], shadow.tmax[s])
        if self.cutouts is not None and blocked.any():
            self.cutouts.shadow(shadow.origin[s], shadow.dir[s], shadow.tmax[s], shadow.value[s],
                                shadow.v2[s], blocked)
        if not self.combiner.resamples:
            found = self.rays.first_hit(direction.origin[d], direction.dir[d])
            if self.cutouts is not None and n_direction:
                self.cutouts.direction(found, direction.origin[d], direction.dir[d], direction.value[d])
        made.function(estimator_kernels.gather)(radiance, self.surfaces, tables, self.plan, tuned, shadow,
                                                blocked, direction, found, lane_stats)
        if rays is not None:
            rays.append((int(n_shadow), int(n_direction)))
        return radiance, lane_stats

    def compile(self, sampler: samplers.SamplerParams, progress: bool = False) -> float:
        """Compile this estimator's kernels for ``sampler`` (or load them from the disk cache)
        before a render's clock starts, several at once where there are cores, with a progress
        line while they compile (``tracer.kernels.compiling``). Returns the seconds compiling
        took (0 when all were loaded)."""
        from ..kernels.compiling import Call, compile_all

        tuned = tuning.no_tuning()
        out = self.outputs(0, tuned)
        radiance, shadow, direction, reservoirs, lane_stats = out
        lanes = np.zeros(0, dtype=np.int64)
        rays = np.zeros((0, 3), dtype=np.float32)
        found = np.zeros(0, dtype=np.int32)
        tables = self.lights.tables
        calls = [Call((CameraHits(found, rays, rays, lanes, lanes), sampler, self.surfaces, tables, self.plan,
                       tuned, out), template=estimator_kernels.shade),
                 Call((radiance, self.surfaces, tables, self.plan, tuned, shadow, np.zeros(0, dtype=np.bool_),
                       direction, found, lane_stats), template=estimator_kernels.gather),
                 Call((sampler, lanes, lanes, self.lens_dimension, *self.scene.camera.screen),
                      template=lane_camera_rays)]
        if self.combiner.resamples:
            calls.append(Call((radiance, self.surfaces, tables, self.plan, direction, found, shadow,
                               reservoirs),
                              template=ris.resample))
        if self.cutouts is not None:
            calls.extend(self.cutouts.calls(sampler))
        features = self.features(samplers.name_of(sampler))
        return compile_all(features, calls, features.describe(), progress)
