"""Direct lighting estimators: five strategies as settings of one estimator.

    L(x, wo) = Le(x, wo) + integral f(x, wi, wo) Le(y(x, wi), -wi) |cos theta_i| dwi

Two techniques sample ``wi`` at a shading point:

- the *light* technique (light.py): a point on an emitter, pdf converted to solid angle;
- a *direction* technique: ``uniform`` (1/2pi), ``cosine`` (cos/pi) or ``bsdf`` (the
  material's own sampling), followed by a ray that may hit an emitter.

A strategy is a pair of sample counts (Mitsuba's ``emitter_samples``/``bsdf_samples``):

=========  ==============  =================  =========================
strategy   light samples   direction samples  direction sampler
=========  ==============  =================  =========================
uniform    0               M                  uniform hemisphere
cosine     0               M                  cosine hemisphere
bsdf       0               M                  BSDF
light      N               0                  -
mis        N               M                  BSDF, weighted by a heuristic
=========  ==============  =================  =========================

Multi-sample MIS (Veach 1997, section 9.2) weights a light sample by
w_l = h(N p_l, M p_b) and a BSDF sample by w_b = h(M p_b, N p_l), each sample's contribution
divided by its own count. One-sample MIS (section 9.2.4) picks one technique per camera
sample with probability c_l = N / (N + M) and divides by c times its pdf; the weights use
c p. With a single technique the other count is 0 and the weight is 1.

Delta rule: a point light's sample and a mirror's sample get weight 1, because the other
technique produces them with probability 0. Whatever a technique cannot see (a point light
from BSDF or hemisphere sampling, a mirror's reflection from light sampling) contributes 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import mis, warp
from .bsdf import NONE, Bsdf
from .embree import RayCaster
from .frame import Frame
from .lights import LightSampler
from .scene import STRATEGIES, Scene

DIRECTION_SAMPLER = {"uniform": "uniform", "cosine": "cosine", "bsdf": "bsdf", "mis": "bsdf"}


@dataclass(frozen=True)
class Strategy:
    """How to estimate direct light: a strategy name and its sample counts.

    ``light_samples`` is used by ``light`` and ``mis``; ``bsdf_samples`` by ``uniform``,
    ``cosine``, ``bsdf`` and ``mis`` (it counts the direction samples of each).
    """

    name: str = "mis"
    heuristic: str = "power"
    light_samples: int = 1
    bsdf_samples: int = 1
    one_sample: bool = False
    light_selection: str = "power"

    def __post_init__(self) -> None:
        if self.name not in STRATEGIES:
            raise ValueError(f"unknown strategy {self.name!r}; expected one of {STRATEGIES}")
        if self.heuristic not in mis.HEURISTICS:
            raise ValueError(f"unknown heuristic {self.heuristic!r}; expected one of {mis.HEURISTICS}")
        if self.light_samples < 0 or self.bsdf_samples < 0:
            raise ValueError("sample counts must be >= 0")
        if self.light_count + self.direction_count == 0:
            raise ValueError(f"strategy {self.name!r} with these counts takes no samples")

    @property
    def label(self) -> str:
        """A short description such as ``mis (power, 1 light + 1 bsdf)``."""
        if self.name == "mis":
            mode = "one-sample, " if self.one_sample else ""
            return f"mis ({mode}{self.heuristic}, {self.light_samples} light + {self.bsdf_samples} bsdf)"
        count = self.light_count or self.direction_count
        return self.name if count == 1 else f"{self.name} (x{count})"

    @property
    def light_count(self) -> int:
        return self.light_samples if self.name in ("light", "mis") else 0

    @property
    def direction_count(self) -> int:
        return self.bsdf_samples if self.name != "light" else 0

    @property
    def direction_sampler(self) -> str | None:
        return DIRECTION_SAMPLER.get(self.name)


@dataclass
class Shading:
    """Shading points of the lanes that hit a surface with a material.

    lane : (m,) index of the camera lane each point belongs to.
    x : (m, 3) hit position.   origin : (m, 3) x offset along the normal toward the viewer.
    frame : shading frames, z = face normal flipped toward the viewer.
    wo : (m, 3) local direction toward the viewer (wo.z > 0).   bsdf : per-lane materials.
    """

    lane: np.ndarray
    x: np.ndarray
    origin: np.ndarray
    frame: Frame
    wo: np.ndarray
    bsdf: Bsdf

    def take(self, idx: np.ndarray) -> "Shading":
        return Shading(self.lane[idx], self.x[idx], self.origin[idx], self.frame.take(idx),
                       self.wo[idx], self.bsdf.take(idx))


def _repeated(sp: Shading, count: int) -> Shading:
    """Each shading point ``count`` times in a row (one lane per sample); no copy for 1."""
    return sp if count == 1 else sp.take(np.repeat(np.arange(len(sp.lane)), count))


class DirectLighting:
    """The estimator for one scene and strategy, shared by all render threads (read-only)."""

    def __init__(self, scene: Scene, strategy: Strategy, caster: RayCaster | None = None):
        self.scene = scene
        self.strategy = strategy
        self.caster = caster if caster is not None else RayCaster(scene.vertices, scene.faces)
        self.lights = LightSampler(scene, strategy.light_selection)
        self.eps = scene.ray_epsilon

    # -----------------------------------------------------------------------------------------
    # Camera rays -> radiance

    def radiance(self, origins: np.ndarray, dirs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Radiance along camera rays ``(n, 3)``: emission seen directly plus direct lighting.

        Returns ``(n, 3)`` float64, one Monte Carlo sample per ray. The caller guards against
        non-finite values.
        """
        n = len(origins)
        radiance = np.zeros((n, 3))
        hits = self.caster.intersect(origins, dirs)
        lane = np.flatnonzero(hits.prim >= 0)
        g = self.scene.hit_table[hits.prim[lane]]
        wo_world = -dirs[lane]
        cos_view = np.einsum("ij,ij->i", g[:, 9:12], wo_world)

        # --- Emitters seen directly (weight 1 in every strategy): front side only.
        radiance[lane] = g[:, 12:15] * (cos_view > 0.0)[:, None]

        # --- Shading points: surfaces with a material and a defined normal.
        keep = (g[:, 15] != NONE) & (cos_view != 0.0)
        if not np.all(keep):
            lane, g, wo_world, cos_view = lane[keep], g[keep], wo_world[keep], cos_view[keep]
        if len(lane) == 0:
            return radiance
        x = g[:, 0:3] + hits.u[lane, None] * g[:, 3:6] + hits.v[lane, None] * g[:, 6:9]
        normal = g[:, 9:12] * np.sign(cos_view)[:, None]
        frame = Frame.from_normal(normal)
        shading = Shading(lane, x, x + self.eps * normal, frame, frame.to_local(wo_world),
                          self.scene.materials.take(g[:, 15].astype(np.intp)))
        self._direct(shading, radiance, rng)
        return radiance

    # -----------------------------------------------------------------------------------------
    # Direct lighting at shading points

    def _direct(self, sp: Shading, radiance: np.ndarray, rng: np.random.Generator) -> None:
        """Add the direct-lighting estimate of every shading point to ``radiance[sp.lane]``."""
        st = self.strategy
        n_light, n_dir = st.light_count, st.direction_count
        m = len(sp.lane)
        if st.one_sample and n_light and n_dir:
            # One-sample MIS: each point takes one technique, chosen with probability c.
            c_light = n_light / (n_light + n_dir)
            pick_light = rng.random(m) < c_light
            lights_idx = np.flatnonzero(pick_light)
            dirs_idx = np.flatnonzero(~pick_light)
            self._accumulate(radiance, sp.lane[lights_idx], 1,
                             self._light_technique(sp.take(lights_idx), c_light, 1.0 - c_light, rng))
            self._accumulate(radiance, sp.lane[dirs_idx], 1,
                             self._direction_technique(sp.take(dirs_idx), 1.0 - c_light, c_light, rng))
            return
        if n_light:
            rep = _repeated(sp, n_light)
            self._accumulate(radiance, sp.lane, n_light, self._light_technique(rep, n_light, n_dir, rng))
        if n_dir:
            rep = _repeated(sp, n_dir)
            self._accumulate(radiance, sp.lane, n_dir, self._direction_technique(rep, n_dir, n_light, rng))

    @staticmethod
    def _accumulate(radiance: np.ndarray, lanes: np.ndarray, count: int, contribution: np.ndarray) -> None:
        """radiance[lanes] += the sum of each lane's ``count`` consecutive contribution rows.

        ``lanes`` are distinct (one per shading point), so a fancy-indexed add is exact;
        repeated samples of a point are consecutive rows (see ``_repeated``) and are summed
        with a reshape, never with the slow ``np.add.at``.
        """
        if count > 1:
            contribution = contribution.reshape(len(lanes), count, 3).sum(axis=1)
        radiance[lanes] += contribution

    def _light_technique(self, sp: Shading, own: float, other: float,
                         rng: np.random.Generator) -> np.ndarray:
        """One light sample per shading point: f Le |cos| w_l / (own p_l), ``(m, 3)``.

        ``own`` scales this technique's pdf (its sample count, or its selection probability in
        one-sample MIS), ``other`` the direction technique's; other = 0 gives weight 1.
        """
        m = len(sp.lane)
        u_select = rng.random(m)
        u_point = rng.random((m, 2))
        ls = self.lights.sample(u_select, u_point, sp.x)
        wi = sp.frame.to_local(ls.wi)
        f = sp.bsdf.eval(sp.wo, wi)
        cos_i = np.maximum(wi[:, 2], 0.0)
        safe_pdf = np.where(ls.pdf > 0.0, ls.pdf, 1.0)
        value = f * ls.radiance * (cos_i / (own * safe_pdf))[:, None]
        value[ls.pdf <= 0.0] = 0.0

        live = np.flatnonzero(np.any(value > 0.0, axis=1))
        if other > 0.0 and self.strategy.direction_sampler is not None and len(live):
            pdf_dir = self._direction_pdf(sp.bsdf, sp.wo, wi, live)
            w = mis.weight(self.strategy.heuristic, own * ls.pdf[live], other * pdf_dir)
            value[live] *= np.where(ls.delta[live], 1.0, w)[:, None]
            live = live[np.any(value[live] > 0.0, axis=1)]

        # --- Shadow rays from the offset origin to the sampled point, stopping short of it.
        target = sp.x[live] + ls.wi[live] * ls.dist[live, None]
        to_target = target - sp.origin[live]
        length = np.linalg.norm(to_target, axis=1)
        blocked = self.caster.occluded(sp.origin[live], to_target / length[:, None],
                                       np.maximum(length - self.eps, 0.0))
        value[live[blocked]] = 0.0
        return value

    def _direction_technique(self, sp: Shading, own: float, other: float,
                             rng: np.random.Generator) -> np.ndarray:
        """One direction sample per shading point, traced to the emitter it hits:
        f |cos| Le w_d / (own p_d), ``(m, 3)``. ``own``/``other`` as in the light technique."""
        m = len(sp.lane)
        u = rng.random((m, 2))
        sampler = self.strategy.direction_sampler
        if sampler == "bsdf":
            bs = sp.bsdf.sample(u, sp.wo)
            wi, weight, pdf, delta = bs.wi, bs.weight, bs.pdf, bs.delta
        else:
            if sampler == "uniform":
                wi = warp.sample_uniform_hemisphere(u)
                pdf = warp.pdf_uniform_hemisphere(wi)
            else:
                wi = warp.sample_cosine_hemisphere(u)
                pdf = warp.pdf_cosine_hemisphere(wi)
            f = sp.bsdf.eval(sp.wo, wi)
            safe_pdf = np.where(pdf > 0.0, pdf, 1.0)
            weight = np.where((pdf > 0.0)[:, None], f * (np.maximum(wi[:, 2], 0.0) / safe_pdf)[:, None], 0.0)
            delta = np.zeros(m, dtype=bool)
        value = weight / own

        live = np.flatnonzero(np.any(value > 0.0, axis=1))
        # Rotating every lane and dropping the dead ones is cheaper than gathering the frames of
        # the live ones when most are live (diffuse surfaces).
        if 2 * len(live) > m:
            wi_world = sp.frame.to_world(wi)[live]
        else:
            wi_world = sp.frame.take(live).to_world(wi[live])
        hits = self.caster.intersect(sp.origin[live], wi_world)
        found = hits.prim >= 0
        live, wi_world = live[found], wi_world[found]
        prim, dist = hits.prim[found], hits.t[found]
        s = self.scene
        g = s.hit_table[prim]
        front = np.einsum("ij,ij->i", g[:, 9:12], wi_world) < 0.0
        emitted = g[:, 12:15] * front[:, None]

        w = np.ones(len(live))
        if other > 0.0:
            pdf_light = self.lights.pdf(prim, wi_world, dist)
            w = np.where(delta[live], 1.0, mis.weight(self.strategy.heuristic, own * pdf[live],
                                                      other * pdf_light))
        result = np.zeros((m, 3))
        result[live] = value[live] * emitted * w[:, None]
        return result

    def _direction_pdf(self, bsdf: Bsdf, wo: np.ndarray, wi: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """pdf of the direction technique for light-sampled ``wi[idx]`` (for MIS weights)."""
        sampler = self.strategy.direction_sampler
        wi_i = wi[idx]
        if sampler == "uniform":
            return warp.pdf_uniform_hemisphere(wi_i)
        if sampler == "cosine":
            return warp.pdf_cosine_hemisphere(wi_i)
        return bsdf.take(idx).pdf(wo[idx], wi_i)
