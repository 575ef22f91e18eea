"""Light selection by a light BVH, the compiled alias table, and ris on many lights.

The unbiasedness of every selection and of ris against closed forms is in test_estimators (the
polygon lights and the furnace) and on the shipped scenes in test_scenes; here: that the BVH
draws candidates with exactly the pmf it reports, that its pmf is 0 only where a light cannot
contribute (both on a scene of bounded lights and on the same with an environment and directional
lights, which the BVH chooses between with its tree), that the tree bounds what it claims to, and the many-light scenes themselves.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tracer.lights import LightSampler, bvh, selection
from tracer.scene import load_scene

from stats import sidak


def _random_unit(rng, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def many_light_scene(seed: int = 3) -> dict:
    """A floor under 300 small quads of random size, orientation, power and colour (some facing
    away from everything), 4 sphere lights and 3 point lights, spread over 20 x 6 x 20."""
    rng = np.random.default_rng(seed)
    shapes = [{"type": "quad", "origin": [-10.0, 0.0, -10.0], "edge1": [0.0, 0.0, 20.0],
               "edge2": [20.0, 0.0, 0.0], "material": "floor"}]
    for _ in range(300):
        normal = _random_unit(rng, 1)[0]
        e1 = np.cross(normal, [0.3, 0.5, 0.8])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(normal, e1)  # e1 x e2 = normal
        size = rng.uniform(0.05, 0.6)
        shapes.append({"type": "quad", "origin": [float(rng.uniform(-10, 10)), float(rng.uniform(0.2, 6.0)),
                                                  float(rng.uniform(-10, 10))],
                       "edge1": (e1 * size).tolist(), "edge2": (e2 * size).tolist(),
                       "emission": (rng.uniform(0.1, 1.0, 3) * 10.0 ** rng.uniform(-1, 2)).tolist()})
    for _ in range(4):
        shapes.append({"type": "sphere", "center": [float(rng.uniform(-8, 8)), float(rng.uniform(1, 5)),
                                                    float(rng.uniform(-8, 8))],
                       "radius": float(rng.uniform(0.05, 0.4)), "emission": [3.0, 2.0, 1.0]})
    lights = [{"type": "point", "position": [float(rng.uniform(-8, 8)), float(rng.uniform(1, 5)),
                                             float(rng.uniform(-8, 8))], "intensity": [5.0, 5.0, 5.0]}
              for _ in range(3)]
    return {"camera": {"origin": [0.0, 8.0, 15.0], "target": [0.0, 0.0, 0.0], "fov": 50.0,
                       "width": 8, "height": 8},
            "materials": {"floor": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
            "shapes": shapes, "lights": lights}


def with_lights_at_infinity(description: dict) -> dict:
    """The scene with a constant environment and two directional lights (one pointing down, one
    grazing), which the light BVH keeps out of its tree and chooses between with the tree by
    their irradiance at the point (``tracer.lights.selections.bvh``)."""
    described = dict(description)
    described["lights"] = description["lights"] + [
        {"type": "directional", "direction": [0.2, -1.0, 0.1], "irradiance": [2.0, 2.0, 2.0]},
        {"type": "directional", "direction": [1.0, -0.05, 0.0], "irradiance": [0.5, 1.0, 0.5]}]
    described["environment"] = {"radiance": [0.3, 0.4, 0.5]}
    return described


@pytest.fixture(scope="module", params=["bounded", "with lights at infinity"])
def scene(request):
    description = many_light_scene()
    return load_scene(description if request.param == "bounded" else with_lights_at_infinity(description))


def shading_points(rng, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Random points in the lights' region and random unit normals."""
    x = np.column_stack([rng.uniform(-10, 10, count), rng.uniform(0.0, 6.0, count),
                         rng.uniform(-10, 10, count)])
    return x, _random_unit(rng, count)


def test_bvh_draws_candidates_with_the_pmf_it_reports(scene):
    """At 8 random shading points, 40,000 draws of the BVH's selection against its own pmf
    function (``selection_pmf`` of every candidate; the rest of the mass, 1 - sum, is "no light":
    the descent stops where both children's bounds are 0, which only lights that cannot
    contribute lose): a chi-square goodness-of-fit test per point, categories with fewer than 5
    expected draws pooled, Sidak over the points. The pmf a draw returns must equal the pmf
    function's value for that candidate bit for bit: MIS weighs BSDF samples with the latter,
    so any difference would bias it."""
    sampler = LightSampler(scene, "bvh")
    rng = np.random.default_rng(11)
    points, normals = shading_points(rng, 8)
    draws = 40_000
    level = sidak(len(points))
    everyone = np.arange(sampler.count)
    for x, n in zip(points, normals, strict=True):
        xs, ns = np.tile(x, (draws, 1)), np.tile(n, (draws, 1))
        k, pmf = sampler.choose(rng.random(draws), xs, ns)
        chosen = k >= 0
        assert np.array_equal(pmf[chosen], sampler.selection_pmf(k[chosen], xs[chosen], ns[chosen]))
        assert np.all(pmf[~chosen] == 0.0)
        expected = sampler.selection_pmf(everyone, np.tile(x, (sampler.count, 1)),
                                         np.tile(n, (sampler.count, 1)))
        assert 0.0 < expected.sum() <= 1.0 + 1e-12
        expected = np.append(expected, max(1.0 - expected.sum(), 0.0))  # the last: no light
        observed = np.bincount(np.where(chosen, k, sampler.count), minlength=sampler.count + 1).astype(float)
        assert observed[expected == 0.0].sum() == 0, "a candidate of pmf 0 was drawn"
        big = expected * draws >= 5.0
        obs = np.append(observed[big], observed[~big].sum())
        exp = np.append(expected[big], expected[~big].sum()) * draws
        if exp[-1] == 0.0:
            obs, exp = obs[:-1], exp[:-1]
        chi2 = float(np.sum((obs - exp) ** 2 / exp))
        p = stats.chi2.sf(chi2, len(exp) - 1)
        assert p > level, f"point {x}: chi2 {chi2:.1f} on {len(exp) - 1} dof, p = {p:.2g}"


def test_bvh_pmf_is_zero_only_where_a_light_cannot_contribute(scene):
    """Light samples drawn by power selection (which can pick any light) at 2,000 random shading
    points: wherever one contributes (radiance > 0 arriving above the point's horizon), the BVH
    must give its candidate a positive pmf at that point, or the BVH estimator would miss that
    light there (a biased image). The bounds are conservative, so this must hold for every sample."""
    power, tree = LightSampler(scene, "power"), LightSampler(scene, "bvh")
    rng = np.random.default_rng(5)
    x, n = shading_points(rng, 2_000)
    x, n = np.repeat(x, 50, axis=0), np.repeat(n, 50, axis=0)
    u_select, u_point = rng.random(len(x)), rng.random((len(x), 2))
    k, _ = power.choose(u_select, x, n)
    sample = power.sample(u_select, u_point, x, n, n)
    contributes = (sample.pdf > 0) & (sample.radiance.max(axis=1) > 0) & (np.sum(sample.wi * n, axis=1) > 0)
    assert contributes.sum() > 10_000
    pmf = tree.selection_pmf(k[contributes], x[contributes], n[contributes])
    assert np.all(pmf > 0.0)
    # And the BVH does use its bounds: a good share of (point, light) pairs are skipped.
    assert np.mean(tree.selection_pmf(k, x, n) == 0.0) > 0.2


def test_tree_bounds_what_it_claims_for_100k_emitters():
    """A tree over 100,000 random candidates: every node's box holds its children's, its power
    is their sum and its normal cone holds theirs, leaves map to candidates one to one, and
    each candidate's trail leads to its leaf through nodes whose cones hold its own."""
    rng = np.random.default_rng(1)
    count = 100_000
    lo = rng.uniform(-50, 50, (count, 3))
    hi = lo + rng.uniform(0, 0.5, (count, 3))
    axis = _random_unit(rng, count)
    cos_o = np.where(rng.random(count) < 0.1, -1.0, 1.0)
    tree = bvh.build(lo, hi, axis, cos_o, np.zeros(count), rng.uniform(0.1, 10, count))
    nodes, child = tree.nodes, tree.child
    assert len(nodes) == 2 * count - 1
    leaves = child < 0
    assert np.array_equal(np.sort(-1 - child[leaves]), np.arange(count))  # no owners: no clusters
    assert np.all(tree.span[leaves] == 1) and np.all(tree.share == 1.0)
    assert tree.trail_depth.max() <= bvh.TRAIL_BITS + 1
    parent = np.flatnonzero(~leaves)
    for side in (0, 1):
        kid = child[parent] + side
        assert np.all(nodes[parent, bvh.LO:bvh.LO + 3] <= nodes[kid, bvh.LO:bvh.LO + 3])
        assert np.all(nodes[parent, bvh.HI:bvh.HI + 3] >= nodes[kid, bvh.HI:bvh.HI + 3])
    total = nodes[child[parent], bvh.POWER] + nodes[child[parent] + 1, bvh.POWER]
    np.testing.assert_allclose(nodes[parent, bvh.POWER], total, rtol=1e-12)
    for side in (0, 1):  # a child's cone lies in its parent's
        kid = child[parent] + side
        a, b = nodes[parent, bvh.AXIS:bvh.AXIS + 3], nodes[kid, bvh.AXIS:bvh.AXIS + 3]
        between = 2.0 * np.arctan2(np.linalg.norm(a - b, axis=1), np.linalg.norm(a + b, axis=1))
        spread = np.minimum(np.arccos(np.clip(nodes[kid, bvh.COS_O], -1, 1)) + between, np.pi)
        assert np.all(spread <= np.arccos(np.clip(nodes[parent, bvh.COS_O], -1, 1)) + 1e-7)
    # Each leaf's trail leads from the root to it, through nodes whose normal cones hold its
    # cone: angle(axes) + its spread <= the node's spread.
    for k in rng.integers(0, count, 300):
        node, path = 0, [0]
        for level in range(tree.trail_depth[k]):
            node = child[node] + ((tree.trail[k] >> level) & 1)
            path.append(node)
        assert child[node] == -1 - k
        a, b = nodes[path, bvh.AXIS:bvh.AXIS + 3], axis[k]
        between = 2.0 * np.arctan2(np.linalg.norm(a - b, axis=1), np.linalg.norm(a + b, axis=1))
        spread = np.minimum(np.arccos(cos_o[k]) + between, np.pi)
        assert np.all(spread <= np.arccos(np.clip(nodes[path, bvh.COS_O], -1, 1)) + 1e-9)


def test_a_quads_two_triangles_share_a_leaf_and_nothing_else_does():
    """``bvh.clusters`` groups consecutive candidates of one emitter facing one way whose box
    stays within CLUSTER_SPREAD of the largest member's: a quad's two triangles (axis-aligned,
    and turned 45 degrees in its plane) join; the next quad of the same mesh, a triangle of
    another emitter, one facing elsewhere and a sphere (a cone of every direction) do not.
    The scene's tree then has one leaf per quad, each member chosen by its share of the leaf's
    power, the shares of a leaf summing to 1."""
    def triangle(a, b, c):
        pts = np.array([a, b, c], dtype=float)
        return pts.min(axis=0), pts.max(axis=0)

    turned = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]) * np.sqrt(0.5)
    boxes = [triangle([0, 0, 0], [1, 0, 0], [1, 1, 0]), triangle([0, 0, 0], [1, 1, 0], [0, 1, 0]),  # quad 1
             triangle([1, 0, 0], [2, 0, 0], [2, 1, 0]), triangle([1, 0, 0], [2, 1, 0], [1, 1, 0]),  # quad 2
             triangle(turned[0], turned[1], turned[2]), triangle(turned[0], turned[2], turned[3]),  # turned
             triangle([5, 0, 0], [6, 0, 0], [6, 1, 0]),  # another emitter
             triangle([5, 0, 0], [6, 1, 0], [5, 1, 0]),  # same as the one before, facing elsewhere
             (np.array([9.0, 0, 0]), np.array([10.0, 1, 1]))]  # a sphere
    lo, hi = np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes])
    axis = np.tile([0.0, 0.0, 1.0], (len(boxes), 1))
    axis[7] = [0.0, 1.0, 0.0]
    cos_o = np.ones(len(boxes))
    cos_o[8] = -1.0
    owner = np.array([0, 0, 0, 0, 1, 1, 2, 2, 3])
    assert bvh.clusters(lo, hi, axis, cos_o, owner).tolist() == [0, 2, 4, 6, 7, 8, 9]

    sampler = LightSampler(load_scene(many_light_scene()), "bvh")
    tree = sampler.tables.selection
    leaves = tree.child < 0
    quads = 300
    assert leaves.sum() == quads + 4 + 3 and np.sum(tree.span[leaves] == 2) == quads
    first = -1 - tree.child[leaves]
    sums = np.array([tree.share[f:f + s].sum() for f, s in zip(first, tree.span[leaves], strict=True)])
    np.testing.assert_allclose(sums, 1.0, rtol=1e-12)
    # A cluster's normal cone holds each member's normal (the two triangles' normals differ by
    # rounding; a cone of spread 0 around the first would not hold the second).
    axis = _candidates(sampler.scene).axis
    for leaf in np.flatnonzero(leaves & (tree.span > 1)):
        k = -1 - tree.child[leaf]
        a = tree.nodes[leaf, bvh.AXIS:bvh.AXIS + 3]
        for b in axis[k:k + tree.span[leaf]]:
            angle = 2.0 * np.arctan2(np.linalg.norm(a - b), np.linalg.norm(a + b))
            assert angle <= np.arccos(np.clip(tree.nodes[leaf, bvh.COS_O], -1, 1)) + 1e-12


def _candidates(scene):
    """The light candidates of ``scene`` under area sampling, as ``build_tables`` orders them."""
    from tracer.lights import _triangle_records, emitters, techniques_for

    triangles = emitters.emitting_triangles(scene)
    records = _triangle_records(scene, triangles, np.zeros(len(triangles), bool), techniques_for("area"))
    records.update(sphere=emitters.spheres(scene), point=emitters.points(scene),
                   directional=emitters.directionals(scene), environment=emitters.environment(scene))
    return emitters.Candidates.of([records[kind] for kind in emitters.KINDS])


def test_alias_table_reproduces_the_pmf():
    """Walker's table from the compiled Vose construction: the probability of each column
    (kept itself, or given as an alias) equals the pmf to rounding, also for zeros and ties."""
    rng = np.random.default_rng(4)
    for pmf in (rng.random(1000) ** 4, np.array([0.0, 1.0, 0.0]), np.ones(7), rng.random(1)):
        pmf = pmf / pmf.sum()
        prob, alias = selection.alias_table(pmf)
        k = len(pmf)
        rebuilt = prob / k + np.bincount(alias, weights=(1.0 - prob) / k, minlength=k)
        np.testing.assert_allclose(rebuilt, pmf, atol=1e-12)


@pytest.mark.parametrize("name", ["many_lights", "emissive_mesh"])
def test_many_light_scenes_have_what_they_promise(name):
    """many_lights: at least 1,000 emitters of widely varying power, with occluders;
    emissive_mesh: at least 10,000 emitting triangles."""
    from pathlib import Path

    scene = load_scene(Path(__file__).resolve().parent.parent / "tracer" / "scenes" / f"{name}.toml")
    emitting = scene.emission.max(axis=1) > 0
    sampler = LightSampler(scene, "bvh")
    if name == "many_lights":
        shapes = {scene.shape_of_triangle[i] for i in np.flatnonzero(emitting)}
        assert len(shapes) >= 1000
        power = sampler.pmf
        assert power.max() / power.min() > 100
        assert (~emitting).sum() > 100  # buildings and kiosks: occluders
    else:
        assert emitting.sum() >= 10_000
    assert sampler.tables.selection.trail_depth.max() >= 10


def test_api_renders_ris_and_bvh_and_records_them():
    """``tracer.render(scene, "ris", ris_candidates=, ris_sources=, light_selection=)`` runs the
    strategy it names and the image's record says so; a bad source is a ValueError."""
    import tracer

    scene = load_scene(many_light_scene(), width=8, height=8)
    image = tracer.render(scene, "ris", spp=2, ris_candidates=6, ris_sources="light+bsdf",
                          light_selection="bvh")
    record = image.film.record
    assert (record.strategy, record.light_samples, record.bsdf_samples, record.light_selection,
            record.light_selection_ran) == ("ris", 3, 3, "bvh", None)
    assert np.all(np.isfinite(image.mean))
    with pytest.raises(ValueError, match="ris sources"):
        tracer.render(scene, "ris", spp=1, ris_sources="bsdf")


def test_a_bvh_of_one_leaf_runs_as_power_with_the_same_probabilities(tmp_path, monkeypatch):
    """A light BVH whose tree is one leaf, without lights at infinity, runs the ``power``
    selection (its cheaper equivalent, ``bvh.runs_as``) and the render record says so. What
    makes this exact is checked on the tree itself (``runs_as`` switched off): with a trapezoid
    light of two triangles of areas 1.5 and 1 (one leaf, shares 0.6 and 0.4), at 2,000 random
    shading points and normals, its pmf of each triangle is power's up to float rounding,
    everywhere (a leaf's members are picked by share, with no bound to test). Deterministic:
    no tolerance beyond rounding. A scene of many leaves keeps its tree."""
    import tracer
    from tracer.lights.selections import bvh as bvh_selection
    from tracer.record import RenderRecord

    (tmp_path / "light.obj").write_text("v 0 2 0\nv 3 2 0\nv 2 2 1\nv 0 2 1\nf 1 2 3\nf 1 3 4\n")
    description = {
        "camera": {"origin": [1.5, 1.0, 5.0], "target": [1.5, 0.5, 0.0], "fov": 60.0, "width": 8, "height": 8},
        "materials": {"floor": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
        "shapes": [{"type": "quad", "origin": [-5.0, 0.0, -5.0], "edge1": [0.0, 0.0, 10.0],
                    "edge2": [10.0, 0.0, 0.0], "material": "floor"},
                   {"type": "mesh", "file": str(tmp_path / "light.obj"), "emission": [4.0, 3.0, 2.0]}]}
    scene = load_scene(description)
    power, ran = LightSampler(scene, "power"), LightSampler(scene, "bvh")
    assert (ran.requested, ran.selection) == ("bvh", "power")
    assert np.array_equal(ran.tables.selection.pmf, power.tables.selection.pmf)
    assert np.allclose(power.pmf, [0.6, 0.4], rtol=1e-12)
    assert LightSampler(load_scene(many_light_scene()), "bvh").selection == "bvh"
    # With a light at infinity the selection chooses between it and the tree by the point: bvh.
    assert LightSampler(load_scene({**description, "environment": {"radiance": [0.2, 0.2, 0.2]}}),
                        "bvh").selection == "bvh"
    # auto does not pilot the bvh candidates where they would be the power ones again.
    from tracer import auto
    from tracer.strategy import Strategy
    assert not any(s.light_selection == "bvh" for s in auto.candidates(scene, Strategy("auto")))

    monkeypatch.setattr(bvh_selection, "runs_as", lambda tables: None)
    tree = LightSampler(scene, "bvh")
    assert tree.selection == "bvh" and len(tree.tables.selection.nodes) == 1
    rng = np.random.default_rng(2)
    count = 2_000
    x = np.column_stack([rng.uniform(-2, 5, count), rng.uniform(0.0, 3.0, count), rng.uniform(-2, 3, count)])
    n = _random_unit(rng, count)
    for k in (0, 1):
        assert np.allclose(tree.selection_pmf(np.full(count, k), x, n), power.pmf[k], rtol=1e-12, atol=0.0)

    monkeypatch.undo()
    record = tracer.render(scene, "mis", spp=1, light_selection="bvh").film.record
    assert (record.light_selection, record.light_selection_ran) == ("bvh", "power")
    assert RenderRecord.from_attributes(record.attributes(), spp=1).light_selection_ran == "power"
    # A merge keeps it only where both files say the same (older files say nothing).
    from dataclasses import replace
    from tracer.record import merged
    later = replace(record, samples=((record.samples[0][0] + 1, 0, 1),))
    assert merged(record, later).light_selection_ran == "power"
    assert merged(replace(record, light_selection_ran=None), later).light_selection_ran is None
    assert tracer.render(scene, "mis", spp=1).film.record.light_selection_ran is None
