"""Write the meshes of the Mitsuba XML verification scenes (tracer/scenes/mitsuba/meshes/).

    python benchmarks/mitsuba_xml_meshes.py

Deterministic: the same bytes on every run (numpy only, no randomness), so the scenes' SHA-256
in tests/data/mitsuba_refs/*.npz stays meaningful. Two meshes, both wound counter-clockwise
seen from outside (front = outward), both coarse enough that flat and smooth shading differ
clearly:

- `torus.ply`: binary little-endian PLY, a torus (major radius 1, minor radius 0.35, 36 x 18
  quads split into 1296 triangles, 648 shared vertices) with positions only, no normals.
  `smooth_mesh.xml` loads it twice: with `face_normals` false, so that Mitsuba computes
  angle-weighted vertex normals and shades smoothly, and with `face_normals` true (flat).
- `blob.obj`: a bumpy sphere r(theta, phi) = 1 + 0.12 sin^2(theta) cos(4 phi) (24 rings x 32
  segments, 738 vertices, 1472 triangles) with a `vn` per vertex: the exact normal of the smooth
  surface (cross product of its analytic partial derivatives), which differs from the
  angle-weighted normals of the facets, so a reader that recomputes normals instead of reading
  the file's shows. Faces are written `f a//a b//b c//c` (vertex and normal indices equal).
"""

from __future__ import annotations

import pathlib
import struct
import sys

import numpy as np

OUT = pathlib.Path(__file__).resolve().parent.parent / "tracer" / "scenes" / "mitsuba" / "meshes"


def torus(major=1.0, minor=0.35, nu=36, nv=18) -> tuple[np.ndarray, np.ndarray]:
    """Torus around the z axis (Mitsuba's shapes' local +z), vertices (nu*nv, 3), faces (2*nu*nv, 3)."""
    u = 2 * np.pi * np.arange(nu) / nu  # around the axis
    v = 2 * np.pi * np.arange(nv) / nv  # around the tube
    uu, vv = np.meshgrid(u, v, indexing="ij")
    ring = major + minor * np.cos(vv)
    vertices = np.stack([ring * np.cos(uu), ring * np.sin(uu), minor * np.sin(vv)], axis=-1).reshape(-1, 3)
    idx = lambda i, j: (i % nu) * nv + (j % nv)  # noqa: E731
    faces = []
    for i in range(nu):
        for j in range(nv):
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            faces += [[a, b, c], [a, c, d]]
    return vertices, np.array(faces, dtype=np.int64)


def blob(rings=24, segments=32, bump=0.12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bumpy sphere around the y axis: vertices, faces, exact unit normals (outward)."""

    def point(theta, phi):
        r = 1 + bump * np.sin(theta) ** 2 * np.cos(4 * phi)
        return np.stack([r * np.sin(theta) * np.cos(phi), r * np.cos(theta),
                         r * np.sin(theta) * np.sin(phi)], axis=-1)

    def d_theta(theta, phi):
        r = 1 + bump * np.sin(theta) ** 2 * np.cos(4 * phi)
        dr = 2 * bump * np.sin(theta) * np.cos(theta) * np.cos(4 * phi)
        return np.stack([dr * np.sin(theta) * np.cos(phi) + r * np.cos(theta) * np.cos(phi),
                         dr * np.cos(theta) - r * np.sin(theta),
                         dr * np.sin(theta) * np.sin(phi) + r * np.cos(theta) * np.sin(phi)], axis=-1)

    def d_phi_over_sin(theta, phi):
        """dP/dphi divided by sin(theta) (finite at the poles)."""
        r = 1 + bump * np.sin(theta) ** 2 * np.cos(4 * phi)
        dr = -4 * bump * np.sin(theta) * np.sin(4 * phi)  # (dr/dphi) / sin(theta)
        return np.stack([dr * np.sin(theta) * np.cos(phi) - r * np.sin(phi),
                         dr * np.cos(theta),
                         dr * np.sin(theta) * np.sin(phi) + r * np.cos(phi)], axis=-1)

    theta = np.pi * np.arange(1, rings) / rings
    phi = 2 * np.pi * np.arange(segments) / segments
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    body = point(tt, pp).reshape(-1, 3)
    normals = np.cross(d_phi_over_sin(tt, pp), d_theta(tt, pp)).reshape(-1, 3)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    top, bottom = len(body), len(body) + 1
    vertices = np.concatenate([body, [[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]]])
    normals = np.concatenate([normals, [[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]]])
    idx = lambda i, j: i * segments + (j % segments)  # noqa: E731  ring i (0 = near the top)
    faces = []
    for j in range(segments):
        faces.append([top, idx(0, j + 1), idx(0, j)])
        faces.append([bottom, idx(rings - 2, j), idx(rings - 2, j + 1)])
    for i in range(rings - 2):
        for j in range(segments):
            a, b, c, d = idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j)
            faces += [[a, b, c], [a, c, d]]
    faces = np.array(faces, dtype=np.int64)
    # Winding check: every face normal points away from the centre.
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.einsum("ij,ij->i", n, tri.mean(axis=1)) > 0), "blob winding"
    assert np.all(np.einsum("ij,ij->i", normals, vertices) > 0), "blob normals"
    return vertices, faces, normals


def write_ply(path: pathlib.Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    header = (f"ply\nformat binary_little_endian 1.0\ncomment written by benchmarks/mitsuba_xml_meshes.py\n"
              f"element vertex {len(vertices)}\nproperty float x\nproperty float y\nproperty float z\n"
              f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    body = np.asarray(vertices, dtype="<f4").tobytes()
    rows = b"".join(struct.pack("<B3i", 3, *map(int, f)) for f in faces)
    path.write_bytes(header.encode("ascii") + body + rows)


def write_obj(path: pathlib.Path, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray) -> None:
    lines = ["# written by benchmarks/mitsuba_xml_meshes.py: bumpy sphere with exact vertex normals"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"vn {x:.6f} {y:.6f} {z:.6f}" for x, y, z in normals]
    lines += [f"f {a + 1}//{a + 1} {b + 1}//{b + 1} {c + 1}//{c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    v, f = torus()
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centre_of_tube = np.stack([np.cos(np.arctan2(tri[..., 1], tri[..., 0]))[:, 0],
                               np.sin(np.arctan2(tri[..., 1], tri[..., 0]))[:, 0],
                               np.zeros(len(f))], axis=-1)
    outward = tri[:, 0] - centre_of_tube
    assert np.all(np.einsum("ij,ij->i", n, outward) > 0), "torus winding"
    write_ply(OUT / "torus.ply", v, f)
    v, f, n = blob()
    write_obj(OUT / "blob.obj", v, f, n)
    for p in sorted(OUT.iterdir()):
        print(f"{p.name}: {p.stat().st_size} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
