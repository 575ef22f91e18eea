"""``tracer compare --reference X.exr`` with an EXR that another renderer wrote (as Mitsuba 3 does:
float32 R, G, B and perhaps variance.R/G/B, no tracer attributes): what is read of it, how each
use of the reference's noise degrades when its sample count or variance is not known, and the
one-line refusals. Not statistical: the foreign files here are made from a tracer reference, so
the comparison with one is checked against the comparison with the other, number for number."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from tracer.cli import main
from tracer.imagefiles import read_exr
from tracer.study import viewer

SCENES = Path(__file__).resolve().parent.parent / "tracer" / "scenes"
SCENE = str(SCENES / "cornell.toml")
SIZE = 8  # the reference's width and height, at which the comparison renders (the scene's frame is square)
SPP = 16  # the tracer reference's samples per pixel
UNCORRECTED = "tracer: note: mse and relmse are as measured, the reference's own noise not subtracted: "


def write_foreign_exr(path: Path, planes: dict[str, np.ndarray], width: int = SIZE,
                      height: int = SIZE) -> Path:
    """Write ``planes`` (channel name -> (P,) values, row-major) as a float32 EXR with no tracer
    attributes, as Mitsuba's hdrfilm (component_format float32) writes its R, G, B."""
    spec = oiio.ImageSpec(width, height, len(planes), "float")
    spec.channelnames = tuple(planes)
    spec.attribute("compression", "zip")
    pixels = np.stack(list(planes.values()), axis=1).astype(np.float32).reshape(height, width, len(planes))
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(pixels) and out.close()
    return path


def rgb(prefix: str, values: np.ndarray) -> dict[str, np.ndarray]:
    """Channels ``PREFIX R, G, B`` of ``values (P, 3)``."""
    return {f"{prefix}{c}": values[:, i] for i, c in enumerate("RGB")}


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A tracer reference of cornell (8 x 8, 16 spp, float32 means) and the same pixels as another
    renderer's file: its means as R, G, B and its per-sample variance as variance.R/G/B."""
    folder = tmp_path_factory.mktemp("external")
    tracer_ref = folder / "tracer_ref.exr"
    assert main(["reference", SCENE, "-o", str(tracer_ref), "--width", str(SIZE), "--height", str(SIZE),
                 "--spp", str(SPP), "--float", "--quiet"]) == 0
    film = read_exr(tracer_ref)
    foreign = write_foreign_exr(folder / "mitsuba.exr",
                                {**rgb("", film.mean), **rgb("variance.", film.variance())})
    return {"folder": folder, "tracer": tracer_ref, "foreign": foreign, "film": film}


def compare(reference: Path, out: Path, *extra: str) -> int:
    """One cheap comparison: the light strategy at 2 spp."""
    return main(["compare", SCENE, "--reference", str(reference), "--spp", "2", "--strategies", "light",
                 "--out", str(out), *extra])


def metrics(out: Path) -> dict:
    return json.loads((out / "metrics.json").read_text())


def test_a_foreign_reference_with_its_spp_measures_as_the_tracer_reference_it_came_from(made, tmp_path,
                                                                                       capsys):
    """The same pixels, variance and count, from a file without tracer's header: every measure is
    the tracer reference's (both comparisons draw seed 1, since neither says it holds seed 0's
    samples apart from the tracer one, which does: the renders are the same bits). The scene
    cannot be checked, and a note says so once; nothing says the noise went uncorrected."""
    assert compare(made["tracer"], tmp_path / "tracer", "--quiet") == 0
    capsys.readouterr()
    assert compare(made["foreign"], tmp_path / "foreign", "--reference-spp", str(SPP)) == 0
    err = capsys.readouterr().err
    assert err.count("cannot be checked to be of this scene") == 1, err
    assert "mitsuba.exr is another renderer's image (no tracer:spp in its header)" in err
    assert "not subtracted" not in err and "does not say which samples" not in err, err
    mine, theirs = metrics(tmp_path / "foreign"), metrics(tmp_path / "tracer")
    assert mine["reference_noise"]["subtracted"] and mine["reference_spp"] == SPP
    assert mine["reference_noise"]["relmse"] == pytest.approx(theirs["reference_noise"]["relmse"], rel=1e-12)
    for key in ("mse", "relmse", "mse_uncorrected", "relmse_uncorrected"):
        assert mine["results"][0][key] == pytest.approx(theirs["results"][0][key], rel=1e-12), key
    assert mine["results"][0]["relmse"] < mine["results"][0]["relmse_uncorrected"]
    assert mine["reference_made_by"] == "another renderer" and theirs["reference_made_by"] == "tracer"
    page = (tmp_path / "foreign" / "index.html").read_text()
    assert "another renderer&#x27;s channels R, G, B; 16 spp" in page


def test_without_a_sample_count_nothing_is_subtracted_and_one_line_says_so(made, tmp_path, capsys):
    """Variance channels but no spp: the variance of a pixel value (variance / spp) is not known,
    so mse and relmse are as measured, the noise warning is not given, and one line says so: on
    stderr (the only line with --quiet), on the page, in metrics.json. The viewer gets no
    variance or spp for the reference (null), rather than one made up."""
    out = tmp_path / "cmp"
    assert compare(made["foreign"], out, "--quiet") == 0
    line = UNCORRECTED + f"{made['foreign']} has variance channels but no sample count to divide them by " \
                         "(--reference-spp N gives it)"
    assert capsys.readouterr().err.splitlines() == [line]
    doc = metrics(out)
    assert doc["reference_noise"] == {"relmse": None, "mse": None, "subtracted": False,
                                      "correction": line.removeprefix("tracer: note: ")}
    assert doc["reference_spp"] is None
    row = doc["results"][0]
    assert row["relmse"] == row["relmse_uncorrected"] and row["mse"] == row["mse_uncorrected"]
    page = (out / "index.html").read_text()
    assert len(re.findall(r"<p class=note>.*not subtracted.*</p>", page)) == 1
    data = viewer.read_viewer_data(out / viewer.DATA_FILE)
    assert (data["images"][0]["name"], data["images"][0]["spp"], data["images"][0]["variance"]) == \
        ("reference", None, None)
    assert data["images"][1]["variance"] is not None


def test_without_variance_channels_nothing_is_subtracted_even_with_a_sample_count(made, tmp_path, capsys):
    """R, G, B only (hdrfilm's plain output): --reference-spp cannot make a variance, so the one
    line names the missing channels; Mitsuba's moment channels (m2_*: second moments of X, Y, Z)
    are said not to give one."""
    film = made["film"]
    plain = write_foreign_exr(tmp_path / "plain.exr", rgb("", film.mean))
    assert compare(plain, tmp_path / "a", "--reference-spp", "16", "--quiet") == 0
    assert capsys.readouterr().err.splitlines() == [UNCORRECTED + f"{plain} has no variance channels"]
    squares = {f"m2_direct.{c}": film.mean[:, i] ** 2 for i, c in enumerate("XYZ")}
    moments = write_foreign_exr(tmp_path / "moment.exr", {**rgb("", film.mean), **squares})
    assert compare(moments, tmp_path / "b", "--quiet") == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(UNCORRECTED + f"{moments} has no variance channels (its m2_* "
                                               "channels are Mitsuba's second moments"), err
    assert metrics(tmp_path / "b")["reference_noise"]["subtracted"] is False


def test_a_layer_is_found_named_or_refused_and_gray_is_read_as_rgb(made, tmp_path, capsys):
    """Without plain R, G, B the file's one RGB layer is used, with its own variance layer
    (the same numbers as the plain file); with two, compare refuses naming them until
    --reference-layer picks one. A gray file (Y) is R = G = B."""
    film = made["film"]
    beauty = {**rgb("beauty.", film.mean), **rgb("beauty.variance.", film.variance())}
    one = write_foreign_exr(tmp_path / "one.exr", beauty)
    assert compare(one, tmp_path / "one", "--reference-spp", str(SPP), "--quiet") == 0
    assert compare(made["foreign"], tmp_path / "plain", "--reference-spp", str(SPP), "--quiet") == 0
    for key in ("relmse", "mse", "relmse_uncorrected"):
        assert metrics(tmp_path / "one")["results"][0][key] == metrics(tmp_path / "plain")["results"][0][key]
    two = write_foreign_exr(tmp_path / "two.exr", {**beauty, **rgb("albedo.", np.full_like(film.mean, 0.5))})
    capsys.readouterr()
    assert compare(two, tmp_path / "two", "--quiet") == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"tracer: error: {two}: no plain R, G, B channels but 2 RGB layers (albedo, beauty): name "
                   "the one to compare with (--reference-layer)"], err
    assert not (tmp_path / "two").exists()
    assert compare(two, tmp_path / "two", "--reference-layer", "beauty", "--reference-spp", str(SPP),
                   "--quiet") == 0
    chosen, alone = metrics(tmp_path / "two")["results"][0], metrics(tmp_path / "one")["results"][0]
    assert chosen["relmse"] == alone["relmse"]
    gray_values = film.mean.mean(axis=1)
    gray = write_foreign_exr(tmp_path / "gray.exr", {"Y": gray_values})
    capsys.readouterr()
    assert compare(gray, tmp_path / "gray", "--quiet") == 0
    data = viewer.read_viewer_data(tmp_path / "gray" / viewer.DATA_FILE)
    reference = viewer.unpack(data["images"][0]["mean"], (SIZE * SIZE, 3))
    assert np.array_equal(reference, np.repeat(gray_values.astype(np.float32)[:, None], 3, axis=1))
    assert capsys.readouterr().err.startswith(UNCORRECTED + f"{gray} has no variance channels")


def _bad_files(folder: Path, film) -> dict[str, tuple[Path, list[str], str]]:
    """Each refused case: its file, extra options and the words its one line holds."""
    mean, variance = film.mean.copy(), film.variance()
    with_nan, with_inf, negative = mean.copy(), mean.copy(), variance.copy()
    with_nan[9, 0] = np.nan  # pixel (1, 1)
    with_inf[2, 1] = np.inf  # pixel (2, 0)
    negative[63, 2] = -1e-3  # pixel (7, 7)
    junk = folder / "junk.exr"
    junk.write_bytes(b"not an image " * 40)
    png = folder / "preview.exr"
    spec = oiio.ImageSpec(SIZE, SIZE, 3, "uint8")
    out = oiio.ImageOutput.create(str(folder / "preview.png"))
    assert out.open(str(folder / "preview.png"), spec)
    assert out.write_image(np.zeros((SIZE, SIZE, 3), np.uint8))
    out.close()
    png.write_bytes((folder / "preview.png").read_bytes())
    wide = np.repeat(mean, 2, axis=0)  # 16 x 8 pixels: another frame than the scene's square camera

    def exr(name: str, planes: dict[str, np.ndarray], width: int = SIZE, height: int = SIZE) -> Path:
        return write_foreign_exr(folder / name, planes, width, height)

    return {
        "nan": (exr("nan.exr", rgb("", with_nan)), [],
                "R, G, B is not a finite number at pixel (1, 1): [nan, "),
        "inf": (exr("inf.exr", {**rgb("", with_inf), **rgb("variance.", variance)}), [],
                "R, G, B is not a finite number at pixel (2, 0): ["),
        "negative variance": (exr("neg.exr", {**rgb("", mean), **rgb("variance.", negative)}),
                              [], "variance.R, variance.G, variance.B is not a finite non-negative number at "
                              "pixel (7, 7): ["),
        "missing B": (exr("rg.exr", {"R": mean[:, 0], "G": mean[:, 1]}), [],
                      "missing channel(s) B (has "),
        "no colour": (exr("depth.exr", {"depth.Z": mean[:, 0]}), [],
                      "no channels R, G, B (nor a gray Y) (has depth.Z)"),
        "partial variance": (exr("pv.exr", {**rgb("", mean), "variance.R": variance[:, 0]}),
                             [], "has variance channel(s) variance.R but not all of variance.R, variance.G, "
                             "variance.B"),
        "xyz": (exr("xyz.exr", {c: mean[:, i] for i, c in enumerate("XYZ")}), [],
                "holds CIE XYZ (channels X, Y, Z), not RGB"),
        "unknown layer": (exr("layer.exr", rgb("beauty.", mean)), ["--reference-layer", "diffuse"],
                          "no channels diffuse.R, diffuse.G, diffuse.B (nor a gray diffuse.Y) (has "
                          "beauty.R, "),
        "unreadable": (junk, [], "cannot read image: "),
        "not an EXR": (png, [], "is a png image, not an OpenEXR file"),
        "no such file": (folder / "absent.exr", [], "no such file"),
        "another frame": (exr("wide.exr", rgb("", wide), 16, 8), [],
                          "the reference is 16x8, the scene's camera 256x256: another aspect ratio"),
    }


def test_bad_foreign_references_are_refused_in_one_line(made, tmp_path, capsys):
    """Each case: exit 2, one line on stderr naming the file and what is wrong, no traceback,
    no output folder."""
    for case, (path, extra, words) in _bad_files(tmp_path, made["film"]).items():
        capsys.readouterr()
        out = tmp_path / f"cmp_{case.replace(' ', '_')}"
        assert compare(path, out, *extra, "--quiet") == 2, case
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith(f"tracer: error: {path}: {words}"), (case, err)
        assert "Traceback" not in err and not out.exists(), case


def test_tracer_references_refuse_a_layer_or_another_sample_count(made, tmp_path, capsys):
    """A tracer render's image is its R, G, B and its count is in its header: --reference-layer
    is refused, and --reference-spp unless it says the same."""
    refusals = ((["--reference-layer", "beauty"], "--reference-layer beauty: this is a tracer render"),
                (["--reference-spp", "64"], "--reference-spp 64: this tracer render holds 16 samples"))
    for extra, words in refusals:
        capsys.readouterr()
        assert compare(made["tracer"], tmp_path / "cmp", *extra, "--quiet") == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith(f"tracer: error: {made['tracer']}: {words}"), err
    assert compare(made["tracer"], tmp_path / "cmp", "--reference-spp", str(SPP), "--quiet") == 0
    assert metrics(tmp_path / "cmp")["reference_noise"]["subtracted"] is True
