"""Translate a `tracer` scene file (TOML, see SCENE_FORMAT.md) into a Mitsuba 3 scene dict.

This is an independent reference for cross-checking `tracer`: it reads the scene file with its
own code (tomllib + trimesh) and never imports the `tracer` package, so that a misreading of
the contract in one place does not silently show up in both renderers.

Conventions, and how they line up with Mitsuba 3.  Each was checked numerically when this
module was written: rendered pixels against the contract's camera formula (to Monte Carlo
noise, and not mirrored), an emitter with flipped winding (black), flat against smooth shading
of an icosphere, `roughconductor.eval` against the contract's GGX formula, and a diffuse plane
under a square light against Lambert's polygon formula.

- Triangles.  Ours: front = normalize((v1 - v0) x (v2 - v0)), shading normal = that face
  normal.  Mitsuba's `Mesh::face_normal` is the same cross product, and a mesh built without
  vertex normals (`has_vertex_normals=False`) shades with it, so every shape here is built as
  an `mi.Mesh` from raw vertex/face arrays and never gets smoothed vertex normals.
- Area emitters.  Mitsuba's `area` emitter radiates only into the hemisphere of the shape's
  normal (it returns zero when `dot(wi, n) <= 0`, both when hit and when sampled), so with the
  winding kept as is it emits from our front side only, as the contract asks.
- Materials are two-sided in the contract; Mitsuba's BSDFs are one-sided, hence `twosided`.
- Camera.  `look_at` gives a camera frame whose local +x is `up x f`, i.e. *minus* our
  r = normalize(f x up); Mitsuba's `perspective` sensor maps film x (left to right) onto local
  -x, so the image's x grows along our r, and film y (top to bottom) onto local -y.  The net
  result is our film: px to the right along r, py downward, not mirrored.  `fov_axis='y'`
  makes `fov` the vertical field of view, as in the contract.
- Pixel filter: `box` with Mitsuba's default radius 0.5 splats each sample onto its own pixel
  with weight 1, so a pixel is the plain average of its samples.

Only `scalar_rgb` (and the `*_rgb` JIT variants) make sense here: the colours in the contract
are RGB triples, and spectral variants would upsample them.
"""

from __future__ import annotations

import math
import pathlib
import tomllib

import numpy as np
import trimesh

# Optional-key defaults of the contract.
DEFAULT_SUBDIVISIONS = 3

# Mitsuba's microfacet distribution clamps alpha from below to this value.
MIN_MITSUBA_ALPHA = 1e-4


def _mi():
    """Import Mitsuba lazily and make sure a variant is active.

    `mi.Mesh` objects can only be created once a variant is set; `scalar_rgb` is the default
    for the cross-check because it needs no JIT compiler.
    """
    import mitsuba as mi

    if mi.variant() is None:
        mi.set_variant("scalar_rgb")
    return mi


def _vec3(value, where: str) -> np.ndarray:
    """Return `value` as a finite float64 array of shape (3,), or raise naming `where`."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{where}: expected a list of 3 finite numbers, got {value!r}")
    return arr


def _rgb(value, where: str) -> dict:
    """A Mitsuba RGB texture/spectrum dict from a contract colour triple."""
    return {"type": "rgb", "value": [float(c) for c in _vec3(value, where)]}


def quad_triangles(origin, edge1, edge2) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate a contract quad.

    Corners o, o+e1, o+e1+e2, o+e2 in that order, split along the o -> o+e1+e2 diagonal; both
    triangles keep the counter-clockwise order, so each face normal is normalize(e1 x e2).

    Returns vertices (4, 3) float64 and faces (2, 3) int64.
    """
    o, e1, e2 = (np.asarray(a, dtype=np.float64) for a in (origin, edge1, edge2))
    vertices = np.stack([o, o + e1, o + e1 + e2, o + e2])
    faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)
    return vertices, faces


def sphere_triangles(center, radius: float, subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """The contract's tessellated sphere: trimesh's icosphere, translated to `center`.

    trimesh winds the icosphere counter-clockwise seen from outside, so face normals point
    outward.  Returns vertices (n, 3) float64 and faces (m, 3) int64.
    """
    mesh = trimesh.creation.icosphere(subdivisions=int(subdivisions), radius=float(radius))
    vertices = np.asarray(mesh.vertices, dtype=np.float64) + np.asarray(center, dtype=np.float64)
    return vertices, np.asarray(mesh.faces, dtype=np.int64)


def mesh_file_triangles(path: pathlib.Path) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of a mesh file, as trimesh reads them (multi-part files are concatenated).

    `process=False` keeps the file's vertices and winding untouched: merging or reordering
    would not change the surface, but there is no reason to differ from the file.
    Returns vertices (n, 3) float64 and faces (m, 3) int64.
    """
    mesh = trimesh.load_mesh(str(path), process=False)
    if isinstance(mesh, trimesh.Scene):  # some loaders still hand back a scene
        mesh = mesh.to_mesh()
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ValueError(f"{path}: no triangles found")
    if not np.all(np.isfinite(vertices)):
        raise ValueError(f"{path}: mesh has non-finite vertices")
    return vertices, faces


def _bsdf_dict(material: dict | None, name: str) -> dict:
    """Mitsuba BSDF dict for a contract material (None = black), wrapped in `twosided`."""
    if material is None:
        # The contract's "no material": reflects nothing, but still occludes.
        inner = {"type": "diffuse", "reflectance": _rgb([0.0, 0.0, 0.0], name)}
    else:
        kind = material.get("type")
        where = f"materials.{name}"
        if kind == "diffuse":
            inner = {"type": "diffuse", "reflectance": _rgb(material["reflectance"], where)}
        elif kind == "roughconductor":
            # material='none' makes Mitsuba's conductor Fresnel term exactly 1; the colour is
            # carried by specular_reflectance.  Mitsuba's GGX uses alpha as given and the
            # separable Smith G1(wi) G1(wo), matching the contract.  Mitsuba clamps alpha to
            # at least 1e-4 internally, so smaller alphas would silently differ: refuse them.
            if float(material["alpha"]) < MIN_MITSUBA_ALPHA:
                raise ValueError(f"{where}.alpha: {material['alpha']} is below Mitsuba's "
                                 f"internal minimum {MIN_MITSUBA_ALPHA}; no faithful reference")
            inner = {
                "type": "roughconductor",
                "distribution": "ggx",
                "alpha": float(material["alpha"]),
                "material": "none",
                "specular_reflectance": _rgb(material["reflectance"], where),
                "sample_visible": True,
            }
        elif kind == "mirror":
            inner = {
                "type": "conductor",
                "material": "none",
                "specular_reflectance": _rgb(material["reflectance"], where),
            }
        else:
            raise ValueError(f"{where}.type: unknown material type {kind!r}")
    return {"type": "twosided", "material": inner}


def _make_mesh(mi, name: str, vertices: np.ndarray, faces: np.ndarray, bsdf: dict,
               emission=None):
    """An `mi.Mesh` with face normals only, the given BSDF and an optional area emitter.

    vertices: (n, 3) float, faces: (m, 3) int.  Building the mesh in memory (instead of writing
    a PLY file) avoids temporary files and guarantees no vertex normals are computed.
    """
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    if emission is not None:
        props["emitter"] = mi.load_dict({"type": "area", "radiance": _rgb(emission, name)})
    mesh = mi.Mesh(name, len(vertices), len(faces), props=props,
                   has_vertex_normals=False, has_vertex_texcoords=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = type(params["vertex_positions"])(
        np.ascontiguousarray(vertices, dtype=np.float32).ravel())
    params["faces"] = type(params["faces"])(np.ascontiguousarray(faces, dtype=np.uint32).ravel())
    params.update()
    return mesh


def read_toml(scene_path: str | pathlib.Path) -> dict:
    """Parse the scene file; the caller gets the raw TOML tables."""
    with open(scene_path, "rb") as f:
        return tomllib.load(f)


def camera_dict(camera: dict, width: int | None = None, height: int | None = None) -> dict:
    """Mitsuba `perspective` sensor dict (without sampler) for the contract's pinhole camera.

    `width`/`height` override the file's resolution when given.
    """
    mi = _mi()
    origin = _vec3(camera["origin"], "camera.origin")
    target = _vec3(camera["target"], "camera.target")
    up = _vec3(camera["up"], "camera.up")
    fov = float(camera["fov"])
    f = target - origin
    if np.linalg.norm(f) == 0 or np.linalg.norm(np.cross(f, up)) == 0 or not 0 < fov < 180:
        raise ValueError("camera: degenerate (target == origin, up parallel to the view "
                         "direction, or fov outside (0, 180))")
    w = int(width if width is not None else camera["width"])
    h = int(height if height is not None else camera["height"])
    return {
        "type": "perspective",
        "fov_axis": "y",
        "fov": fov,
        # Mitsuba clips at near_clip along the optical axis; the default 1e-2 is far below
        # any distance in our unit-scale scenes.
        "to_world": mi.ScalarTransform4f().look_at(
            origin=origin.tolist(), target=target.tolist(), up=up.tolist()),
        "film": {
            "type": "hdrfilm",
            "width": w,
            "height": h,
            "pixel_format": "rgb",
            "component_format": "float32",
            "rfilter": {"type": "box"},
        },
    }


def load_mitsuba_scene(scene_path: str, spp: int, seed: int, width=None, height=None,
                       emitter_samples=1, bsdf_samples=1) -> dict:
    """Build a Mitsuba 3 scene dict equivalent to the `tracer` scene file `scene_path`.

    Pass the result to `mi.load_dict`.  Shapes are `mi.Mesh` instances, so a Mitsuba variant
    must be active (`scalar_rgb` is selected if none is).  The sampler is `independent` with
    `spp` samples per pixel and `seed`; the integrator is `direct` with `emitter_samples`
    light samples and `bsdf_samples` BSDF samples per camera sample, combined by Mitsuba with
    the power heuristic.  `width`/`height` override the camera's resolution.  The `[render]`
    table is ignored: the caller chooses spp.
    """
    mi = _mi()
    scene_path = pathlib.Path(scene_path)
    data = read_toml(scene_path)
    base_dir = scene_path.parent

    sensor = camera_dict(data["camera"], width, height)
    sensor["sampler"] = {"type": "independent", "sample_count": int(spp), "seed": int(seed)}

    scene: dict = {
        "type": "scene",
        "integrator": {
            "type": "direct",
            "emitter_samples": int(emitter_samples),
            "bsdf_samples": int(bsdf_samples),
        },
        "sensor": sensor,
    }

    materials = data.get("materials", {})
    for i, shape in enumerate(data.get("shapes", [])):
        where = f"shapes[{i}]"
        kind = shape.get("type")
        if kind == "quad":
            vertices, faces = quad_triangles(_vec3(shape["origin"], f"{where}.origin"),
                                             _vec3(shape["edge1"], f"{where}.edge1"),
                                             _vec3(shape["edge2"], f"{where}.edge2"))
        elif kind == "sphere" and "subdivisions" not in shape:
            # A true sphere (tracer >= 0.3): Mitsuba's analytic `sphere`, which its `area`
            # emitter samples by the subtended cone, as tracer's solid-angle sampling does.
            mat_name = shape.get("material")
            if mat_name is not None and mat_name not in materials:
                raise ValueError(f"{where}.material: unknown material {mat_name!r}")
            sphere = {"type": "sphere", "center": _vec3(shape["center"], f"{where}.center").tolist(),
                      "radius": float(shape["radius"]),
                      "bsdf": _bsdf_dict(materials[mat_name] if mat_name is not None else None,
                                         mat_name or where)}
            if shape.get("emission") is not None:
                sphere["emitter"] = {"type": "area", "radiance": _rgb(shape["emission"], where)}
            scene[f"shape_{i}"] = sphere
            continue
        elif kind == "sphere":
            vertices, faces = sphere_triangles(_vec3(shape["center"], f"{where}.center"),
                                               float(shape["radius"]),
                                               int(shape.get("subdivisions", DEFAULT_SUBDIVISIONS)))
        elif kind == "mesh":
            vertices, faces = mesh_file_triangles(base_dir / shape["file"])
        else:
            raise ValueError(f"{where}.type: unknown shape type {kind!r}")

        mat_name = shape.get("material")
        if mat_name is not None and mat_name not in materials:
            raise ValueError(f"{where}.material: unknown material {mat_name!r}")
        bsdf = _bsdf_dict(materials[mat_name] if mat_name is not None else None,
                          mat_name or where)
        scene[f"shape_{i}"] = _make_mesh(mi, f"shape_{i}", vertices, faces, bsdf,
                                         shape.get("emission"))

    for i, light in enumerate(data.get("lights", [])):
        where = f"lights[{i}]"
        if light.get("type") != "point":
            raise ValueError(f"{where}.type: unknown light type {light.get('type')!r}")
        scene[f"light_{i}"] = {
            "type": "point",
            "position": _vec3(light["position"], f"{where}.position").tolist(),
            # Radiant intensity (W/sr), exactly Mitsuba's `intensity`.
            "intensity": _rgb(light["intensity"], f"{where}.intensity"),
        }
    return scene


def project_point(camera: dict, point, width: int, height: int) -> tuple[float, float]:
    """Film position (px, py) in pixels of a world point, from the contract's camera formula.

    Inverse of d = normalize(f + (2 px/W - 1) t (W/H) r + (1 - 2 py/H) t u), t = tan(fov/2).
    Used only by the convention checks: it is written from the contract, not from Mitsuba.
    """
    origin = _vec3(camera["origin"], "camera.origin")
    f = _vec3(camera["target"], "camera.target") - origin
    f /= np.linalg.norm(f)
    r = np.cross(f, _vec3(camera["up"], "camera.up"))
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    d = np.asarray(point, dtype=np.float64) - origin
    d = d / np.dot(d, f)  # scale so that the f component is 1
    t = math.tan(math.radians(float(camera["fov"])) / 2)
    px = (np.dot(d, r) / (t * width / height) + 1) * width / 2
    py = (1 - np.dot(d, u) / t) * height / 2
    return float(px), float(py)
