"""Plug-ins: one module a technique, and one registry a kind.

Every material, light technique, light selection, sampler, direction technique and combiner is
one module that declares itself with a record of its kind (``register(...)`` at module level):
its name (as scene files and the command line spell it), its code where kernels dispatch on
one per primitive (materials, light techniques), the compiled functions of its kind's
interface, and how many random numbers one use of it draws. The kernels' dispatch over the
plug-ins a render uses is generated from these records (``tracer.kernels``), never written by
hand, in the manner of Nori's ``NORI_REGISTER_CLASS`` and Mitsuba's plugin files.

=================  =========================  ====================================================
kind               package                    compiled interface (per lane)
=================  =========================  ====================================================
material           ``tracer.materials``       ``eval_pdf``, ``sample`` (``materials/base.py``)
light_technique    ``tracer.lights.techniques``  ``sample``, ``pdf`` (``lights/techniques/__init__``)
light_selection    ``tracer.lights.selections``  ``choose``, ``pmf`` (``lights/selections/__init__``)
sampler            ``tracer.samplers``        ``start``, ``uniform``, ``uniform_pair``
direction          ``tracer.directions``      ``sample``, ``pdf``
combiner           ``tracer.estimator.combiners``  ``counts``, ``weight``
=================  =========================  ====================================================

A kind's package imports every module in it (``discover``), so a new plug-in is one new file
there; a user's own plug-ins register the same way from wherever they are imported.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import Any

KINDS = ("material", "light_technique", "light_selection", "sampler", "direction", "combiner")
# The functions each kind's modules must define (compiled), checked at registration.
INTERFACE = {"material": ("eval_pdf", "sample"), "light_technique": ("sample", "pdf"),
             "light_selection": ("choose", "pmf"), "sampler": ("start", "uniform", "uniform_pair"),
             "direction": ("sample", "pdf"), "combiner": ("counts", "weight")}
# Where the built-in plug-ins of each kind live (``discover`` imports every module there).
PACKAGES = {"material": "tracer.materials", "light_technique": "tracer.lights.techniques",
            "light_selection": "tracer.lights.selections", "sampler": "tracer.samplers",
            "direction": "tracer.directions", "combiner": "tracer.estimator.combiners"}


@dataclass(frozen=True)
class Plugin:
    """What every plug-in declares (its kind's record adds what that kind needs).

    name : as files and options spell it.
    code : the code kernels dispatch on, where they dispatch per primitive (materials > 0, whose
        0 is the black material; light techniques); kinds that a render fixes once leave it 0.
    module : the module (its ``__name__``) that holds the compiled functions of the interface.
    dims : random numbers one use draws (a light technique: per light sample; a selection: per
        choice; a direction technique: per direction sample, the lobe choice included).
    doc : one line for help texts and the reference pages.
    rank : where it stands in listings (help texts, choices): by rank, then name; the default
        of its kind has rank 0.
    kind : one of ``KINDS`` (each kind's record sets it).
    """

    name: str
    code: int = 0
    module: str = ""
    dims: int = 0
    doc: str = ""
    rank: int = 50
    kind: str = ""

    def functions(self) -> ModuleType:
        """The module with the compiled functions (imported)."""
        return importlib.import_module(self.module)


@dataclass(frozen=True)
class LightTechnique(Plugin):
    """A way to sample a direction toward one emitter candidate.

    emitters : the emitter kinds it samples (``triangle``, ``rectangle``, ``sphere``,
        ``point``; ``tracer.lights.emitters``).   light_samplings : the ``--light-sampling``
        values that choose it for those emitters.   width : float32 columns of its table row
        (at most ``lights.ROW_WIDTH``), which ``rows(emitters)`` in its module fills.
    delta : its samples are of a delta light (no other technique can produce them).
    """

    emitters: tuple[str, ...] = ()
    light_samplings: tuple[str, ...] = ()
    width: int = 0
    delta: bool = False
    kind: str = "light_technique"


@dataclass(frozen=True)
class LightSelection(Plugin):
    """A way to choose which emitter candidate a light sample samples.

    per_point : its pmf depends on the shading point (a light BVH), so a BSDF sample's MIS
        weight recomputes it; else it is the table's ``pmf``.
    """

    per_point: bool = False
    kind: str = "light_selection"


@dataclass(frozen=True)
class Sampler(Plugin):
    """A source of a render's random numbers.

    replicates : independently randomized replicates per pixel (0: the samples are independent,
        ``tracer.film``).   max_samples : one past the largest sample index it can draw.
    """

    replicates: int = 0
    max_samples: int = 2**53
    kind: str = "sampler"


@dataclass(frozen=True)
class DirectionTechnique(Plugin):
    """A way to sample a direction at a shading point (the hemisphere, the material's lobes)."""

    kind: str = "direction"


@dataclass(frozen=True)
class Combiner(Plugin):
    """How a shading point's light and direction samples add up (sum, MIS, one-sample MIS, RIS).

    resamples : keeps one candidate per shading point (``ris``): light candidates go to a
        reservoir and the kernels add a resampling stage (``tracer.estimator.combiners.ris``).
    """

    resamples: bool = False
    kind: str = "combiner"


LIGHT_ROW_WIDTH = 16  # float32 columns of a light table row (``tracer.lights.ROW_WIDTH``)
_REGISTRY: dict[str, dict[str, Plugin]] = {kind: {} for kind in KINDS}
_DISCOVERED: set[str] = set()


def register(plugin: Plugin) -> Plugin:
    """Add ``plugin`` to its kind's registry and return it. Raises ValueError if its kind is
    unknown or its name or code is taken by another module. (Whether its module has the kind's
    functions, ``INTERFACE``, is checked when a render first uses it: the module is still being
    imported here.) Registering the same module again (a reload) replaces its record."""
    if plugin.kind not in KINDS:
        raise ValueError(f"unknown plug-in kind {plugin.kind!r}; expected one of {', '.join(KINDS)}")
    if plugin.kind == "material" and plugin.code <= 0:
        raise ValueError(f"material {plugin.name!r} has code {plugin.code}; "
                         "codes are > 0 (0 is the black material)")
    if isinstance(plugin, LightTechnique):
        # The kernels give a technique two random numbers and a row of one 64-byte cache line
        # (``tracer.lights``); a technique that needs more needs the dimension map widened.
        if plugin.dims > 2 or plugin.width > LIGHT_ROW_WIDTH:
            raise ValueError(f"light technique {plugin.name!r} asks for {plugin.dims} random numbers and "
                             f"{plugin.width} row columns; the kernels give at most 2 and {LIGHT_ROW_WIDTH}")
    registry = _REGISTRY[plugin.kind]
    for other in registry.values():
        if other.module == plugin.module:
            continue
        if other.name == plugin.name:
            raise ValueError(f"{plugin.kind} {plugin.name!r} of {plugin.module} is already {other.module}'s")
        if other.code == plugin.code and plugin.kind in ("material", "light_technique"):
            raise ValueError(f"{plugin.kind} code {plugin.code} of {plugin.module} is already "
                             f"{other.name!r}'s ({other.module})")
    registry.pop(next((n for n, p in registry.items() if p.module == plugin.module and n != plugin.name), ""),
                 None)
    registry[plugin.name] = plugin
    return plugin


def foreign(records) -> tuple[tuple[str, str], ...]:
    """``(module, digest)`` of each of ``records``' modules that is not tracer's own (a user's
    plug-in), by module name; the digest is SHA-256 of the module's source file, so that a
    build's key changes when that file does (tracer's own files are in the cache's key already,
    ``tracer.jit.source_digest``; numba's cache would not see a change in another module)."""
    import hashlib
    from pathlib import Path

    found = {}
    for record in records:
        if record.module.split(".")[0] == "tracer" or record.module in found:
            continue
        path = getattr(importlib.import_module(record.module), "__file__", None)
        found[record.module] = hashlib.sha256(Path(path).read_bytes()).hexdigest() if path else "no file"
    return tuple(sorted(found.items()))


def check_interface(plugin: Plugin, module: Any) -> None:
    """Raise ValueError unless ``module`` defines every function of ``plugin``'s interface."""
    missing = [name for name in INTERFACE[plugin.kind] if not callable(getattr(module, name, None))]
    if missing:
        raise ValueError(f"{plugin.kind} {plugin.name!r} ({plugin.module}) lacks {', '.join(missing)}")


def discover(kind: str) -> None:
    """Import every module of ``kind``'s package (once), so that each registers itself."""
    if kind in _DISCOVERED:
        return
    package = importlib.import_module(PACKAGES[kind])
    for info in pkgutil.iter_modules(package.__path__):
        if not info.name.startswith("_"):
            importlib.import_module(f"{package.__name__}.{info.name}")
    # Marked only now: a package whose own import asks for its registry (while this loop is
    # still importing its modules) discovers them all first, instead of seeing a part.
    _DISCOVERED.add(kind)


def registry(kind: str) -> dict[str, Plugin]:
    """Name -> plug-in of ``kind``, every built-in one discovered, by rank, then name."""
    discover(kind)
    return dict(sorted(_REGISTRY[kind].items(), key=lambda item: (item[1].rank, item[0])))


def get(kind: str, name: str) -> Plugin:
    """The plug-in of ``kind`` called ``name``; ValueError naming the choices if there is none."""
    plugins = registry(kind)
    if name not in plugins:
        raise ValueError(f"unknown {kind.replace('_', ' ')} {name!r}; expected one of {', '.join(plugins)}")
    return plugins[name]


class Names(Sequence):
    """Names given by ``source()`` (a registry's, say), looked up each time they are read: a
    command-line parser built with them imports no plug-in module, and so no numba, until an
    option is checked or help is printed, and it offers a user's plug-ins registered later.
    ``str()`` lists them, comma-separated (for help texts)."""

    def __init__(self, source: Callable[[], Sequence[str]]):
        self._source = source

    def __getitem__(self, index):
        return tuple(self._source())[index]

    def __len__(self) -> int:
        return len(tuple(self._source()))

    def __iter__(self):
        return iter(tuple(self._source()))

    def __contains__(self, name: object) -> bool:
        return name in tuple(self._source())

    def __str__(self) -> str:
        return ", ".join(self._source())


class Live(Mapping):
    """A read-only view of one kind's registry that follows later registrations (a user's
    plug-in registered after tracer was imported): ``by`` is ``name`` or ``code``."""

    def __init__(self, kind: str, by: str = "name"):
        self.kind, self.by = kind, by

    def _current(self) -> dict:
        plugins = registry(self.kind)
        return plugins if self.by == "name" else {p.code: p for p in plugins.values()}

    def __getitem__(self, key):
        return self._current()[key]

    def __iter__(self):
        return iter(self._current())

    def __len__(self) -> int:
        return len(self._current())


def by_code(kind: str) -> dict[int, Plugin]:
    """Code -> plug-in of a kind that dispatches per primitive (materials, light techniques)."""
    return {p.code: p for p in registry(kind).values()}


def names(kind: str) -> tuple[str, ...]:
    """The names of ``kind``'s plug-ins, by rank, then name."""
    return tuple(registry(kind))


