"""Provenance: every render file says which scene (by content) and which samples (the set of
seed and sample-index ranges) it holds, through merges and resumes, and pooling refuses what
would mix scenes or count a sample twice."""

from __future__ import annotations

import dataclasses
import shutil
import tomllib
from pathlib import Path

import pytest

from tracer.cli import main
from tracer.errors import InputError
from tracer.imagefiles import read_exr, write_exr
from tracer.record import RenderRecord, canonical_ranges, check_mergeable, format_ranges, merged, parse_ranges
from tracer.scene import load_scene

SCENES = Path(__file__).resolve().parent.parent / "scenes"
SMALL = ["--width", "12", "--height", "8", "--spp", "2", "--quiet"]


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("tracer: error: ") and "Traceback" not in err, err
    return lines[0]


def test_a_merge_remembers_every_seed_so_a_render_cannot_be_pooled_twice(tmp_path, capsys):
    """merge A B -> M, then M with B again: B's samples are in M already, so the second merge
    must be refused (it was accepted when M kept only A's seed, counting B twice), in either
    order, naming both files. M with a third seed's render C is accepted and its header lists
    all three ranges."""
    scene = str(SCENES / "cornell.toml")
    for name, seed in (("a", 1), ("b", 2), ("c", 3)):
        assert main(["render", scene, "-o", str(tmp_path / f"{name}.exr"), "--seed", str(seed), *SMALL]) == 0
    a, b, c, m = (str(tmp_path / f"{n}.exr") for n in "abcm")
    assert main(["merge", a, b, "-o", m, "--quiet"]) == 0
    for first, second in ((m, b), (b, m)):
        assert main(["merge", first, second, "-o", str(tmp_path / "x.exr"), "--quiet"]) == 2
        line = _one_error_line(capsys)
        assert first in line and second in line and "seed 2: sample indices 0-1 and 0-1 overlap" in line
    assert not (tmp_path / "x.exr").exists()
    assert main(["merge", m, c, "-o", str(tmp_path / "mc.exr"), "--quiet"]) == 0
    pooled = read_exr(tmp_path / "mc.exr")
    assert pooled.record.samples == ((1, 0, 2), (2, 0, 2), (3, 0, 2)) and pooled.spp == 6
    assert pooled.record.seed is None


def test_renders_of_different_scene_content_do_not_pool(tmp_path, capsys):
    """Two files named cornell.toml in different folders: one a copy with a comment added (the
    same scene: merges), one with a brighter light (another scene: refused naming
    tracer:scene_digest and both files, though the names agree, which is all that was compared
    before). A resumed reference refuses another scene at the same resolution too."""
    text = (SCENES / "cornell.toml").read_text()
    for folder, content in (("same", "# a comment\n" + text), ("other", text.replace("17.0", "18.0", 1))):
        shutil.copytree(SCENES / "meshes", tmp_path / folder / "meshes")
        (tmp_path / folder / "cornell.toml").write_text(content)
    assert "17.0" in text  # the light's radiance, which "other" changes
    renders = {}
    sources = (("ref", SCENES / "cornell.toml", 1), ("same", tmp_path / "same" / "cornell.toml", 2),
               ("other", tmp_path / "other" / "cornell.toml", 3))
    for key, path, seed in sources:
        renders[key] = str(tmp_path / f"{key}.exr")
        assert main(["render", str(path), "-o", renders[key], "--seed", str(seed), *SMALL]) == 0
    assert main(["merge", renders["ref"], renders["same"], "-o", str(tmp_path / "m.exr"), "--quiet"]) == 0
    assert main(["merge", renders["ref"], renders["other"], "-o", str(tmp_path / "x.exr"), "--quiet"]) == 2
    line = _one_error_line(capsys)
    assert "tracer:scene_digest" in line and renders["ref"] in line and renders["other"] in line

    reference = tmp_path / "reference.exr"
    assert main(["reference", str(SCENES / "cornell.toml"), "-o", str(reference), *SMALL]) == 0
    before = reference.read_bytes()
    assert main(["reference", str(SCENES / "veach_mis.toml"), "-o", str(reference), "--resume", *SMALL]) == 2
    line = _one_error_line(capsys)
    assert "--resume" in line and "tracer:scene_digest" in line and str(reference) in line
    assert reference.read_bytes() == before


MESH_SCENE = """
[camera]
origin = [0.0, 0.5, 3.0]
target = [0.0, 0.5, 0.0]
fov = 40.0

[materials.white]
type = "diffuse"
reflectance = [0.7, 0.7, 0.7]

[[shapes]]
type = "mesh"
file = "tri.obj"
material = "white"

[[lights]]
type = "point"
position = [0.0, 2.0, 1.0]
intensity = [1.0, 1.0, 1.0]
"""


def test_scene_digest_follows_content_not_paths(tmp_path):
    """The digest is of what renders: the same scene file and mesh in another folder give the
    same digest, as does another resolution (checked on its own); moving one vertex of the
    mesh file (the scene file untouched) changes it, and so does the camera."""
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "s.toml").write_text(MESH_SCENE)
        (tmp_path / folder / "tri.obj").write_text("v -1 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    a = load_scene(tmp_path / "a" / "s.toml")
    assert a.digest == load_scene(tmp_path / "b" / "s.toml").digest
    assert a.digest == load_scene(tmp_path / "a" / "s.toml", width=33, height=7).digest
    (tmp_path / "b" / "tri.obj").write_text("v -1 0 0\nv 1 0 0\nv 0 1.001 0\nf 1 2 3\n")
    assert load_scene(tmp_path / "b" / "s.toml").digest != a.digest
    tables = tomllib.loads(MESH_SCENE)
    tables["camera"]["fov"] = 41.0
    assert load_scene(tables, base_dir=tmp_path / "a").digest != a.digest
    tables["camera"]["fov"] = 40.0
    assert load_scene(tables, base_dir=tmp_path / "a").digest == a.digest


@pytest.mark.parametrize("ranges, text", [
    ([(5, 0, 4), (5, 4, 8), (1, 2, 3)], "1:2-2,5:0-7"),
    ([(2**64 - 1, 2**53 - 1, 2**53)], f"{2**64 - 1}:{2**53 - 1}-{2**53 - 1}"),
])
def test_sample_ranges_are_canonical_and_round_trip(ranges, text):
    """Touching ranges of one seed join, the set sorts, and the header text reads back exactly."""
    canonical = canonical_ranges(ranges)
    assert format_ranges(canonical) == text and parse_ranges(text) == canonical


def test_a_file_holding_more_samples_than_it_lists_cannot_be_pooled(tmp_path, capsys):
    """tracer 0.1's merge kept one seed's range: a file of 8 spp saying 'seed 1, samples 0-3'.
    Read as is, a merge with the seed-2 render it already holds was accepted and counted it
    twice. Such a file is read with its samples unknown, and pooling it is refused, naming it."""
    scene = str(SCENES / "cornell.toml")
    for seed in (1, 2):
        assert main(["render", scene, "-o", str(tmp_path / f"r{seed}.exr"), "--seed", str(seed), *SMALL]) == 0
    assert main(["merge", str(tmp_path / "r1.exr"), str(tmp_path / "r2.exr"), "-o", str(tmp_path / "m.exr"),
                 "--quiet"]) == 0
    old = read_exr(tmp_path / "m.exr")
    old.record = dataclasses.replace(old.record, samples=((1, 0, 2),))  # as tracer 0.1 wrote it
    write_exr(tmp_path / "old.exr", old)
    assert read_exr(tmp_path / "old.exr").record.samples is None
    capsys.readouterr()
    assert main(["merge", str(tmp_path / "old.exr"), str(tmp_path / "r2.exr"), "-o", str(tmp_path / "x.exr"),
                 "--quiet"]) == 2
    line = _one_error_line(capsys)
    assert "old.exr does not say which samples it holds" in line


def test_a_pool_keeps_the_scene_digest_it_knows():
    """Pooling a file without a digest (matched by scene name) with one that has it keeps the
    digest, so that a later pool with another scene of that name is still refused (the pool
    used to drop it and then mixed the scenes). A file without any scene is refused."""
    digest_a, digest_b = "1" * 64, "2" * 64
    old = RenderRecord(strategy="mis", scene="x/cornell.toml", samples=((1, 0, 4),))
    new = RenderRecord(strategy="mis", scene="y/cornell.toml", scene_digest=digest_a, samples=((2, 0, 4),))
    pooled = merged(old, new)
    assert pooled.scene_digest == digest_a
    other = RenderRecord(strategy="mis", scene="z/cornell.toml", scene_digest=digest_b, samples=((3, 0, 4),))
    with pytest.raises(InputError, match="tracer:scene_digest"):
        check_mergeable(pooled, other)
    with pytest.raises(InputError, match="does not say which scene"):
        check_mergeable(RenderRecord(strategy="mis", samples=((1, 0, 4),)), old)


def test_an_interrupted_render_records_the_samples_it_drew(monkeypatch):
    """A render stopped after some batches (injected: Ctrl-C from the batch merge callback
    once a third of the pixels have their first pass) records seed 0 from 0 to the largest count
    it drew, not the spp it was asked for, so a resume continues right after."""
    from tracer import render_loop
    from tracer.film import Film
    from tracer.render_loop import RenderSettings, render
    from tracer.strategy import Strategy

    scene = load_scene(SCENES / "cornell.toml", 16, 16)
    film = Film(16, 16)
    real_add = Film.add_block
    calls = []

    def add_then_interrupt(self, first_pixel, samples, first_sample=0):
        real_add(self, first_pixel, samples, first_sample)
        calls.append(first_pixel)
        if len(calls) == 3:
            raise KeyboardInterrupt

    monkeypatch.setattr(Film, "add_block", add_then_interrupt)
    result = render(scene, Strategy("mis"), RenderSettings(spp=1000, threads=1, batch_lanes=64), film=film)
    monkeypatch.setattr(Film, "add_block", real_add)
    held = int(film.count.max())
    assert result.interrupted and 0 < held < 1000 and film.count.min() < held
    assert film.record.samples == ((0, 0, held),)
    resumed = render_loop.render(scene, Strategy("mis"), RenderSettings(spp=2, threads=1, first_sample=held),
                                 film=film)
    assert resumed.film.record.samples == ((0, 0, held + 2),)
