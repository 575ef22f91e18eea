"""Every value a scene may give a material renders finite (issue 38.7).

An adversary found accepted parameters that did not: a plastic's ``int_ior = 1e-300``
(ZeroDivisionError), ``1e-160`` (NaN samples), a conductor's ``eta = k = 0`` (complex division
by zero) and ``eta = k = 1e300`` (two thirds of the samples NaN). Each parameter's range
(``Param.lo``, ``hi``) is what the readers enforce, so this file tries every parameter of every
type at the ends of its range, alone and mixed with other channels, at normal, oblique and
grazing directions and with the random numbers a sampler can give (0 included), and requires
every value, weight and pdf to be finite. These are deterministic checks, not statistics: one
non-finite lane is a failure.
"""

from __future__ import annotations

import numpy as np
import pytest

from tracer import materials
from tracer.errors import InputError
from tracer.materials import TYPES, Materials, microfacet
from tracer.scene import load_scene

N_LANES = 2000


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _directions() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """wo, wi (local, upper hemisphere) and u (n, 3): random, plus grazing wo (z = 1e-9), the
    normal, mirror pairs, and the random numbers 0 and the largest below 1."""
    rng = np.random.default_rng(20261201)
    wo = rng.normal(size=(N_LANES, 3))
    wo[:, 2] = np.abs(wo[:, 2])
    wo[:10, 2] = 1e-9 * np.linalg.norm(wo[:10, :2], axis=1)
    wo[10:20] = [0.0, 0.0, 1.0]
    wo = _unit(wo)
    wi = rng.normal(size=(N_LANES, 3))
    wi[:, 2] = np.abs(wi[:, 2])
    wi[:10] = wo[:10] * [-1.0, -1.0, 1.0]
    wi[20:30] = [0.0, 0.0, 1.0]
    wi = _unit(wi)
    u = rng.uniform(size=(N_LANES, 3))
    u[:5] = 0.0
    u[5:10] = np.nextafter(1.0, 0.0)
    u[30:40, 1:] = [0.0, 0.5]
    u[40:50, 1:] = [0.5, 0.0]
    return wo, wi, u


def _ends(p: materials.Param) -> list[float]:
    """The extreme values a scene may give parameter ``p``."""
    ends = []
    if p.lo is not None:
        ends += [float(np.nextafter(p.lo, np.inf)), p.lo + 1e-300] if p.lo_open else [p.lo]
    ends += [p.hi] if p.hi is not None else [1e300]
    return ends


CASES = [(t.name, p.name, end, mixed) for t in TYPES.values() for p in t.params
         if not (p.choices or p.boolean or p.internal) for end in _ends(p)
         for mixed in ((False, True) if p.size == 3 else (False,))]
# A composite type (a blend) is tried over parts of every delta, glossy and diffuse kind.
PARTS = [("conductor", {}), ("roughconductor", {"reflectance": np.full(3, 0.5), "alpha": 0.5}),
         ("plastic", {}), ("diffuse", {"reflectance": np.full(3, 0.5)})]


def _lanes(type_name: str, values: dict) -> Materials:
    """N_LANES lanes of the material, a composite one over the pairs of PARTS, lane by lane."""
    if not TYPES[type_name].composite:
        return Materials.uniform(type_name, N_LANES, **values)
    from tracer.materials import blendbsdf

    pairs = [(a, b) for a in PARTS for b in PARTS]
    triples = [t for i, (a, b) in enumerate(pairs) for t in blendbsdf.parts(f"b{i}", values["weight"], a, b)]
    rows = 1 + 3 * (np.arange(N_LANES) % len(pairs))
    return Materials(materials.table(triples), rows.astype(np.int64))


@pytest.mark.parametrize("type_name, param, value, mixed", CASES,
                         ids=[f"{t}.{p}={v:g}{'-mixed' if m else ''}" for t, p, v, m in CASES])
def test_every_accepted_value_renders_finite(type_name, param, value, mixed):
    """Material ``type_name`` with ``param`` at an end of its range (``mixed``: only the first
    and last channel there, the middle at a typical value), other parameters at defaults (0.5
    where there is none), under both distributions for the rough types: eval, pdf and sample
    are finite in every lane."""
    kind = TYPES[type_name]
    spec = next(p for p in kind.params if p.name == param)
    wo, wi, u = _directions()
    chosen = value if spec.size == 1 else np.array([value, 0.5 if mixed else value, value])
    distributions = microfacet.DISTRIBUTIONS if any(p.name == "distribution" for p in kind.params) else (None,)
    for distribution in distributions:
        values = {p.name: (0.5 if p.size == 1 else np.full(3, 0.5)) for p in kind.params if p.default is None}
        values[param] = chosen
        if distribution is not None:
            values["distribution"] = distribution
        lanes = _lanes(type_name, values)
        sample = lanes.sample(u, wo)
        for label, array in (("f", lanes.eval(wo, wi)), ("pdf", lanes.pdf(wo, wi)), ("sampled wi", sample.wi),
                             ("weight", sample.weight), ("sampled pdf", sample.pdf)):
            bad = ~np.all(np.isfinite(np.reshape(array, (N_LANES, -1))), axis=1)
            assert not bad.any(), (f"{type_name} {param}={value:g} ({distribution}): {label} not finite at "
                                   f"lanes {np.flatnonzero(bad)[:5]} (wo {wo[np.argmax(bad)]}, "
                                   f"u {u[np.argmax(bad)]})")


def test_conductor_fresnel_is_one_at_a_zero_index():
    """eta = k = 0 (inside the range) is the limit of a perfect reflector: F = 1 at every angle
    (the textbook form divided by n^2 = 0); elsewhere the rewritten form agrees with the
    normal-incidence closed form ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2) to 1e-12."""
    for cos in (0.0, 1e-9, 0.3, 1.0):
        assert microfacet.fresnel_conductor(cos, 0.0, 0.0) == 1.0
    for eta, k in ((0.2, 3.9), (1.5, 0.0), (1000.0, 1000.0)):
        closed = ((eta - 1.0) ** 2 + k * k) / ((eta + 1.0) ** 2 + k * k)
        assert abs(microfacet.fresnel_conductor(1.0, eta, k) - closed) <= 1e-12


OUTSIDE = {"plastic int_ior 1e-300": ("plastic", "int_ior = 1e-300"),
           "plastic ext_ior 1e-160": ("plastic", "ext_ior = 1e-160"),
           "conductor eta 1e300": ("conductor", "eta = [1e300, 1e300, 1e300]"),
           "conductor k 1001": ("conductor", "k = [1, 1001, 1]"),
           "roughconductor alpha 1e-7": ("roughconductor", "reflectance = [0.5, 0.5, 0.5]\nalpha = 1e-7"),
           "roughplastic alpha 11": ("roughplastic", "alpha = 11")}


@pytest.mark.parametrize("case", sorted(OUTSIDE))
def test_values_outside_the_ranges_are_refused_by_the_toml_reader(case, write_scene):
    """The documented ranges are enforced: one line naming the file and the key."""
    type_name, lines = OUTSIDE[case]
    path = write_scene(f'[camera]\norigin = [0, 0, 5]\ntarget = [0, 0, 0]\nfov = 40\n'
                       f'[materials.m]\ntype = "{type_name}"\n{lines}\n'
                       '[[shapes]]\ntype = "quad"\norigin = [0, 0, 0]\nedge1 = [1, 0, 0]\nedge2 = [0, 1, 0]\n'
                       'material = "m"\n')
    with pytest.raises(InputError) as info:
        load_scene(path)
    assert str(path) in str(info.value) and "materials.m" in str(info.value), str(info.value)


@pytest.mark.parametrize("bsdf, words", [
    ('<bsdf type="plastic"><float name="int_ior" value="1e-300"/></bsdf>', "int_ior"),
    ('<bsdf type="conductor"><rgb name="eta" value="1e300"/><rgb name="k" value="1"/></bsdf>', "eta"),
], ids=["plastic int_ior", "conductor eta"])
def test_values_outside_the_ranges_are_refused_by_the_mitsuba_reader(bsdf, words, tmp_path):
    """The Mitsuba reader holds the same ranges (it gave a ZeroDivisionError traceback)."""
    path = tmp_path / "s.xml"
    path.write_text(f'<scene version="3.0.0"><shape type="rectangle">{bsdf}</shape></scene>')
    with pytest.raises(InputError) as info:
        load_scene(path)
    assert str(path) in str(info.value) and words in str(info.value), str(info.value)


def test_the_material_table_holds_every_reader_to_the_ranges():
    """``materials.table`` itself refuses a value outside its range, naming the material and
    the parameter, so that a reader that forgot a check cannot hand the kernels a NaN."""
    with pytest.raises(ValueError, match=r"material 'glass' \(plastic\): int_ior = 1e-300 is outside"):
        materials.table([("glass", "plastic", {"int_ior": 1e-300})])
