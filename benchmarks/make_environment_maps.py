"""Make the environment maps tracer ships (latitude-longitude EXR, Mitsuba 3's convention:
``tracer.scene.environment``), deterministically, from formulas: nothing photographed.

    python benchmarks/make_environment_maps.py [OUT_DIR]   (default tracer/scenes/mitsuba/textures)
    python benchmarks/make_environment_maps.py --cases [DIR]  (default tracer/study/cases)

- ``sky.exr`` (128 x 64): a sky brightening toward the horizon over a dim brown ground, a sun of
  angular radius 3 degrees and radiance 400 at 35 degrees above the horizon toward +x, -z, and a
  red band near the horizon toward +x and a green one toward +z, so that a wrong orientation
  (a mirrored or rotated map) shows in any test image.
- ``studio.exr`` (128 x 64): black, with three bright rectangles (a key, a fill and a rim light
  of radiance 40, 12 and 25): most of the sphere sends nothing, which light sampling must find.

With ``--cases``, the stability suite's maps (``tracer.study.stability``):

- ``tiny_sun.exr`` (256 x 128): a dim sky (0.05) over a darker ground (0.02) and one texel of
  radiance 30000 at 40 degrees from the zenith: a sun a few 1e-4 sr across (its bilinear
  footprint), which sends almost all the light and which uniform sphere sampling and BSDF
  sampling rarely find;
- ``near_uniform_sky.exr`` (64 x 32): radiance 1 within 2% everywhere (a smooth ripple), where
  importance sampling can gain nothing over uniform sampling.

Values are half floats (OpenEXR's HALF), which OpenImageIO and Mitsuba read to the same floats.
"""

from __future__ import annotations

import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUT = ROOT / "tracer" / "scenes" / "mitsuba" / "textures"
WIDTH, HEIGHT = 128, 64


def directions(width: int, height: int) -> np.ndarray:
    """(H, W, 3) the map-frame direction of each texel: column i at u = (i + 1/2) / W, row j at
    t = j / (H - 1)."""
    u = (np.arange(width) + 0.5) / width
    t = np.arange(height) / (height - 1)
    phi, theta = 2.0 * np.pi * u[None, :], np.pi * t[:, None]
    return np.stack([np.sin(phi) * np.sin(theta), np.cos(theta) + 0.0 * phi, -np.cos(phi) * np.sin(theta)],
                    axis=-1)


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def sky() -> np.ndarray:
    d = directions(WIDTH, HEIGHT)
    up = d[..., 1]
    rgb = np.empty(d.shape)
    above = np.clip(up, 0.0, 1.0)[..., None]
    rgb[:] = (1.0 - above) * np.array([1.1, 1.0, 0.9]) + above * np.array([0.25, 0.45, 1.0])
    ground = up < 0.0
    rgb[ground] = np.array([0.18, 0.12, 0.08])
    elevation = np.radians(35.0)
    sun = unit([np.cos(elevation), np.sin(elevation), -np.cos(elevation)])
    rgb[np.einsum("hwk,k->hw", d, sun) > np.cos(np.radians(3.0))] = 400.0
    band = (up > 0.0) & (up < 0.2)
    rgb[band & (d[..., 0] > 0.9)] = np.array([3.0, 0.1, 0.1])
    rgb[band & (d[..., 2] > 0.9)] = np.array([0.1, 3.0, 0.1])
    return rgb


def studio() -> np.ndarray:
    d = directions(WIDTH, HEIGHT)
    rgb = np.zeros(d.shape)
    u = (np.arange(WIDTH) + 0.5) / WIDTH
    t = np.arange(HEIGHT) / (HEIGHT - 1)
    for (u0, u1, t0, t1), radiance in (((0.10, 0.18, 0.20, 0.40), [40.0, 38.0, 36.0]),
                                       ((0.55, 0.70, 0.35, 0.50), [10.0, 11.0, 12.0]),
                                       ((0.85, 0.88, 0.10, 0.45), [25.0, 25.0, 25.0])):
        rows = (t >= t0) & (t <= t1)
        columns = (u >= u0) & (u <= u1)
        rgb[np.ix_(rows, columns)] = radiance
    return rgb


def tiny_sun() -> np.ndarray:
    width, height = 256, 128
    d = directions(width, height)
    rgb = np.where((d[..., 1] >= 0.0)[..., None], np.array([0.04, 0.05, 0.07]), np.array([0.02, 0.02, 0.02]))
    row = int(round(np.radians(40.0) / np.pi * (height - 1)))
    rgb[row, width // 8] = 30000.0
    return rgb


def near_uniform_sky() -> np.ndarray:
    width, height = 64, 32
    u = (np.arange(width) + 0.5) / width
    t = np.arange(height) / (height - 1)
    ripple = 1.0 + 0.02 * np.sin(2.0 * np.pi * 3.0 * u)[None, :] * np.cos(np.pi * 2.0 * t)[:, None]
    return np.repeat(ripple[..., None], 3, axis=2)


def write(path: pathlib.Path, rgb: np.ndarray) -> None:
    import OpenImageIO as oiio

    spec = oiio.ImageSpec(rgb.shape[1], rgb.shape[0], 3, oiio.HALF)
    spec.attribute("compression", "zip")
    out = oiio.ImageOutput.create(str(path))
    written = out is not None and out.open(str(path), spec) and out.write_image(rgb.astype(np.float32))
    if not written or not out.close():
        sys.exit(f"cannot write {path}: {oiio.geterror()}")


def main() -> None:
    args = sys.argv[1:]
    cases = bool(args) and args[0] == "--cases"
    if cases:
        args = args[1:]
    out = pathlib.Path(args[0]) if args else (ROOT / "tracer" / "study" / "cases" if cases else OUT)
    out.mkdir(parents=True, exist_ok=True)
    maps = ((("tiny_sun.exr", tiny_sun), ("near_uniform_sky.exr", near_uniform_sky)) if cases
            else (("sky.exr", sky), ("studio.exr", studio)))
    for name, make in maps:
        write(out / name, make())
        print(f"wrote {out / name}")


if __name__ == "__main__":
    main()
