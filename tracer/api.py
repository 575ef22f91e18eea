"""The Python API: load a scene, render it with a strategy, get arrays back, measure the error.

    import tracer
    scene = tracer.load_scene("cornell", width=64, height=64)   # a shipped scene, by name
    image = tracer.render(scene, strategy="mis", spp=16, seed=1)
    image.mean.shape        # (64, 64, 3) float64 pixel values (linear RGB radiance)
    image.variance_of_mean  # (64, 64, 3) their estimated variance
    reference = tracer.render(scene, strategy="mis", spp=256, seed=2)
    tracer.compare(image, reference)   # {'mse': ..., 'relmse': ..., 'variance': ..., ...}

Everything here calls the same code as the command line: ``tracer render`` is
:func:`render` followed by :meth:`Image.write`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from .film import Film
from .sampler_choice import DEFAULT_SAMPLER, SAMPLERS
from .scene import Scene, load_scene
from .strategy import DEFAULT_LIGHT_SAMPLING, DEFAULT_RIS_CANDIDATES, Strategy

__all__ = ["Image", "Scene", "Strategy", "compare", "load_scene", "read_image", "render"]


@dataclass
class Image:
    """A rendered image and its per-pixel statistics.

    mean : (H, W, 3) float64 pixel values: linear RGB radiance, the mean of each pixel's samples.
    variance : (H, W, 3) float64 unbiased variance of one sample's estimate per pixel.
    variance_of_mean : (H, W, 3) float64 variance of the pixel value (variance / count).
    count : (H, W) int64 samples per pixel.   spp : the smallest count.
    seconds : render wall time.   nonfinite : samples that came out NaN or infinite (set to 0).
    interrupted : Ctrl-C stopped the render early.   film : the underlying statistics, with
    the render record (``tracer.record``) that the EXR header stores.
    learned : (H, W) maps of what the render learned between passes (``tracer.tuning``), by
    name: ``allocation.light`` (adaptive allocation), ``alpha.R/G/B`` (optimal MIS); else empty.
    """

    mean: np.ndarray
    variance: np.ndarray
    variance_of_mean: np.ndarray
    count: np.ndarray
    spp: int
    seconds: float
    nonfinite: int
    interrupted: bool
    film: Film
    learned: dict[str, np.ndarray]

    @classmethod
    def of_film(cls, film: Film, seconds: float | None = None, nonfinite: int = 0,
                interrupted: bool = False) -> "Image":
        shape = (film.height, film.width, 3)
        return cls(film.image(), film.variance().reshape(shape), film.variance_of_mean().reshape(shape),
                   film.count.reshape(film.height, film.width), film.spp,
                   (film.record.seconds or 0.0) if seconds is None else seconds, nonfinite, interrupted, film,
                   {name: plane.reshape(film.height, film.width) for name, plane in film.learned.items()})

    def write(self, path: str | os.PathLike[str], exposure: float = 0.0, half: bool = False) -> None:
        """Write the EXR (mean, variance, render record) to ``path`` and a PNG preview beside it
        (same stem, ``exposure`` in stops)."""
        from pathlib import Path

        from .imagefiles import write_exr, write_png

        write_exr(path, self.film, half=half)
        write_png(Path(path).with_suffix(".png"), self.mean, exposure)


def render(scene: Scene | str | os.PathLike[str] | dict[str, Any], strategy: str | Strategy = "mis",
           spp: int = 64, seed: int = 0, *, threads: int | None = None, heuristic: str = "power",
           light_samples: int = 1, bsdf_samples: int = 1, one_sample: bool = False,
           light_selection: str = "power", light_sampling: str | None = None, sampler: str | None = None,
           ris_candidates: int = DEFAULT_RIS_CANDIDATES, ris_sources: str = "light",
           allocation: str = "fixed", environment_sampling: str = "luminance",
           progress: bool = False) -> Image:
    """Render ``scene`` (a :class:`Scene`, or a path or dict for :func:`load_scene`) with
    ``spp`` samples per pixel.

    strategy : ``uniform``, ``cosine``, ``bsdf``, ``light``, ``mis``, ``ris`` or ``auto`` (the
        one of light, bsdf and mis, with the light sampling and selection, that a pilot measures
        most efficient on the scene: ``tracer.auto``; the image's record says which), or a
        :class:`Strategy` (then the keyword options heuristic ... ris_sources are ignored).
    light_selection : ``power``, ``uniform`` or ``bvh`` (a light BVH: by an importance bound at
        the shading point; pays with many lights).
    ris_candidates, ris_sources : ``ris`` keeps one of ``ris_candidates`` candidates per camera
        sample, all light samples (``"light"``) or half of them BSDF samples (``"light+bsdf"``);
        light_samples and bsdf_samples are then not used (``Strategy.ris``).
    heuristic : ``balance``, ``power``, ``max`` or ``optimal`` (the balance heuristic plus a
        control variate each pixel learns from earlier passes: ``tracer.tuning``).
    allocation : ``fixed`` (light_samples and bsdf_samples per camera sample) or ``adaptive``
        (mis: each pixel splits that many samples as earlier passes say is best).
    light_sampling : ``area``, ``solid-angle`` or ``solid-angle-cos`` (default: the scene's
        ``[render] light_sampling``, else ``Strategy``'s default).
    environment_sampling : ``luminance``, ``uniform``, ``compensated`` (needs BSDF samples:
        mis, or ris with BSDF candidates) or ``product`` (luminance x the shading point's BSDF
        lobe): how the environment is light-sampled.
    sampler : ``independent``, ``stratified`` or ``sobol`` (default: the scene's ``[render]
        sampler``, else ``independent``); the variance is honest for each (``tracer.film``).
    seed : the same seed gives the same bits whatever ``threads`` (default: all cores).
    Raises ``ValueError`` for a bad option and ``tracer.errors.InputError`` for a bad scene.
    """
    from .render_loop import RenderSettings
    from .render_loop import render as render_film

    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if not isinstance(strategy, Strategy):
        # auto chooses the light sampling itself: a scene's [render] light_sampling is not for it.
        sampling = light_sampling if light_sampling is not None or strategy == "auto" else \
            scene.render_defaults.get("light_sampling", DEFAULT_LIGHT_SAMPLING)
        strategy = Strategy.from_options(strategy, heuristic=heuristic, light_samples=light_samples,
                                         bsdf_samples=bsdf_samples, one_sample=one_sample,
                                         light_selection=light_selection, light_sampling=sampling,
                                         allocation=allocation, ris_candidates=ris_candidates,
                                         ris_sources=ris_sources, environment_sampling=environment_sampling)
    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
        raise ValueError(f"spp must be a whole number >= 1, got {spp!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a whole number >= 0, got {seed!r}")
    sampler = sampler if sampler is not None else scene.render_defaults.get("sampler", DEFAULT_SAMPLER)
    if sampler not in SAMPLERS:
        raise ValueError(f"sampler must be one of {', '.join(SAMPLERS)}, got {sampler!r}")
    settings = RenderSettings(spp=int(spp), seed=int(seed), threads=threads or os.cpu_count() or 1,
                              sampler=sampler)
    result = render_film(scene, strategy, settings, progress=progress)
    return Image.of_film(result.film, result.seconds, result.nonfinite, result.interrupted)


def read_image(path: str | os.PathLike[str]) -> Image:
    """Read a render EXR (``tracer render``, ``tracer reference``) as an :class:`Image`."""
    from .imagefiles import read_exr

    return Image.of_film(read_exr(path))


def compare(image: Image, reference: Image, seconds: float | None = None) -> dict[str, float]:
    """The noise measures of ``image`` against ``reference`` (same resolution), as ``tracer
    compare`` reports them: ``mse`` = mean (I - R)^2, ``relmse`` = mean (I - R)^2 / (R^2 + 0.01),
    each less the reference's own variance (``tracer.study.metrics``: unbiased for the image's
    error; ``*_uncorrected`` as measured), ``variance`` = mean variance of the pixel value,
    ``efficiency`` = 1 / (relmse x seconds), NaN if relmse is not positive (seconds: the
    image's own unless given)."""
    from .study import metrics

    if image.mean.shape != reference.mean.shape:
        raise ValueError(f"image {image.mean.shape[:2]} and reference {reference.mean.shape[:2]} "
                         "differ in size")
    noise = reference.variance_of_mean
    relmse = metrics.relmse(image.mean, reference.mean, noise)
    seconds = image.seconds if seconds is None else seconds
    return {"mse": metrics.mse(image.mean, reference.mean, noise), "relmse": relmse,
            "variance": float(np.mean(image.variance_of_mean)),
            "efficiency": metrics.efficiency(relmse, seconds),
            "mse_uncorrected": metrics.mse(image.mean, reference.mean),
            "relmse_uncorrected": metrics.relmse(image.mean, reference.mean)}
