"""Kernels compiled for what a render uses.

A render's **feature set** (:class:`FeatureSet`) is known before it starts: the material types
of its scene, the light techniques its emitters get, its light selection, sampler, direction
technique and combiner, and whether it learns. :func:`build` gives the feature set's
:class:`~tracer.kernels.templates.Build`: copies of the estimator's templates whose calls into
plug-ins go through a dispatch namespace holding only those plug-ins
(``tracer.kernels.dispatch``), compiled on first use and cached on disk under a name that
carries the feature set's key. So a scene of diffuse walls under one quad light compiles no
microfacet model, no Sobol sampler, no light BVH and no resampling, and two feature sets never
share a stale cache entry. ``tracer.kernels.compiling`` compiles a build's kernels (several in
parallel where there are cores) and says so on a terminal while it does.

    features = FeatureSet.of(scene, strategy, sampler, techniques)
    made = build(features)
    shade = made.function(estimator.kernels.shade)   # a numba dispatcher
"""

from __future__ import annotations

import hashlib
import threading
import types
from dataclasses import asdict, dataclass

from .. import plugins
from .templates import UNBOUND, Build, Template, kernel, template, template_called

__all__ = ["UNBOUND", "Build", "FeatureSet", "Template", "build", "kernel", "template", "template_called"]


@dataclass(frozen=True)
class FeatureSet:
    """What a render's kernels need, by plug-in name.

    materials : the material types of the scene's table (by code).   light_techniques : the
    techniques of its light candidates (by code).   light_selection, sampler : one each.
    direction : the direction technique, None without direction samples.   combiner : one.
    light_samples, direction_samples : the strategy takes samples of that technique.
    learns : the estimator learns between passes (``tracer.tuning``).
    textures : some material parameter of the scene is textured (``tracer.textures``).
    environment : the scene has an environment light (``tracer.lights.environment``): rays
        that escape see it, and it may be light-sampled.
    environment_product : light samples of the environment are drawn by product sampling
        (``tracer.lights.environment_product``): the shading point's lobe proxy is computed, and
        direction samples carry the environment's pdf of their direction.
    shared : a build that renders of many scenes share (``widened``): every material and
        technique, each called rather than inlined, so that all such builds link one compiled
        copy of each instead of compiling them into every kernel.
    """

    materials: tuple[str, ...]
    light_techniques: tuple[str, ...]
    light_selection: str
    sampler: str
    direction: str | None
    combiner: str
    light_samples: bool
    direction_samples: bool
    learns: bool
    shared: bool = False
    textures: bool = False
    environment: bool = False
    environment_product: bool = False

    @property
    def key(self) -> str:
        """12 hex digits of SHA-256 of the feature set and of the sources of the users' plug-ins
        in it (``plugins.foreign``): the cache entries' names carry it."""
        text = repr(sorted(asdict(self).items())) + repr(plugins.foreign(self.records()))
        return hashlib.sha256(text.encode()).hexdigest()[:12]

    def records(self) -> list[plugins.Plugin]:
        """The plug-in record of every name in this feature set."""
        named = ([("material", m) for m in self.materials]
                 + [("light_technique", t) for t in self.light_techniques])
        named += [("light_selection", self.light_selection), ("sampler", self.sampler),
                  ("combiner", self.combiner)]
        if self.direction is not None:
            named.append(("direction", self.direction))
        return [plugins.get(kind, name) for kind, name in named]

    def flags(self) -> dict[str, bool]:
        """The compile-time switches of the templates (``tracer.kernels.dispatch``)."""
        selection = plugins.get("light_selection", self.light_selection)
        return {"LIGHT_SAMPLES": self.light_samples, "DIRECTION_SAMPLES": self.direction_samples,
                "LEARNS": self.learns, "RESAMPLES": plugins.get("combiner", self.combiner).resamples,
                "PER_POINT_SELECTION": bool(getattr(selection, "per_point", False)),
                "TEXTURES": self.textures, "ENVIRONMENT": self.environment,
                "PRODUCT": self.environment_product,
                "TRANSMITS": any(getattr(plugins.get("material", m), "transmits", False)
                                 for m in self.materials)}

    def without(self, fields: tuple[str, ...]) -> "FeatureSet":
        """This feature set with ``fields`` at fixed defaults (no materials or techniques, the
        default selection and sampler, no directions, ``sum``, flags off): what a kernel that
        ignores them is built for (``templates.Template.ignores``)."""
        from dataclasses import replace

        defaults = {"materials": (), "light_techniques": (), "light_selection": "power",
                    "sampler": "independent", "direction": None, "combiner": "sum", "light_samples": False,
                    "direction_samples": False, "learns": False, "textures": False,
                    "environment": False, "environment_product": False}
        unknown = set(fields) - set(defaults)
        if unknown:
            raise ValueError(f"no feature-set field {sorted(unknown)[0]!r} to ignore")
        return replace(self, **{name: defaults[name] for name in fields})

    def widened(self) -> "FeatureSet":
        """This feature set with every registered material and light technique, ``shared``: the
        build that renders of many scenes share (``shared_builds``). Textures and the
        environment stay as the scene needs them: such a scene's build is another shared build,
        so that the many scenes without them keep compiling (and running) kernels without the
        lookups."""
        from dataclasses import replace

        return replace(self, materials=plugins.names("material"),
                       light_techniques=plugins.names("light_technique"), shared=True)

    def describe(self) -> str:
        """One line of what is compiled: ``diffuse, roughconductor; triangle_area; power; ...``."""
        environment = "environment by product" if self.environment_product else "environment"
        lights = self.light_techniques + ((environment,) if self.environment else ())
        parts = [", ".join(self.materials) or "no materials", ", ".join(lights) or "no lights",
                 f"{self.light_selection} selection", f"{self.sampler} sampler",
                 f"{self.combiner}" + (f" with {self.direction} directions" if self.direction else "")]
        if self.learns:
            parts.append("learning")
        if self.textures:
            parts.append("textures")
        return "; ".join(parts)


# ``TRACER_KERNELS=shared``: every render's feature set takes every material and light technique
# (``FeatureSet.widened``), so that renders of many scenes (a test suite, a study) share one build
# per strategy and sampler instead of compiling one per scene. The kernels give the same bits
# (tests/test_kernels.py); they call the materials and techniques instead of inlining them, which
# costs render time (about 8%) and saves most of each build's compilation.
# Without the variable: per scene, unless a command that renders many scenes asked for shared
# builds (``prefer_shared``: ``tracer check`` and ``tracer stability``, whose dozens of scenes
# would otherwise compile a build each; measured: stability over 15 min from an empty cache).
SHARED_BUILDS_VARIABLE = "TRACER_KERNELS"
_default_mode = "scene"


def prefer_shared() -> None:
    """Make shared builds this process's default (``TRACER_KERNELS`` still decides if set)."""
    global _default_mode
    _default_mode = "shared"


def shared_builds() -> bool:
    """Whether renders share one build per strategy and sampler (``SHARED_BUILDS_VARIABLE``,
    else the process's default, ``prefer_shared``)."""
    import os

    value = os.environ.get(SHARED_BUILDS_VARIABLE, _default_mode)
    if value not in ("scene", "shared"):
        from ..errors import InputError

        raise InputError(f"{SHARED_BUILDS_VARIABLE}={value[:40]!r}: expected 'scene' or 'shared'",
                         "environment")
    return value == "shared"


_BUILDS: dict[FeatureSet, Build] = {}
_LOCK = threading.Lock()


def build(features: FeatureSet) -> Build:
    """The build of ``features`` (made once per process; its functions compile on first call)."""
    with _LOCK:
        made = _BUILDS.get(features)
        if made is None:
            from . import dispatch

            key = features.key
            namespace = types.ModuleType(f"tracer.kernels.dispatch__{key}")
            made = Build(key, namespace, features.flags())
            dispatch.fill(made, features)
            _BUILDS[features] = made
        return made
