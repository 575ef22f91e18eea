"""A reference image and the scene it is of: the checks before a comparison or a noise test
renders against a reference (``compare`` and ``check`` both use them).

The reference must be of the scene (its digest), of the scene's frame (its aspect ratio), hold
at least two samples in every pixel (its variance is subtracted from the error), and the
comparison's random numbers must be independent of its own (its seeds).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from ..errors import InputError
from ..film import Film
from ..record import MAX_SEED
from ..scene import Scene, load_scene


def scene_for_reference(scene_path: str | Path, reference_path: str | Path, reference: Film,
                        downsample: int = 1, quiet: bool = False) -> Scene:
    """The scene, loaded to render at the reference's resolution / ``downsample``, after
    checking that the reference is of it: the same scene digest (when the reference records
    one; otherwise a note says it cannot be checked), the same aspect ratio as the scene's
    camera, to within one pixel's rounding (a reference of the same frame at another size is
    fine, and a note says so), and at least 2 samples in every pixel (a reference interrupted
    in its first pass has pixels without any, and one sample gives no variance to correct
    with). A reference not made with MIS gets a note: it shares the blind spots of its
    strategy (point lights for bsdf). ``InputError`` naming the reference file otherwise."""
    if reference.spp < 2:
        raise InputError(f"the reference has pixels with {reference.spp} sample(s); it needs at least 2 in "
                         "every pixel (grow it with tracer reference --resume)", str(reference_path))
    scene = load_scene(scene_path)
    digest = reference.record.scene_digest
    if digest is not None and digest != scene.digest:
        raise InputError(f"tracer:scene_digest: the reference is of another scene "
                         f"({reference.record.scene}) than {scene_path}", str(reference_path))
    if digest is None and not quiet:
        print(f"tracer: note: {reference_path} does not record its scene's digest (made by another tool "
              "or an older tracer): it cannot be checked to be of this scene", file=sys.stderr)
    if reference.record.strategy not in (None, "mis") and not quiet:
        print(f"tracer: note: {reference_path} was rendered with {reference.record.strategy}, not mis: it "
              "misses what that strategy cannot see", file=sys.stderr)
    width, height = scene.camera.width, scene.camera.height
    aspect = width / height
    # The same frame: one side of the reference is the other times the aspect ratio, rounded.
    if abs(reference.width - reference.height * aspect) > 0.5 and \
            abs(reference.height - reference.width / aspect) > 0.5:
        raise InputError(f"the reference is {reference.width}x{reference.height}, the scene's camera "
                         f"{width}x{height}: another aspect ratio, so another image", str(reference_path))
    size = (reference.width // downsample, reference.height // downsample)
    if (reference.width, reference.height) != (width, height) and not quiet:
        print(f"tracer: note: rendering at the reference's {reference.width}x{reference.height}, "
              f"not the scene's {width}x{height}", file=sys.stderr)
    scene.camera = dataclasses.replace(scene.camera, width=size[0], height=size[1])
    return scene


def independent_seed(reference: Film, seed: int | None, reference_path: str | Path) -> int:
    """A seed whose samples are independent of the reference's: ``seed`` if the reference holds
    none of it, else InputError; None picks the smallest such seed. A comparison that drew the
    reference's own random numbers would share its noise (the reference's first N samples
    *are* an N-spp MIS render), and subtracting the reference's variance would then favour it.
    A reference that does not say which samples it holds cannot be checked: seed 0 is avoided
    by default (tracer's default seed) and a note says so."""
    return independent_seeds(reference, seed, 1, reference_path)[0]


def independent_seeds(reference: Film, seed: int | None, count: int, reference_path: str | Path) -> list[int]:
    """``count`` distinct seeds none of which the reference holds samples of (the rule of
    :func:`independent_seed`): ``seed`` (refused if the reference holds it) and the next seeds
    above it that it does not hold, or with None the smallest such seeds. The comparison's
    renders use the first; a convergence sweep uses all of them, one progressive render each."""
    held = {s for s, _, _ in reference.record.samples or ()}
    if reference.record.samples is None:
        print(f"tracer: note: {reference_path} does not say which samples it holds: the comparison's "
              "renders cannot be checked to be independent of it", file=sys.stderr)
        held = {0}
    if seed is not None and seed in held:
        raise InputError(f"--seed {seed}: the reference holds samples of seed {seed}, so the "
                         "comparison would share its random numbers; use another seed or leave "
                         "--seed out", str(reference_path))
    seeds: list[int] = []
    candidate = 0 if seed is None else seed
    while len(seeds) < count:
        if candidate > MAX_SEED:
            raise InputError(f"--seed {seed}: no room for {count} seeds from it below 2^64",
                             str(reference_path))
        if candidate not in held:
            seeds.append(candidate)
        candidate += 1
    return seeds
