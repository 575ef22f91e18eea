"""Write the image and mesh files of the textured Mitsuba verification scenes
(tracer/scenes/mitsuba/textures.xml, textured_meshes.xml), deterministically:

    python benchmarks/mitsuba_texture_assets.py

- textures/tiles.png: 12 x 8 texels of 8-bit sRGB colours from a fixed seed, so that a wrong
  row order, a missing sRGB decode or a half-texel shift shows as a wrong colour;
- textures/ramp.exr: 16 x 4 float texels, a linear ramp in red and steps in green (EXR: no
  decode);
- meshes/quad_uv.obj: a quad of two triangles whose corners carry texture coordinates through
  `vt` indices that differ from the position indices, with a seam (one position with two `vt`);
- meshes/quad_uv.ply: the same quad with per-vertex `u`, `v`;
- meshes/quad_uv.serialized: the same quad, Mitsuba's serialized format (version 4, with uv);

and those of tracer/scenes/mitsuba/normal_maps.xml:

- textures/bumps.png: 48 x 32 one-channel 8-bit heights, a product of sines (a bump map's
  height field: its gradient, not its value, is what shades);
- textures/normals.png: 48 x 32 8-bit RGB normals 0.5 + 0.5 n of another field of sines,
  tilted up to about 35 degrees (a wrong tangent frame turns the tilt the wrong way);
- meshes/uv_sphere.obj: a sphere of 32 x 16 quads (fanned into triangles) with `vt`
  coordinates (a seam at u = 0) and `vn` normals.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent.parent / "tracer" / "scenes" / "mitsuba"


def write_image(path: Path, pixels: np.ndarray, uint8: bool) -> None:
    import OpenImageIO as oiio

    height, width, channels = pixels.shape
    spec = oiio.ImageSpec(width, height, channels, oiio.UINT8 if uint8 else oiio.FLOAT)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), spec)
    out.write_image(pixels)
    out.close()


def main() -> None:
    rng = np.random.default_rng(2026)
    (HERE / "textures").mkdir(exist_ok=True)
    write_image(HERE / "textures" / "tiles.png", rng.integers(20, 236, (8, 12, 3)).astype(np.uint8), True)
    ramp = np.zeros((4, 16, 3), dtype=np.float32)
    ramp[..., 0] = np.linspace(0.05, 0.95, 16)[None, :]
    ramp[..., 1] = np.array([0.1, 0.8, 0.3, 0.6])[:, None]
    ramp[..., 2] = 0.25
    write_image(HERE / "textures" / "ramp.exr", ramp, False)
    positions = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    uv = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.5], [0.0, 1.5]])
    obj = ["# quad_uv: texture coordinates by their own indices, and a seam"]
    obj += [f"v {x:g} {y:g} {z:g}" for x, y, z in positions]
    obj += [f"vt {u:g} {v:g}" for u, v in uv] + ["vt 0.25 1.75"]
    obj += ["f 1/1 2/2 3/3", "f 1/5 3/3 4/4"]  # corner 1 of the second triangle has its own vt
    (HERE / "meshes" / "quad_uv.obj").write_text("\n".join(obj) + "\n")
    ply = ["ply", "format ascii 1.0", "element vertex 4", "property float x", "property float y",
           "property float z", "property float u", "property float v", "element face 2",
           "property list uchar int vertex_indices", "end_header"]
    ply += [f"{x:g} {y:g} {z:g} {u:g} {v:g}" for (x, y, z), (u, v) in zip(positions, uv, strict=True)]
    ply += ["3 0 1 2", "3 0 2 3"]
    (HERE / "meshes" / "quad_uv.ply").write_text("\n".join(ply) + "\n")
    faces = np.array([[0, 1, 2], [0, 2, 3]], dtype="<u4")
    body = struct.pack("<I", 0x1000 | 0x0002) + b"quad_uv\0" + struct.pack("<QQ", 4, 2)
    body += positions.astype("<f4").tobytes() + uv.astype("<f4").tobytes() + faces.tobytes()
    stream = struct.pack("<HH", 0x041C, 4) + zlib.compress(body)
    (HERE / "meshes" / "quad_uv.serialized").write_bytes(stream + struct.pack("<QI", 0, 1))
    write_normal_map_assets()


def write_normal_map_assets() -> None:
    x, y = np.meshgrid((np.arange(48) + 0.5) / 48, (np.arange(32) + 0.5) / 32)
    heights = 0.5 + 0.4 * np.sin(2 * np.pi * 3 * x) * np.sin(2 * np.pi * 2 * y)
    write_image(HERE / "textures" / "bumps.png", np.round(255 * heights)[..., None].astype(np.uint8), True)
    # The normal of the surface z = k f(x, y), f another field of sines: (-k f_x, -k f_y, 1).
    k = 0.12
    f_x = 2 * np.pi * 2 * np.cos(2 * np.pi * 2 * x) * np.cos(2 * np.pi * 3 * y)
    f_y = -2 * np.pi * 3 * np.sin(2 * np.pi * 2 * x) * np.sin(2 * np.pi * 3 * y)
    n = np.stack([-k * f_x, -k * f_y, np.ones_like(x)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    write_image(HERE / "textures" / "normals.png", np.round(255 * (0.5 + 0.5 * n)).astype(np.uint8), True)
    rings, segments = 16, 32
    obj = ["# uv_sphere: texture coordinates (a seam at u = 0) and vertex normals"]
    for i in range(rings + 1):
        theta = np.pi * i / rings
        for j in range(segments + 1):
            phi = 2 * np.pi * j / segments
            p = (np.sin(theta) * np.cos(phi), np.cos(theta), np.sin(theta) * np.sin(phi))
            obj.append("v {:.6f} {:.6f} {:.6f}".format(*p))
            obj.append("vn {:.6f} {:.6f} {:.6f}".format(*p))
            obj.append(f"vt {j / segments:.6f} {1 - i / rings:.6f}")
    for i in range(rings):
        for j in range(segments):
            a, b = i * (segments + 1) + j + 1, (i + 1) * (segments + 1) + j + 1
            corners = [a, a + 1, b + 1, b]
            if i == 0:
                corners = [a, b + 1, b]
            elif i == rings - 1:
                corners = [a, a + 1, b]
            obj.append("f " + " ".join(f"{c}/{c}/{c}" for c in corners))
    (HERE / "meshes" / "uv_sphere.obj").write_text("\n".join(obj) + "\n")


if __name__ == "__main__":
    main()
