"""A reference image and the scene it is of: the checks before a comparison or a noise test
renders against a reference (``compare`` and ``check`` both use them).

The reference must be of the scene (its digest), of the scene's frame (its aspect ratio), hold
at least two samples in every pixel (its variance is subtracted from the error), and the
comparison's random numbers must be independent of its own (its seeds).

``compare`` also takes an EXR that another renderer wrote (:func:`read_reference`): its pixel
values, with a variance only where the file has variance channels *and* its sample count is
known (given by the user), since the variance channels are one sample's and the pixel value's
variance is that / spp. Without both, nothing is subtracted for the reference's noise and the
comparison says so (:attr:`Reference.uncorrected_because`); its scene cannot be checked.
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..film import Film
from ..imagefiles import ExternalImage, is_tracer_exr, read_exr, read_external_exr
from ..record import MAX_SEED, RenderRecord
from ..scene import Scene, load_scene


@dataclass
class Reference:
    """The image a comparison measures against: a tracer render, or another renderer's EXR.

    path : the file, as the user named it (for messages).   width, height : pixels.
    mean : (P, 3) float64 pixel values, row-major, row 0 at the top.
    pixel_variance : (P, 3) float64 variance of each pixel value (the reference's noise, which
        the measures subtract), or None where it is not known.
    spp : samples in every pixel (the smallest count), or None where not known.
    record : the tracer render record (empty, all None, for another renderer's file).
    film : the tracer render, or None for another renderer's file.
    external : for another renderer's file, what was read of it (channels); else None.
    uncorrected_because : why ``pixel_variance`` is None, as a clause for a line ("ref.exr has
        no variance channels"); None when it is known.
    """

    path: str
    width: int
    height: int
    mean: np.ndarray
    pixel_variance: np.ndarray | None
    spp: int | None
    record: RenderRecord
    film: Film | None = None
    external: ExternalImage | None = None
    uncorrected_because: str | None = None

    @classmethod
    def of_film(cls, film: Film, path: str | Path = "the reference") -> "Reference":
        """A tracer render as a reference: its means, the variance of its pixel values and its count."""
        return cls(str(path), film.width, film.height, film.mean, film.variance_of_mean(), film.spp,
                   film.record, film=film)

    @classmethod
    def of_external(cls, image: ExternalImage, path: str | Path, spp: int | None) -> "Reference":
        """Another renderer's image as a reference: the variance of its pixel values is its
        variance channels (one sample's variance) / ``spp``, when it has both."""
        path = str(path)
        why = None
        if image.variance is None:
            moments = (" (its m2_* channels are Mitsuba's second moments of X, Y, Z, which give no RGB "
                       "variance)" if image.has_moments else "")
            why = f"{path} has no variance channels{moments}"
        elif spp is None:
            why = (f"{path} has variance channels but no sample count to divide them by "
                   "(--reference-spp N gives it)")
        variance = None if why else image.variance / spp
        return cls(path, image.width, image.height, image.mean, variance, spp, RenderRecord(),
                   external=image, uncorrected_because=why)

    def image(self) -> np.ndarray:
        """(H, W, 3) float64 pixel values."""
        return self.mean.reshape(self.height, self.width, 3)

    @property
    def description(self) -> str:
        """What the reference is, for the report: ``1024 spp, mis`` or ``another renderer's
        channels R, G, B; spp unknown``."""
        spp = "spp unknown" if self.spp is None else f"{self.spp} spp"
        if self.external is None:
            return f"{spp}, {self.record.strategy}"
        return f"another renderer's channels {', '.join(dict.fromkeys(self.external.channels))}; {spp}"


def as_reference(reference: Film | Reference, path: str | Path = "the reference") -> Reference:
    """``reference`` as a :class:`Reference` (a film is a tracer render)."""
    return reference if isinstance(reference, Reference) else Reference.of_film(reference, path)


def read_reference(path: str | Path, layer: str | None = None, spp: int | None = None) -> Reference:
    """The reference in file ``path``: a tracer render (``imagefiles.read_exr``, every check of
    the render file), or an EXR of another renderer (``imagefiles.read_external_exr``: channels
    R, G, B of ``layer`` or the file's one RGB layer, variance channels if present), whose
    sample count is ``spp`` (None: unknown). InputError naming the file: a tracer render with a
    ``layer`` (its image is R, G, B) or an ``spp`` other than its own, or what the readers refuse."""
    if is_tracer_exr(path):
        if layer is not None:
            raise InputError(f"--reference-layer {layer}: this is a tracer render, whose image is channels "
                             "R, G, B", str(path))
        film = read_exr(path)
        if spp is not None and spp != film.spp:
            raise InputError(f"--reference-spp {spp}: this tracer render holds {film.spp} samples in every "
                             "pixel (tracer:spp)", str(path))
        return Reference.of_film(film, path)
    return Reference.of_external(read_external_exr(path, layer), path, spp)


def scene_for_reference(scene_path: str | Path, reference_path: str | Path, reference: Film | Reference,
                        downsample: int = 1, quiet: bool = False) -> Scene:
    """The scene, loaded to render at the reference's resolution / ``downsample``, after
    checking that the reference is of it: the same scene digest (when the reference records
    one; otherwise a note says it cannot be checked), the same aspect ratio as the scene's
    camera, to within one pixel's rounding (a reference of the same frame at another size is
    fine, and a note says so), and at least 2 samples in every pixel (a reference interrupted
    in its first pass has pixels without any, and one sample gives no variance to correct
    with). A reference not made with MIS gets a note: it shares the blind spots of its
    strategy (point lights for bsdf). Another renderer's image (``Reference.external``) records
    neither a digest nor its samples: a note says its scene cannot be checked, and its sample
    count is not required (without one its noise is not corrected for: ``Reference``).
    ``InputError`` naming the reference file otherwise."""
    reference = as_reference(reference, reference_path)
    if reference.external is None and reference.spp < 2:
        raise InputError(f"the reference has pixels with {reference.spp} sample(s); it needs at least 2 in "
                         "every pixel (grow it with tracer reference --resume)", str(reference_path))
    scene = load_scene(scene_path)
    digest = reference.record.scene_digest
    if digest is not None and digest != scene.digest:
        raise InputError(f"tracer:scene_digest: the reference is of another scene "
                         f"({reference.record.scene}) than {scene_path}", str(reference_path))
    if reference.external is not None and not quiet:
        print(f"tracer: note: {reference_path} is another renderer's image (no tracer:spp in its header): "
              "it cannot be checked to be of this scene (it records no tracer:scene_digest)", file=sys.stderr)
    elif digest is None and not quiet:
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


def independent_seed(reference: Film | Reference, seed: int | None, reference_path: str | Path) -> int:
    """A seed whose samples are independent of the reference's: ``seed`` if the reference holds
    none of it, else InputError; None picks the smallest such seed. A comparison that drew the
    reference's own random numbers would share its noise (the reference's first N samples
    *are* an N-spp MIS render), and subtracting the reference's variance would then favour it.
    A reference that does not say which samples it holds cannot be checked: seed 0 is avoided
    by default (tracer's default seed) and a note says so, except for another renderer's image,
    whose samples are not drawn from tracer's random numbers (seed 0 is still avoided, in case
    the file is a tracer render whose header was lost)."""
    return independent_seeds(reference, seed, 1, reference_path)[0]


def independent_seeds(reference: Film | Reference, seed: int | None, count: int,
                      reference_path: str | Path) -> list[int]:
    """``count`` distinct seeds none of which the reference holds samples of (the rule of
    :func:`independent_seed`): ``seed`` (refused if the reference holds it) and the next seeds
    above it that it does not hold, or with None the smallest such seeds. The comparison's
    renders use the first; a convergence sweep uses all of them, one progressive render each."""
    reference = as_reference(reference, reference_path)
    held = {s for s, _, _ in reference.record.samples or ()}
    if reference.record.samples is None and reference.external is None:
        print(f"tracer: note: {reference_path} does not say which samples it holds: the comparison's "
              "renders cannot be checked to be independent of it", file=sys.stderr)
    if reference.record.samples is None:
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
