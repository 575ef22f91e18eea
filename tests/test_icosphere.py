"""tracer's own icosphere against trimesh's, which tracer used before and which the shipped
references and every scene digest of a sphere were made with."""

import subprocess
import sys

import numpy as np
import pytest
import trimesh

from tracer.scene import default_scene_path
from tracer.scene.icosphere import unit_icosphere


@pytest.mark.parametrize("subdivisions", range(8))  # the range the scene reader allows
def test_bit_identical_to_trimesh(subdivisions):
    # Exact equality, not a tolerance: any difference in a vertex's last bit or in the order of
    # faces changes the scene digest and the sequence of random numbers each triangle receives.
    reference = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    vertices, faces = unit_icosphere(subdivisions)
    assert vertices.dtype == np.float64
    assert np.array_equal(vertices, np.asarray(reference.vertices))
    assert np.array_equal(faces, np.asarray(reference.faces))


def test_closed_outward_sphere():
    # Independent of trimesh: all vertices on the unit sphere, every edge shared by exactly two
    # faces in opposite directions (closed and consistently wound), and normals pointing out.
    vertices, faces = unit_icosphere(3)
    assert np.allclose(np.linalg.norm(vertices, axis=1), 1.0, rtol=0, atol=1e-15)
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    assert len({tuple(e) for e in directed.tolist()}) == len(directed)
    assert {tuple(e) for e in directed[:, ::-1].tolist()} == {tuple(e) for e in directed.tolist()}
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c)
    assert np.all(outward > 0)


def test_a_scene_without_mesh_files_does_not_import_trimesh():
    # The point of the own icosphere: trimesh (and the scipy.spatial it pulls in) costs about
    # 0.7 s of start-up, so a fresh interpreter reading a scene of quads and spheres must not
    # import it; cornell, with two PLY meshes, must, which shows the probe sees the import.
    probe = ("import sys; from tracer.scene import load_scene; load_scene(sys.argv[1]); "
             "print('trimesh' in sys.modules)")
    meshless = subprocess.run([sys.executable, "-c", probe, str(default_scene_path())],
                              capture_output=True, text=True, check=True)
    assert meshless.stdout.strip() == "False"
    cornell = default_scene_path().parent / "cornell.toml"
    with_mesh = subprocess.run([sys.executable, "-c", probe, str(cornell)], capture_output=True, text=True,
                               check=True)
    assert with_mesh.stdout.strip() == "True"
