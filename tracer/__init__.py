"""tracer: a small, exact and fast direct-lighting path tracer for comparing sampling strategies.

The Python API (``tracer/api.py``)::

    import tracer
    scene = tracer.load_scene("scene.toml")             # or a dict with the file's tables
    image = tracer.render(scene, strategy="mis", spp=64, seed=0)
    image.mean, image.variance_of_mean                  # (H, W, 3) float64 arrays
    image.write("out.exr")                              # EXR with variance, PNG beside it
    tracer.compare(image, tracer.read_image("reference.exr"))

load_scene(source, width=None, height=None, base_dir=None, notify=None) -> Scene   (.toml or Mitsuba .xml)
render(scene, strategy="mis", spp=64, seed=0, **options) -> Image
read_image(path) -> Image
compare(image, reference, seconds=None) -> dict of mse, relmse, variance, efficiency
Strategy(name, heuristic, light_samples, bsdf_samples, one_sample, light_selection, light_sampling,
         allocation, environment_sampling)
Strategy.ris(candidates, sources, **fields) -> the ris strategy
STRATEGIES, LIGHT_SAMPLINGS, LIGHT_SELECTIONS : the strategy, light-sampling and selection names.

The renderer core is the rest of this package (scene, materials, lights, samplers,
estimator, render_loop, film, imagefiles); the study tools (compare, check, stability, primer)
are ``tracer.study``. Names are loaded on first use, so ``import tracer`` and
``tracer --help`` stay fast.
"""

from __future__ import annotations

import importlib
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("tracer")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+source"

_API = {"Image": "api", "Scene": "scene", "Strategy": "strategy", "STRATEGIES": "strategy",
        "LIGHT_SAMPLINGS": "strategy", "LIGHT_SELECTIONS": "strategy", "compare": "api",
        "load_scene": "scene", "read_image": "api", "render": "api", "InputError": "errors"}
__all__ = sorted(_API)


def __getattr__(name: str):
    # PEP 562: the API is imported when first asked for, not at ``import tracer``, so that the
    # command line starts without loading numba.
    if name in _API:
        value = getattr(importlib.import_module(f".{_API[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'tracer' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
