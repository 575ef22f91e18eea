"""All strategies agree on every shipped scene, within statistical error.

Each scene is rendered small (32 x 32) with every strategy that can see all of its light, and
the image mean of each channel is compared with MIS's by a two-sample z-test (the standard
errors come from the films' per-pixel variances). Strategies left out of a scene are those
whose estimate there is unbiased but whose variance is so heavy-tailed that a few thousand
samples cannot estimate it (for example uniform sampling of a 0.005-alpha plate: measured
z-scores of -3.7 against MIS over six seeds, while the kept pairs gave a spread of 1.0), or that by
design cannot see part of the light (checked separately: they must give exactly zero there).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sps

from tracer.render_loop import RenderSettings, render
from tracer.scene import load_scene
from tracer.strategy import Strategy

from stats import image_mean_and_se, sidak

SCENES = Path(__file__).resolve().parent.parent / "tracer" / "scenes"

BVH = "bvh"
# ris with light candidates picked by the BVH, and with BSDF candidates (which find their
# emitter by a ray against the emitters alone): on the scenes with occluders, a point light, a
# mirror (delta BSDF candidates) and a glossy plate.
RIS_LIGHT = Strategy.ris(4, light_selection=BVH)
RIS_MIXED = Strategy.ris(4, "light+bsdf")
# Optimal MIS with adaptive allocation learns between passes: at 32 x 32 a pass is 32 spp, so
# 160 spp is 5 passes (it learns after passes 1, 2 and 4). One-sample MIS with adaptive
# allocation learns each pixel's probability of the light technique.
LEARNED = Strategy("mis", "optimal", allocation="adaptive")
ONE_SAMPLE_LEARNED = Strategy("mis", "balance", one_sample=True, allocation="adaptive")
LEARNED_SPP = 160

# scene -> (strategies compared with MIS, spp); a name stands for Strategy(name).
AGREE = {
    # (Not mis with the BVH here: a single quad light is a tree of one leaf, which runs as power.)
    "cornell": (["uniform", "cosine", "bsdf", "light", RIS_MIXED], 32),
    "veach_mis": (["bsdf", "light", Strategy("mis", light_selection=BVH), RIS_MIXED], 64),
    "tiny_light": (["light"], 32),
    "point_light": (["light", RIS_LIGHT, RIS_MIXED], 32),
    # Uniform and cosine sampling of the alpha = 0.03 plate under the big light are unbiased but
    # so heavy-tailed that their 32-spp means sit several "standard errors" low most of the time.
    "big_light": (["bsdf", "light"], 64),
    "near_mirror": (["bsdf", RIS_MIXED], 32),
    # Power selection of the street's lights is unbiased but wastes most samples on floodlights
    # that face away; light sampling by BVH and ris carry the comparison there.
    "many_lights": ([Strategy("light", light_selection=BVH), RIS_LIGHT, RIS_MIXED], 16),
    "emissive_mesh": (["bsdf", Strategy("mis", light_selection=BVH), RIS_LIGHT], 16),
}
# Every shipped scene with optimal MIS and adaptive allocation; one-sample too where the
# split matters most (glossy plates, a mirror).
LEARNED_SCENES = {name: [LEARNED] for name in AGREE}
LEARNED_SCENES["veach_mis"] = LEARNED_SCENES["near_mirror"] = [LEARNED, ONE_SAMPLE_LEARNED]
COMPARISONS = (sum(len(v[0]) for v in AGREE.values()) + sum(len(v) for v in LEARNED_SCENES.values())) * 3
SIZE = 32


def test_every_shipped_scene_is_covered():
    assert sorted(p.stem for p in SCENES.glob("*.toml")) == sorted(AGREE)


@pytest.fixture(scope="module")
def mis_films(computed_once):
    def compute(_folder):
        films = {}
        for name in AGREE:
            scene = load_scene(SCENES / f"{name}.toml", SIZE, SIZE)
            films[name] = render(scene, Strategy("mis"), RenderSettings(spp=AGREE[name][1], seed=1000)).film
        return films

    return computed_once("mis-films", compute)


@pytest.mark.parametrize("name", sorted(AGREE))
def test_strategies_agree_with_mis(name, mis_films):
    """z = (mean_s - mean_mis) / sqrt(se_s^2 + se_mis^2) per channel; two-sided p-value against
    the Sidak level over every comparison in this file (1% family false-alarm rate)."""
    scene = load_scene(SCENES / f"{name}.toml", SIZE, SIZE)
    strategies, spp = AGREE[name]
    ref_mean, ref_se = image_mean_and_se(mis_films[name])
    assert np.all(ref_mean > 0.0)
    level = sidak(COMPARISONS)
    runs = [(Strategy(s) if isinstance(s, str) else s, spp) for s in strategies]
    runs += [(strategy, LEARNED_SPP) for strategy in LEARNED_SCENES.get(name, [])]
    for i, (strategy, count) in enumerate(runs):
        film = render(scene, strategy, RenderSettings(spp=count, seed=2000 + i)).film
        mean, se = image_mean_and_se(film)
        z = (mean - ref_mean) / np.sqrt(se**2 + ref_se**2)
        p = 2.0 * sps.norm.sf(np.abs(z))
        assert np.all(p > level), f"{name}/{strategy.label}: mean {mean} vs mis {ref_mean}, z = {z}"


def test_point_light_is_invisible_to_direction_sampling():
    """Uniform, cosine and BSDF sampling cannot hit a point light: exactly zero, not NaN."""
    scene = load_scene(SCENES / "point_light.toml", 16, 16)
    for strategy in ["uniform", "cosine", "bsdf"]:
        result = render(scene, Strategy(strategy), RenderSettings(spp=2, seed=1))
        assert result.nonfinite == 0
        assert np.array_equal(result.film.mean, np.zeros_like(result.film.mean)), strategy


def test_a_light_too_small_for_float32_is_left_out_of_the_light_table():
    """An emitting sphere of radius 1e-20 at the origin passes the radius rule (1e-6 of the
    centre's magnitude, which is 0), but its triangles' areas are below float32's smallest
    normal number, so 1 / area in the light table was inf. Its triangles are left out like
    zero-area ones: the table stays finite and holds only the other light."""
    from tracer.lights import build_tables

    scene = load_scene({
        "camera": {"origin": [0.0, 0.0, 3.0], "target": [0.0, 0.0, 0.0], "fov": 40.0,
                   "width": 4, "height": 4},
        "shapes": [{"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 1e-20,
                    "emission": [1.0, 1.0, 1.0]},
                   {"type": "quad", "origin": [-1.0, 1.0, -1.0], "edge1": [2.0, 0.0, 0.0],
                    "edge2": [0.0, 0.0, 2.0], "emission": [1.0, 1.0, 1.0]}],
    })
    tables, owner, _ = build_tables(scene)
    assert np.all(np.isfinite(tables.rows)) and set(owner.tolist()) == {1}


def test_a_mesh_coordinate_past_float32_is_one_line_without_warnings(tmp_path):
    """A PLY whose float32 vertex holds 1e39 (found by the fuzzer): trimesh's cast printed a
    numpy overflow warning on stderr before tracer's one-line refusal; now only the refusal."""
    import warnings

    from tracer.errors import InputError

    (tmp_path / "m.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                    "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                    "end_header\n0 0 0\n1 1e39 0\n0 1 0\n3 0 1 2\n")
    scene = tmp_path / "s.toml"
    scene.write_text('[camera]\norigin = [0, 0, 5]\ntarget = [0, 0, 0]\nfov = 40\n'
                     '[[shapes]]\ntype = "mesh"\nfile = "m.ply"\n')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(InputError, match="non-finite vertex"):
            load_scene(scene)
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], [str(w.message) for w in caught]


def test_a_huge_echoed_name_gives_a_short_error_line(tmp_path):
    """Issue 38.10: a 60 MB material name gave a 60 MB error line after 78 s. A shape naming an
    unknown 8 MB material is refused with one line of at most errors.MAX_MESSAGE characters
    (the name cut, its length said)."""
    from tracer.errors import MAX_MESSAGE, InputError

    scene = tmp_path / "s.toml"
    scene.write_text('[camera]\norigin = [0, 0, 5]\ntarget = [0, 0, 0]\nfov = 40\n'
                     '[[shapes]]\ntype = "quad"\norigin = [0, 0, 0]\nedge1 = [1, 0, 0]\nedge2 = [0, 1, 0]\n'
                     f'material = "{"m" * 8_000_000}"\n')
    with pytest.raises(InputError) as info:
        load_scene(scene)
    text = str(info.value)
    assert len(text) <= MAX_MESSAGE + 100 and "\n" not in text and "characters" in text, text[:300]


def test_shipped_scenes_load_by_name_from_any_folder(tmp_path, monkeypatch):
    """A newcomer's `load_scene("cornell")` from a folder of their own: every shipped scene
    loads by its name (the TOML stem, or mitsuba/ and the XML stem), with or without its
    suffix, and has a one-line description. A file of that name in the current folder wins
    over the shipped scene; a name matching nothing is one line naming it and listing the
    shipped names."""
    from tracer.errors import InputError
    from tracer.scene import resolve_scene, shipped_scenes

    monkeypatch.chdir(tmp_path)
    shipped = shipped_scenes()
    names = [s.name for s in shipped]
    assert names[:len(AGREE)] == sorted(AGREE) and "mitsuba/veach_mis" in names
    for s in shipped:
        assert resolve_scene(s.name) == s.path == resolve_scene(s.name + s.path.suffix)
        assert s.description and "\n" not in s.description and len(s.description) <= 100, s
    assert load_scene("cornell", 8, 8).digest == load_scene(SCENES / "cornell.toml", 8, 8).digest
    assert load_scene("mitsuba/veach_mis", 8, 6).name == "veach_mis"
    # The user's own file named cornell (TOML without a suffix) is theirs, not the shipped one.
    (tmp_path / "cornell").write_text('[camera]\norigin = [0, 0, 5]\ntarget = [0, 0, 0]\nfov = 40\n')
    assert load_scene("cornell").shapes == []
    with pytest.raises(InputError) as info:
        load_scene("cornel")
    text = str(info.value)
    assert text.startswith("cornel: no such scene file, nor a shipped scene's name") and "\n" not in text
    assert all(name in text for name in names)
