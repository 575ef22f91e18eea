"""The dispatch namespace of a feature set: what ``dispatch.NAME`` is in a built template.

For the plug-ins a render uses, one module object holds:

=========================================  ==============================================================
name                                       what
=========================================  ==============================================================
``material_eval_pdf(kind, params, row,     (f, pdf) of the material of code ``kind``: a generated chain of
wo, wi)``, ``material_sample(kind,         ``if kind == CODE`` branches over the scene's material types
params, row, wo, u_lobe, u0, u1)``         only (``tracer.materials``), black for any other code
``part_eval_pdf``, ``part_sample``         the same chains over the non-composite types: a blend's parts
                                           (``tracer.materials.blendbsdf``)
``material_lobe(kind, params, row, wo)``   (kd, ks, ku, alpha): the type's lobe proxy for product sampling
                                           of the environment (``tracer.lights.environment_product``),
                                           uniform for a type without one
``technique_sample(code, rows, k, x, n,    (wi, dist, le, pdf, delta) and the pdf of the light technique of
u0, u1)``, ``technique_pdf(code, rows,     ``code``: a generated chain over the techniques the scene's
k, x, n, wi, dist)``                       emitters use (``tracer.lights.techniques``)
``choose``, ``selection_pmf``              the light selection's (``tracer.lights.selections``)
``start``, ``uniform``, ``uniform_pair``   the sampler's (``tracer.samplers``)
``direction_sample``, ``direction_pdf``    the direction technique's (``tracer.directions``)
``counts``, ``weight``                     the combiner's (``tracer.estimator.combiners``)
=========================================  ==============================================================

Flags (plain booleans, also bound as globals of every built template, where numba drops the
branches they turn off before it compiles them): ``LIGHT_SAMPLES`` and ``DIRECTION_SAMPLES``
(the strategy takes any), ``LEARNS`` (a strategy that learns between passes: the kernels
gather ``tracer.tuning``'s statistics), ``RESAMPLES`` (``ris``: light candidates go to a
reservoir), ``PER_POINT_SELECTION`` (the selection's pmf depends on the shading point),
``PRODUCT`` (the environment is light-sampled by product: ``tracer.lights.environment_product``).

The chains are generated as source text, compiled with a file name that says what they are
(``<tracer dispatch …>``, registered in ``linecache`` so tracebacks show them) and inlined into
the kernels, whose cache entries hold them.
"""

from __future__ import annotations

import linecache
import types

from .. import jit as jit_module
from .. import plugins
from .templates import Build, Template


def _chain(name: str, arguments: str, selector: str, branches: list[tuple[int, str]], default: str) -> str:
    """The source of ``def NAME(ARGUMENTS)`` returning the call of the branch whose code equals
    ``selector``, else ``default``."""
    lines = [f"def {name}({arguments}):"]
    for code, call in branches:
        lines += [f"    if {selector} == {code}:", f"        return {call}"]
    lines.append(f"    return {default}")
    return "\n".join(lines) + "\n"


def _bind(build: Build, namespace: types.ModuleType, name: str, function) -> None:
    """``namespace.name`` = ``function``, or this build's copy of it if it is a template."""
    setattr(namespace, name, build.function(function) if isinstance(function, Template) else function)


def fill(build: Build, features) -> None:
    """Put the feature set's functions and flags into ``build.dispatch`` (module docstring)."""
    namespace = build.dispatch
    namespace.FEATURES = features
    for flag, value in features.flags().items():
        setattr(namespace, flag, value)
    source: list[str] = []

    materials = [plugins.get("material", name) for name in features.materials]
    for m in materials:
        if m.composite:  # its functions are templates over the part chains below: this build's copies
            module = _checked(m)
            built = types.ModuleType(f"{module.__name__}__{build.key}")
            for name in ("eval_pdf", "sample"):
                _bind(build, built, name, getattr(module, name))
            setattr(namespace, f"_material_{m.code}", built)
            continue
        module = _checked(m)
        setattr(namespace, f"_material_{m.code}", _called(module, ("eval_pdf", "sample") + _lobe_of(module))
                if features.shared else module)
    # The parts of a composite material (a blend's two) are of the other types: chains over those.
    for chain, over in (("material", materials), ("part", [m for m in materials if not m.composite])):
        source.append(_chain(f"{chain}_eval_pdf", "kind, params, row, wo, wi", "kind",
                             [(m.code, f"_material_{m.code}.eval_pdf(params, row, wo, wi)") for m in over],
                             "(0.0, 0.0, 0.0), 0.0"))
        source.append(_chain(f"{chain}_sample", "kind, params, row, wo, u_lobe, u0, u1", "kind",
                             [(m.code, f"_material_{m.code}.sample(params, row, wo, u_lobe, u0, u1)")
                              for m in over], "(0.0, 0.0, 1.0), (0.0, 0.0, 0.0), 0.0, 0"))

    # The lobe proxies of product sampling (``tracer.lights.environment_product``), where a type
    # has one; any other type (a blend too) is sampled by the map alone.
    source.append(_chain("material_lobe", "kind, params, row, wo", "kind",
                         [(m.code, f"_material_{m.code}.lobe(params, row, wo)") for m in materials
                          if not m.composite and _lobe_of(m.functions())],
                         "(0.0, 0.0, 1.0, 1.0)"))

    techniques = [plugins.get("light_technique", name) for name in features.light_techniques]
    for t in techniques:
        setattr(namespace, f"_technique_{t.code}", _called(_checked(t), ("sample", "pdf"))
                if features.shared else _checked(t))
    source.append(_chain("technique_sample", "code, rows, k, x, n, u0, u1", "code",
                         [(t.code, f"_technique_{t.code}.sample(rows, k, x, n, u0, u1)") for t in techniques],
                         "(0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0, False"))
    source.append(_chain("technique_pdf", "code, rows, k, x, n, wi, dist", "code",
                         [(t.code, f"_technique_{t.code}.pdf(rows, k, x, n, wi, dist)") for t in techniques],
                         "0.0"))

    filename = f"<tracer dispatch {build.key}: {features.describe()}>"
    text = "".join(source)
    linecache.cache[filename] = (len(text), None, text.splitlines(True), filename)
    exec(compile(text, filename, "exec"), namespace.__dict__)
    for name in ("material_eval_pdf", "material_sample", "part_eval_pdf", "part_sample", "material_lobe",
                 "technique_sample", "technique_pdf"):
        setattr(namespace, name, jit_module.jit_generated(getattr(namespace, name)))
    namespace.source = text

    # In a shared build the selection's and the sampler's functions are called copies too (their
    # own functions, not templates, so one compiled copy serves every build that uses them).
    selection = _checked(plugins.get("light_selection", features.light_selection))
    if features.shared and not any(isinstance(f, Template) for f in (selection.choose, selection.pmf)):
        selection = _called(selection, ("choose", "pmf"))
    _bind(build, namespace, "choose", selection.choose)
    _bind(build, namespace, "selection_pmf", selection.pmf)
    sampler = _checked(plugins.get("sampler", features.sampler))
    names = ("start", "uniform", "uniform_pair")
    if features.shared and not any(isinstance(getattr(sampler, n), Template) for n in names):
        sampler = _called(sampler, names)
    for name in names:
        _bind(build, namespace, name, getattr(sampler, name))
    if features.direction is not None:  # else DIRECTION_SAMPLES is off and nothing calls them
        direction = _checked(plugins.get("direction", features.direction))
        _bind(build, namespace, "direction_sample", direction.sample)
        _bind(build, namespace, "direction_pdf", direction.pdf)
    combiner = _checked(plugins.get("combiner", features.combiner))
    for name in ("counts", "weight"):
        _bind(build, namespace, name, getattr(combiner, name))


def _lobe_of(module: types.ModuleType) -> tuple[str, ...]:
    """``("lobe",)`` if a material's module has a lobe proxy for product sampling, else ()."""
    return ("lobe",) if callable(getattr(module, "lobe", None)) else ()


_CALLED: dict[str, types.ModuleType] = {}


def _called(module: types.ModuleType, names: tuple[str, ...]) -> types.ModuleType:
    """A module of ``module``'s functions ``names`` compiled to be called, not inlined (made
    once per process, so that every shared build links the same compiled copies, which numba
    also keeps in its disk cache)."""
    made = _CALLED.get(module.__name__)
    if made is None:
        made = _CALLED[module.__name__] = types.ModuleType(f"{module.__name__}__called")
        for name in names:
            function = getattr(module, name)
            setattr(made, name, jit_module.jit_called(getattr(function, "py_func", function)))
    return made


def _checked(plugin: plugins.Plugin) -> types.ModuleType:
    """The module of ``plugin``, which must define its kind's interface."""
    module = plugin.functions()
    plugins.check_interface(plugin, module)
    return module
