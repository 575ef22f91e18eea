"""relMSE at equal spp of textured area emitters sampled three ways (issue 33, part 4).

A diffuse floor under a light whose radiance is a 64 x 64 texture, dim (0.02) but for a bright
3 x 3-texel spot (300, bilinear): about 85% of its light comes from 0.2% of its area. The light
is a Mitsuba ``rectangle`` (two triangles) or the same rectangle as a 16 x 16 grid mesh (512
triangles, an OBJ with coordinates). Under ``--light-sampling area`` with the ``power``
selection:

- ``before``: each triangle weighed by the texture's mean, a point uniform by area (tracer
  before this change, reproduced by turning both parts off);
- ``flux``: each triangle weighed by its texture's exact integral over its own footprint, a
  point uniform by area (part 1 alone);
- ``texels``: that, and the point by area x texel luminance (``triangle_texels``).

The reference is ``texels`` MIS at REFERENCE_SPP (unbiased, and its own error is reported as
the reference's relMSE). relMSE is ``tracer.study.metrics.relmse`` averaged over SEEDS seeds,
for ``light`` and ``mis``, at SPP samples per pixel, and the efficiency 1 / (relMSE x seconds)
against ``before`` (seconds: the median render of seeds 1.., the first compiling). Not a test: run it by hand
(``python benchmarks/textured_emitters.py``, a few minutes on two cores).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

import tracer
from tracer.lights import emitters, textured_area
from tracer.study.metrics import reference_relmse, relmse

SPP, REFERENCE_SPP, SEEDS = 16, 2048, 4
WIDTH, HEIGHT = 96, 72


def _texture(path: Path) -> None:
    import OpenImageIO as oiio

    pixels = np.full((64, 64, 3), 0.02, dtype=np.float32)
    pixels[40:43, 20:23] = 300.0
    spec = oiio.ImageSpec(64, 64, 3, oiio.FLOAT)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(pixels)
    out.close()


def _grid_obj(path: Path, n: int = 16) -> None:
    """The square [-1, 1]^2 at z = 0 facing +z as n x n quads (2 n^2 triangles), with Mitsuba's
    rectangle coordinates (u, v) = ((x + 1) / 2, (y + 1) / 2)."""
    lines = []
    for j in range(n + 1):
        for i in range(n + 1):
            lines.append(f"v {2 * i / n - 1} {2 * j / n - 1} 0")
            lines.append(f"vt {i / n} {j / n}")
    for j in range(n):
        for i in range(n):
            a, b, c, d = (j * (n + 1) + i + 1, j * (n + 1) + i + 2, (j + 1) * (n + 1) + i + 2,
                          (j + 1) * (n + 1) + i + 1)
            lines.append(f"f {a}/{a} {b}/{b} {c}/{c}")
            lines.append(f"f {a}/{a} {c}/{c} {d}/{d}")
    path.write_text("\n".join(lines) + "\n")


def _scene(folder: Path, shape: str) -> Path:
    light = ('<shape type="rectangle">' if shape == "rectangle" else
             f'<shape type="obj"><string name="filename" value="{folder / "grid.obj"}"/>')
    text = f"""<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="50"/>
        <transform name="to_world"><lookat origin="0, 3, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="{WIDTH}"/><integer name="height" value="{HEIGHT}"/></film>
    </sensor>
    <shape type="rectangle"><transform name="to_world"><scale value="4"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.6"/></bsdf></shape>
    {light}
        <transform name="to_world"><scale x="1.5" y="1"/><rotate x="1" angle="90"/><translate y="1.5"/></transform>
        <emitter type="area"><texture name="radiance" type="bitmap">
            <string name="filename" value="{folder / "spot.exr"}"/></texture></emitter>
    </shape>
</scene>"""
    path = folder / f"{shape}.xml"
    path.write_text(text)
    return path


def _variant(name: str, monkeypatch) -> None:
    """Turn the parts off that ``name`` goes without (``before``, ``flux``, ``texels``)."""
    if name in ("before", "flux"):
        monkeypatch(emitters, "texel_sampled", lambda scene, tri: np.zeros(len(tri), dtype=bool))
    if name == "before":
        monkeypatch(textured_area, "mean_radiance",
                    lambda scene, tri: np.array(scene.emission[tri], dtype=np.float64).reshape(-1, 3))


def main() -> None:
    originals = {(emitters, "texel_sampled"): emitters.texel_sampled,
                 (textured_area, "mean_radiance"): textured_area.mean_radiance}

    def patch(module, name, value):
        setattr(module, name, value)

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        _texture(folder / "spot.exr")
        _grid_obj(folder / "grid.obj")
        for shape in ("rectangle", "grid mesh"):
            scene = tracer.load_scene(_scene(folder, shape.split()[0]))
            ref = tracer.render(scene, tracer.Strategy("mis"), spp=REFERENCE_SPP, seed=1000, sampler="independent")
            reference, reference_var = ref.mean.reshape(-1, 3), ref.variance_of_mean.reshape(-1, 3)
            print(f"{shape}: {scene.triangle_count - 2} emitting triangles; reference relMSE "
                  f"{reference_relmse(reference, reference_var):.2e}")
            for strategy in ("light", "mis"):
                row, seconds = [], []
                for variant in ("before", "flux", "texels"):
                    _variant(variant, patch)
                    errors, times = [], []
                    for s in range(SEEDS):
                        start = time.perf_counter()
                        film = tracer.render(scene, tracer.Strategy(strategy), spp=SPP, seed=s, sampler="independent")
                        times.append(time.perf_counter() - start)
                        errors.append(relmse(film.mean.reshape(-1, 3), reference, reference_var))
                    for (module, name), value in originals.items():
                        setattr(module, name, value)
                    row.append(float(np.mean(errors)))
                    seconds.append(float(np.median(times[1:])))  # the first compiles
                efficiency = [1.0 / (e * t) for e, t in zip(row, seconds, strict=True)]
                print(f"  {strategy:<5} relMSE at {SPP} spp: before {row[0]:.4g}, flux {row[1]:.4g}, "
                      f"texels {row[2]:.4g}; seconds per render {seconds[0]:.3f}, {seconds[1]:.3f}, "
                      f"{seconds[2]:.3f}; efficiency vs before: flux {efficiency[1] / efficiency[0]:.1f}x, "
                      f"texels {efficiency[2] / efficiency[0]:.1f}x")

if __name__ == "__main__":
    main()
