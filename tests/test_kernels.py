"""Kernels compiled for what a render uses (``tracer.kernels``): the dispatch generated from the
plug-in registries, builds keyed by their feature sets, nothing compiled that a scene does not use.

These are deterministic checks of the machinery, not statistics: the estimator's statistics
are tested elsewhere (test_estimators, test_light_techniques, test_sampling), now through the
builds these tests check.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import tracer
from tracer import materials, plugins
from tracer.kernels import FeatureSet, build
from tracer.materials import Materials

ROOT = Path(__file__).resolve().parent.parent


def _features(materials_used=("diffuse",), techniques=("triangle_area",), selection="power",
              sampler="independent", direction="bsdf", combiner="mis", learns=False) -> FeatureSet:
    return FeatureSet(tuple(materials_used), tuple(techniques), selection, sampler, direction, combiner,
                      True, direction is not None, learns)


def test_the_dispatch_has_a_branch_for_every_plugin_of_the_feature_set_and_no_other():
    """The generated chains name each material and technique of the feature set once, by its
    code, bound to that plug-in's module, and nothing else."""
    every = _features(tuple(materials.TYPES), tuple(plugins.names("light_technique")))
    namespace = build(every).dispatch
    for m in materials.TYPES.values():
        assert f"if kind == {m.code}:\n        return _material_{m.code}.eval_pdf" in namespace.source
        bound = getattr(namespace, f"_material_{m.code}").__name__
        # A composite type's functions are templates: the chain calls this build's copies of them.
        assert bound == (f"{m.module}__{build(every).key}" if m.composite else m.module)
    # The parts' chains (a blend's) name the other types only.
    parts = namespace.source[namespace.source.index("def part_eval_pdf"):]
    parts = parts[:parts.index("def technique_sample")]
    assert {m.code for m in materials.TYPES.values() if f"if kind == {m.code}:" in parts} == \
        {m.code for m in materials.TYPES.values() if not m.composite}
    for t in plugins.registry("light_technique").values():
        assert f"if code == {t.code}:\n        return _technique_{t.code}.sample" in namespace.source
        assert getattr(namespace, f"_technique_{t.code}").__name__ == t.module
    few = build(_features(("diffuse",), ("triangle_area",))).dispatch
    assert "_material_1." in few.source and "_material_2." not in few.source
    assert "_technique_0." in few.source and "_technique_6." not in few.source


@pytest.mark.parametrize("type_name", sorted(materials.TYPES))
def test_every_material_is_reached_by_its_own_branch(type_name):
    """For each registered material, the batch API (a build for the types of its table, through
    the generated chain) gives exactly what the material's own module gives, lane by lane: f,
    pdf and a sample. A branch that called another type's code, or none, differs."""
    rng = np.random.default_rng(3)
    n = 64
    wo = rng.normal(size=(n, 3))
    wo[:, 2] = np.abs(wo[:, 2])
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    wi = rng.normal(size=(n, 3))
    wi[:, 2] = np.abs(wi[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    kind = materials.TYPES[type_name]
    if kind.composite:  # its own functions are templates: compare with its parts' own functions
        _composite_is_reached(kind, wo, wi)
        return
    values = {p.name: (0.3 if p.size == 1 else np.full(3, 0.3)) for p in kind.params if p.default is None}
    lanes = Materials.uniform(type_name, n, **values)
    module = kind.functions()
    params = lanes.table.params
    own = [module.eval_pdf(params, 1, tuple(wo[i]), tuple(wi[i])) for i in range(n)]
    np.testing.assert_array_equal(lanes.eval(wo, wi), np.array([f for f, _ in own]))
    np.testing.assert_array_equal(lanes.pdf(wo, wi), np.array([p for _, p in own]))
    u = rng.uniform(size=(n, 3))
    sampled = lanes.sample(u, wo)
    direct = [module.sample(params, 1, tuple(wo[i]), u[i, 0], u[i, 1], u[i, 2]) for i in range(n)]
    np.testing.assert_array_equal(sampled.wi, np.array([d[0] for d in direct]))
    np.testing.assert_array_equal(sampled.weight, np.array([d[1] for d in direct]))


def _composite_is_reached(kind, wo, wi):
    """A blend (weight 0.3) of a diffuse and a rough metal, through the chain, gives 0.7 and 0.3
    times what those types' own modules give, to rounding (a sum's order)."""
    from tracer.materials import blendbsdf

    parts = [("diffuse", {"reflectance": np.full(3, 0.6)}), ("roughconductor", {"reflectance": np.ones(3),
                                                                                "alpha": 0.2})]
    table = materials.table(blendbsdf.parts("b", 0.3, *parts))
    lanes = Materials(table, np.ones(len(wo), dtype=np.int64))
    own = [[materials.TYPES[name].functions().eval_pdf(table.params, row, tuple(wo[i]), tuple(wi[i]))
            for i in range(len(wo))] for row, (name, _) in ((2, parts[0]), (3, parts[1]))]
    f = 0.7 * np.array([v for v, _ in own[0]]) + 0.3 * np.array([v for v, _ in own[1]])
    np.testing.assert_allclose(lanes.eval(wo, wi), f, rtol=1e-14, atol=1e-300)
    pdf = 0.7 * np.array([q for _, q in own[0]]) + 0.3 * np.array([q for _, q in own[1]])
    np.testing.assert_allclose(lanes.pdf(wo, wi), pdf, rtol=1e-14, atol=1e-300)


def test_feature_sets_have_their_own_keys_and_cache_entries():
    """Two feature sets that differ in one plug-in get two keys, and their copies of one
    template two cache entries (the key is in each entry's name), so neither can load the
    other's machine code."""
    from tracer.estimator import kernels

    a, b = build(_features(("diffuse",))), build(_features(("diffuse", "plastic")))
    assert a.key != b.key and a.key == build(_features(("diffuse",))).key
    shade_a, shade_b = a.function(kernels.shade), b.function(kernels.shade)
    if getattr(shade_a, "_cache", None) is not None and hasattr(shade_a._cache, "_impl"):
        assert shade_a._cache._impl.filename_base != shade_b._cache._impl.filename_base
        assert a.key in shade_a._cache._impl.filename_base and b.key in shade_b._cache._impl.filename_base


PROBE = textwrap.dedent("""
    import json, sys
    import numpy as np
    from tracer.kernels import FeatureSet, build
    from tracer import materials
    from tracer.materials import Materials

    # Build A knows only diffuse, build B diffuse and plastic: a plastic lane is black in A and
    # plastic's own value in B, whichever was compiled (and cached) first.
    order = sys.argv[1]
    table = materials.table([("d", "diffuse", {"reflectance": 0.5}), ("p", "plastic", {})])
    wo, wi = np.array([[0.0, 0.6, 0.8]]), np.array([[0.0, -0.6, 0.8]])
    out = {}
    for name in order:
        used = ("diffuse",) if name == "A" else ("diffuse", "plastic")
        made = build(FeatureSet(used, (), "power", "independent", None, "sum", False, False, False))
        f = made.function(materials._eval_pdf_lanes)(table.kind, table.params, np.array([2]), wo, wi)[0]
        stats = made.function(materials._eval_pdf_lanes).stats
        out[name] = [f.tolist(), sum(stats.cache_hits.values()), sum(stats.cache_misses.values())]
    print(json.dumps(out))
""")


def test_two_feature_sets_share_nothing_stale_in_the_disk_cache(tmp_path):
    """In fresh processes over one cache folder: A then B compiles both (two misses); B then A
    in a new process loads both (two hits), and each build gives its own answer for a plastic
    lane (0 in A, which has no plastic branch; plastic's value in B): a B that loaded A's entry
    would say 0."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT),
               TRACER_KERNELS="scene")

    def run(order):
        done = subprocess.run([sys.executable, "-c", PROBE, order], capture_output=True, text=True, env=env,
                              timeout=600)
        assert done.returncode == 0, done.stderr
        return json.loads(done.stdout)

    first, second = run("AB"), run("BA")
    for result in (first, second):
        assert result["A"][0] == [[0.0, 0.0, 0.0]]
        assert result["B"][0][0][0] > 0.0
    assert [first["A"][2], first["B"][2]] == [1, 1] and [second["A"][1], second["B"][1]] == [1, 1]
    assert first["B"][0] == second["B"][0]


UNUSED = {"sobol sampler": ("tracer.samplers.sobol", "point"),
          "stratified sampler": ("tracer.samplers.stratified", "point"),
          "light BVH": ("tracer.lights.bvh", "_build"),
          "rough plastic": ("tracer.materials.roughplastic", "eval_pdf"),
          "Beckmann sampling": ("tracer.materials.microfacet", "beckmann_visible_normal"),
          "spherical rectangles": ("tracer.lights.techniques.spherical_rectangle", "sample_warped"),
          "spherical triangles": ("tracer.lights.techniques.spherical_triangle", "sample_warped")}


def test_a_scene_without_a_feature_does_not_compile_it(tmp_path):
    """A fresh process with an empty cache renders diffuse walls under one quad light (mis,
    area sampling, power selection, the independent sampler). Compared: which of the large
    compiled functions of unused features numba compiled (none may be), and, as the control
    that the check can see them, the same functions after the batch APIs use each feature
    once (all must be)."""
    scene = tmp_path / "walls.toml"
    scene.write_text('[camera]\norigin = [0, 0, 3]\ntarget = [0, 0, 0]\nfov = 50\nwidth = 4\nheight = 4\n'
                     '[materials.wall]\ntype = "diffuse"\nreflectance = [0.5, 0.5, 0.5]\n'
                     '[[shapes]]\ntype = "quad"\norigin = [-1, -1, 0]\nedge1 = [2, 0, 0]\nedge2 = [0, 2, 0]\n'
                     'material = "wall"\n'
                     '[[shapes]]\ntype = "quad"\norigin = [-0.2, -0.2, 1]\n'
                     'edge1 = [0, 0.4, 0]\nedge2 = [0.4, 0, 0]\n'
                     'emission = [4, 4, 4]\n')
    probe = textwrap.dedent(f"""
        import importlib, json
        import numpy as np
        import tracer
        unused = {UNUSED!r}

        def compiled():
            return {{k: bool(getattr(importlib.import_module(m), f).signatures) for k, (m, f) in unused.items()}}

        tracer.render(tracer.load_scene({str(scene)!r}), "mis", spp=1, threads=1)
        after_render = compiled()
        from tracer import samplers
        from tracer.lights import LightSampler
        from tracer.materials import Materials
        for name in ("sobol", "stratified"):
            samplers.uniforms(samplers.make(name, 1, 0, 8), np.arange(2), np.arange(2), [0, 1])
        x = np.array([[0.0, 0.0, 0.5]]); n = np.array([[0.0, 0.0, 1.0]])
        walls = tracer.load_scene({str(scene)!r})
        LightSampler(walls, "bvh").choose(np.array([0.5]), x, n)
        for sampling in ("solid-angle", "solid-angle-cos"):
            LightSampler(walls, "power", sampling).sample(np.array([0.5]), np.array([[0.3, 0.6]]), x, n)
        lanes = Materials.uniform("roughplastic", 1, distribution="beckmann")
        lanes.eval(np.array([[0.0, 0.6, 0.8]]), np.array([[0.0, -0.6, 0.8]]))
        lanes.sample(np.array([[0.9, 0.3, 0.6]]), np.array([[0.0, 0.6, 0.8]]))
        tri = tracer.load_scene({{"camera": {{"origin": [0, 0, 3], "target": [0, 0, 0], "fov": 50}},
                                 "shapes": [{{"type": "mesh", "file": {str(ROOT / "tracer/scenes/meshes/shortbox.ply")!r},
                                              "emission": [1, 1, 1]}}]}})
        LightSampler(tri, "power", "solid-angle").sample(np.array([0.5]), np.array([[0.3, 0.6]]), x, n)
        print(json.dumps([after_render, compiled()]))
    """)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT),
               TRACER_KERNELS="scene")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, timeout=900)
    assert done.returncode == 0, done.stderr
    after_render, after_use = json.loads(done.stdout.strip().splitlines()[-1])
    assert not any(after_render.values()), after_render
    assert all(after_use.values()), after_use


WALLS = ('[camera]\norigin = [0, 0, 3]\ntarget = [0, 0, 0]\nfov = 50\nwidth = 4\nheight = 4\n'
         '[materials.wall]\ntype = "diffuse"\nreflectance = [0.5, 0.5, 0.5]\n'
         '[[shapes]]\ntype = "quad"\norigin = [-1, -1, 0]\nedge1 = [2, 0, 0]\nedge2 = [0, 2, 0]\n'
         'material = "wall"\n'
         '[[shapes]]\ntype = "quad"\norigin = [-0.2, -0.2, 1]\nedge1 = [0, 0.4, 0]\nedge2 = [0.4, 0, 0]\n'
         'emission = [4, 4, 4]\n')


def test_two_processes_that_need_one_build_compile_it_once(tmp_path):
    """Two renders of one scene started together over one empty cache (as the workers of a local
    cluster start): the first to reach the build compiles it while the other waits for its lock
    and then loads what it wrote. Compared: the progress lines on stderr (at most one process
    compiles without waiting; before the lock, both compiled the whole build side by side) and
    the two images (equal bits)."""
    from tracer.imagefiles import read_exr

    scene = tmp_path / "walls.toml"
    scene.write_text(WALLS)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT),
               TRACER_KERNELS="scene")
    runs = [subprocess.Popen([sys.executable, "-m", "tracer", "render", str(scene), "--spp", "4",
                              "--threads", "1", "-o", str(tmp_path / f"r{i}.exr")],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                             text=True, env=env) for i in range(2)]
    errors = [run.communicate(timeout=900)[1] for run in runs]
    assert [run.returncode for run in runs] == [0, 0], errors
    compiled_alone = [any("compiling the kernels" in line and "waiting" not in line
                          for line in err.splitlines())
                      for err in errors]
    assert sum(compiled_alone) <= 1, errors
    images = [read_exr(tmp_path / f"r{i}.exr") for i in range(2)]
    np.testing.assert_array_equal(images[0].mean, images[1].mean)


@pytest.mark.parametrize("scene_name, strategy, sampler", [
    ("veach_mis", {"name": "mis"}, "independent"),
    ("cornell", {"name": "light", "light_sampling": "solid-angle-cos"}, "sobol"),
], ids=["veach_mis-mis", "cornell-light-solid-angle-cos-sobol"])
def test_a_scenes_own_build_renders_the_bits_of_the_shared_build(scene_name, strategy, sampler, monkeypatch):
    """The suite renders with shared builds (every material and technique in the chains,
    conftest.py); a user's render builds for its scene alone. The two must be the same
    function of the random numbers: compared bit for bit, mean and variance, at 12 x 12 and
    4 spp (a branch the shared chain takes that the scene's would not, or flags that differ,
    change bits)."""
    import tracer
    from tracer.render_loop import RenderSettings, render
    from tracer.strategy import Strategy

    scene = tracer.load_scene(ROOT / "tracer" / "scenes" / f"{scene_name}.toml", width=12, height=12)
    films = {}
    for mode in ("scene", "shared"):
        monkeypatch.setenv("TRACER_KERNELS", mode)
        result = render(scene, Strategy(**strategy),
                        RenderSettings(spp=4, seed=5, threads=1, sampler=sampler))
        films[mode] = result.film
    np.testing.assert_array_equal(films["scene"].mean, films["shared"].mean)
    np.testing.assert_array_equal(films["scene"].variance(), films["shared"].variance())


def test_a_users_plugin_source_is_part_of_the_build_key(tmp_path, monkeypatch):
    """numba's disk cache sees a change of the file a cached function is defined in, not of the
    files of the functions it inlines: a kernel built with a user's plug-in would be loaded stale
    after the user edits the plug-in. So the build key holds the digest of every plug-in module
    outside tracer (``plugins.foreign``), and editing the file gives another key; tracer's own
    modules add nothing (the cache is keyed to tracer's sources already)."""
    module = "users_plugin_for_the_key_test"
    (tmp_path / f"{module}.py").write_text("VALUE = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    record = plugins.Plugin("users", module=module)
    features = _features()
    builtin_key = features.key
    assert plugins.foreign(features.records()) == ()
    monkeypatch.setattr(FeatureSet, "records", lambda self: [*plugins.registry("sampler").values(), record])
    first = features.key
    (tmp_path / f"{module}.py").write_text("VALUE = 2\n")
    second = features.key
    assert len({builtin_key, first, second}) == 3
    assert [name for name, _ in plugins.foreign([record])] == [module]


EVERY_EMITTER = """
[camera]
origin = [0.0, 2.0, 6.0]
target = [0.0, 0.0, 0.0]
fov = 40.0
width = 8
height = 8

[[shapes]]
type = "quad"
origin = [-1.0, 2.0, -1.0]
edge1 = [2.0, 0.0, 0.0]
edge2 = [0.0, 0.0, 2.0]
emission = [3.0, 2.0, 1.0]

[[shapes]]
type = "sphere"
center = [2.0, 1.5, 0.0]
radius = 0.4
emission = [1.0, 2.0, 3.0]

[[shapes]]
type = "mesh"
file = "triangle.obj"
emission = [2.0, 2.0, 2.0]

[[lights]]
type = "point"
position = [0.0, 3.0, 1.0]
intensity = [5.0, 5.0, 5.0]

[[lights]]
type = "directional"
direction = [0.0, -1.0, 0.0]
irradiance = [1.0, 0.5, 0.25]
"""


@pytest.mark.parametrize("technique", sorted(plugins.names("light_technique")))
def test_every_light_technique_is_reached_by_its_own_branch(technique, write_scene, tmp_path):
    """For each registered light technique, under each light sampling it serves, on a scene
    with an emitter of every kind: the generated chain of a build holding every technique gives,
    for the technique's candidates, exactly the sample and pdf the technique's own module gives.
    A branch that called another technique (or none) differs."""
    from tracer.lights import build_tables
    from tracer.scene import load_scene

    (tmp_path / "triangle.obj").write_text("v -2 1.5 -1\nv -1.5 2 -1\nv -2.5 2 -1\nf 1 2 3\n")
    scene = load_scene(write_scene(EVERY_EMITTER))
    if technique == "triangle_texels":  # textured emitters come from Mitsuba XML only
        scene = load_scene(Path(tracer.__file__).parent / "scenes" / "mitsuba" / "textured_emitters.xml")
    plugin = plugins.get("light_technique", technique)
    module = plugin.functions()
    # The technique's own chain and one after a branch of every other technique's code, so that
    # a branch that another code reached would show (a chain of all of them compiles for a minute).
    others = tuple(t for t in plugins.names("light_technique")
                   if t in ("point", "triangle_area") and t != technique)
    dispatch = build(_features(techniques=(*others, technique))).dispatch
    rng = np.random.default_rng(11)
    served = [s for s in plugin.light_samplings if s != "*"] or ["area"]
    reached = 0
    for sampling in served:
        tables, _, _ = build_tables(scene, "power", sampling)
        for k in np.flatnonzero(tables.technique == plugin.code):
            for _ in range(8):
                x = (float(rng.uniform(-0.5, 0.5)), 0.0, float(rng.uniform(-0.5, 0.5)))
                n = (0.0, 1.0, 0.0)
                u0, u1 = (float(v) for v in rng.uniform(size=2))
                mine = module.sample(tables.rows, int(k), x, n, u0, u1)
                assert dispatch.technique_sample(plugin.code, tables.rows, int(k), x, n, u0, u1) == mine
                wi, dist = mine[0], mine[1]
                assert dispatch.technique_pdf(plugin.code, tables.rows, int(k), x, n, wi, dist) == \
                    module.pdf(tables.rows, int(k), x, n, wi, dist)
                reached += 1
    assert reached > 0, f"no candidate of the test scene uses {technique}"
