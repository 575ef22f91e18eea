"""Templates: compiled code written once and built anew for each feature set.

A template is a plain Python function, written like any compiled per-lane function of tracer,
that calls the plug-ins of a render through the module-level name ``dispatch``
(``dispatch.material_eval_pdf(...)``, ``dispatch.uniform(...)``: ``tracer.kernels.dispatch``
says what each name does). It is never run as it is. :class:`Build` makes, for one feature set,
a copy of it whose ``dispatch`` is that feature set's namespace (the plug-ins the render uses,
and branch chains over only those), and compiles the copy with tracer's options
(``tracer.jit``). A template that calls other templates, directly or through their module
(``light_samples.add(...)``), gets their copies of the same build, so one kernel's whole call
tree is specialized; everything else it calls (frame math, a material's own functions) is
shared.

Why copies of a function and not one function per plug-in combination written out: numba
resolves a function's globals when it compiles it, so a copy with other globals is other
machine code, and the source is written once. Why this keeps numba's file cache working: a
copy's qualified name carries the feature set's key (``shade__3f9a...``), which names its cache
entry, and the cache entries of tracer's own files are keyed to the digest of all its sources
(``tracer.jit``), so two feature sets never share an entry and an edit invalidates both. The
dispatch chains themselves are generated source (``tracer.kernels.dispatch``), inlined into
the kernels whose cache entries hold them.
"""

from __future__ import annotations

import functools
import types
from collections.abc import Callable
from typing import Any

from .. import jit as jit_module


class Template:
    """A function to be compiled per feature set; calling it directly is an error.

    flavor : ``inline`` (inlined into its callers, as ``tracer.jit.jit``), ``called`` (a
    compiled call, as ``jit.jit_called``) or ``kernel`` (an entry point called from Python).
    ignores : for a kernel, the ``FeatureSet`` fields its code cannot depend on (a kernel that
    takes no sampler cannot draw from one): it is built for the feature set with those fields at
    their defaults (``FeatureSet.without``), so that feature sets differing only there share its
    compiled copy."""

    def __init__(self, py_func: Callable, flavor: str, ignores: tuple[str, ...] = ()):
        self.py_func = py_func
        self.flavor = flavor
        self.ignores = tuple(ignores)
        functools.update_wrapper(self, py_func)

    def __call__(self, *args: Any, **kwargs: Any):
        raise TypeError(f"{self.py_func.__qualname__} is a template: build it for a feature set first "
                        "(tracer.kernels.build)")

    def __repr__(self) -> str:
        return f"<template {self.py_func.__module__}.{self.py_func.__qualname__} ({self.flavor})>"


def template(py_func: Callable) -> Template:
    """Mark ``py_func`` as a template inlined into its callers (a per-lane helper)."""
    return Template(py_func, "inline")


def template_called(py_func: Callable) -> Template:
    """Mark ``py_func`` as a template its callers call (large code used at several places)."""
    return Template(py_func, "called")


def kernel(py_func: Callable | None = None, *, ignores: tuple[str, ...] = ()):
    """Mark ``py_func`` as a template that Python calls: a kernel over a batch of lanes.
    ``@kernel(ignores=(...))`` names the feature-set fields it does not depend on (``Template``)."""
    if py_func is None:
        return lambda f: Template(f, "kernel", ignores)
    return Template(py_func, "kernel", ignores)


def has_templates(module: types.ModuleType) -> bool:
    return any(isinstance(v, Template) for v in vars(module).values())


class Unbound(types.ModuleType):
    """What ``dispatch`` is in a template's own module: nothing a template may call before it
    is built (any attribute raises)."""

    def __getattr__(self, name: str):
        raise TypeError(f"dispatch.{name} is bound only in a build for a feature set (tracer.kernels)")


UNBOUND = Unbound("tracer.kernels.unbound")


class Build:
    """The copies of templates for one feature set, compiled on first call.

    key : a short digest of the feature set, in every copy's qualified name.
    dispatch : the feature set's namespace (``tracer.kernels.dispatch``).
    flags : compile-time switches, bound as globals of every copy (numba drops the branches
        they turn off before compiling, where it would still compile them behind a module
        attribute)."""

    def __init__(self, key: str, dispatch: types.ModuleType, flags: dict[str, bool] | None = None):
        self.key = key
        self.dispatch = dispatch
        self.flags = dict(flags or {})
        self._functions: dict[int, Any] = {}
        self._modules: dict[str, types.ModuleType] = {}

    def function(self, t: Template):
        """The compiled copy of template ``t`` for this build (made once); for a kernel that
        ignores some of the feature set, the copy of the build without them."""
        made = self._functions.get(id(t))
        if made is not None:
            return made
        features = getattr(self.dispatch, "FEATURES", None)
        if t.ignores and features is not None and features.without(t.ignores) != features:
            from . import build

            made = self._functions[id(t)] = build(features.without(t.ignores)).function(t)
            return made
        source = t.py_func
        namespace = dict(source.__globals__)
        namespace["dispatch"] = self.dispatch
        namespace.update(self.flags)
        copy = types.FunctionType(source.__code__, namespace, f"{source.__name__}__{self.key}",
                                  source.__defaults__, source.__closure__)
        copy.__qualname__ = f"{source.__qualname__}__{self.key}"
        copy.__module__ = source.__module__
        copy.__doc__ = source.__doc__
        # A kernel is compiled as an inlined helper would be: inlining matters only to callers.
        compile_with = jit_module.jit_called if t.flavor == "called" else jit_module.jit
        made = self._functions[id(t)] = compile_with(copy)
        # Its globals are resolved after it is recorded, so that a template whose code names
        # itself (a global that is also an attribute name it uses) or a cycle of templates ends.
        # numba reads them when it compiles the copy, on its first call.
        for name in _global_names(source.__code__):
            value = namespace.get(name)
            if isinstance(value, Template):
                namespace[name] = self.function(value)
            elif isinstance(value, types.ModuleType) and has_templates(value):
                namespace[name] = self.module(value)
        return made

    def module(self, module: types.ModuleType) -> types.ModuleType:
        """A copy of ``module`` whose templates are this build's copies (other names as they are)."""
        made = self._modules.get(module.__name__)
        if made is not None:
            return made
        made = self._modules[module.__name__] = types.ModuleType(f"{module.__name__}__{self.key}")
        made.__dict__.update({k: v for k, v in vars(module).items() if not k.startswith("__")})
        for name, value in vars(module).items():
            if isinstance(value, Template):
                setattr(made, name, self.function(value))
        return made

    def compiled(self) -> list[Any]:
        """The dispatchers made so far (kernels and helpers)."""
        return list(self._functions.values())


def _global_names(code: types.CodeType) -> set[str]:
    """Every name a code object (and the code objects nested in it) may look up as a global."""
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= _global_names(const)
    return names
