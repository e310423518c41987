"""Every mesh format `isotope extract -o` writes, read back by a reader that is not ours.

The PLY of the same extraction is the reference (its layout is pinned by tests/io/mesh_formats_test.cpp); each
other format must give the same vertex and triangle counts and the same bounds, exactly (floats
are stored as they are, or as their shortest exact text):
- .vtp through VTK's XML PolyData reader (python3-vtk9, what ParaView uses), with its normals;
- .obj and .stl parsed here with numpy (no mesh library), and through VTK's OBJ and STL readers;
- .glb through the Khronos glTF validator (npm, tests/formats/package-lock.json): no error, no
  warning, its counts, and the bounds of the position accessor, whose min and max it checks
  against the data.
Run by scripts/test.sh (pytest) with ISOTOPE pointing at the command.
"""

import json
import os
import pathlib
import struct
import subprocess

import numpy as np
import pytest
import vtk
from vtk.util.numpy_support import vtk_to_numpy

HERE = pathlib.Path(__file__).resolve().parent
DATA = HERE.parents[2] / "shared" / "data"
ISOTOPE = os.environ.get("ISOTOPE", str(HERE.parents[1] / "build-ci" / "tools" / "isotope"))

# (volume, isovalue, eps): adaptive and full resolution, two shared volumes, and a mesh with no
# triangle at all (an isovalue above every value).
CASES = [
    ("bolt_70x123x66_uint8.raw", "64.5", "4"),
    ("neghip_66x66x66_uint8.raw", "30.5", "0"),
    ("bolt_70x123x66_uint8.raw", "300", "0"),
]


def extract(tmp, volume, iso, eps, ext):
    path = tmp / f"mesh.{ext}"
    subprocess.run([ISOTOPE, "extract", str(DATA / volume), "--iso", iso, "--eps", eps, "-q", "-o", str(path)],
                   check=True)
    return path


def read_ply(path):
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    head = data[:end].decode()
    n = int(head.split("element vertex ")[1].split()[0])
    m = int(head.split("element face ")[1].split()[0])
    vertices = np.frombuffer(data, dtype="<f4", count=3 * n, offset=end).reshape(n, 3)
    faces = np.frombuffer(data, dtype=np.dtype([("k", "u1"), ("i", "<i4", 3)]), count=m, offset=end + 12 * n)
    assert (faces["k"] == 3).all()
    return vertices, faces["i"]


def bounds(vertices):
    if len(vertices) == 0:
        return None
    return vertices.min(axis=0).tolist(), vertices.max(axis=0).tolist()


def vtk_bounds(poly):
    if poly.GetNumberOfPoints() == 0:
        return None
    b = poly.GetBounds()
    return [b[0], b[2], b[4]], [b[1], b[3], b[5]]


@pytest.fixture(params=CASES, ids=lambda c: f"{c[0].split('_')[0]}-iso{c[1]}-eps{c[2]}")
def case(request, tmp_path):
    volume, iso, eps = request.param
    vertices, faces = read_ply(extract(tmp_path, volume, iso, eps, "ply"))
    return tmp_path, request.param, vertices, faces


def test_vtp_through_vtk(case):
    tmp, params, vertices, faces = case
    reader = vtk.vtkXMLPolyDataReader()
    reader.SetFileName(str(extract(tmp, *params, "vtp")))
    reader.Update()
    assert reader.GetErrorCode() == 0
    poly = reader.GetOutput()
    assert poly.GetNumberOfPoints() == len(vertices)
    assert poly.GetNumberOfPolys() == len(faces)
    assert vtk_bounds(poly) == bounds(vertices)
    if len(faces):
        np.testing.assert_array_equal(vtk_to_numpy(poly.GetPoints().GetData()), vertices)
        cells = vtk_to_numpy(poly.GetPolys().GetConnectivityArray()).reshape(-1, 3)
        np.testing.assert_array_equal(cells, faces)
        normals = vtk_to_numpy(poly.GetPointData().GetNormals())
        assert normals.shape == vertices.shape
        length = np.linalg.norm(normals, axis=1)
        assert np.all((np.abs(length - 1) < 1e-5) | (length == 0))


def test_obj_parsed_and_through_vtk(case):
    tmp, params, vertices, faces = case
    path = extract(tmp, *params, "obj")
    v, f = [], []
    for line in path.read_text().splitlines():
        if line.startswith("v "):
            v.append([float(t) for t in line.split()[1:]])
        elif line.startswith("f "):
            f.append([int(t) - 1 for t in line.split()[1:]])
    v = np.array(v, dtype=np.float32).reshape(-1, 3)
    np.testing.assert_array_equal(v, vertices)  # shortest exact text: every float comes back
    np.testing.assert_array_equal(np.array(f).reshape(-1, 3), faces)
    reader = vtk.vtkOBJReader()
    reader.SetFileName(str(path))
    reader.Update()
    poly = reader.GetOutput()
    assert poly.GetNumberOfPolys() == len(faces)
    assert vtk_bounds(poly) == bounds(vertices)


def test_stl_parsed_and_through_vtk(case):
    tmp, params, vertices, faces = case
    path = extract(tmp, *params, "stl")
    data = path.read_bytes()
    assert not data.startswith(b"solid")  # else readers take it for the text format
    (m,) = struct.unpack_from("<I", data, 80)
    assert len(data) == 84 + 50 * m
    assert m == len(faces)
    records = np.frombuffer(data, offset=84, count=m,
                            dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    np.testing.assert_array_equal(records["v"], vertices[faces])
    if m:
        # each facet normal is the unit normal of its corners, counter-clockwise seen from outside
        cross = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
        length = np.linalg.norm(cross, axis=1)
        ok = length > 1e-12
        np.testing.assert_allclose(records["n"][ok], cross[ok] / length[ok, None], atol=1e-4)
    # STL keeps no shared vertices: distinct corners are the mesh's distinct positions
    assert len(np.unique(records["v"].reshape(-1, 3), axis=0)) == len(np.unique(vertices, axis=0))
    reader = vtk.vtkSTLReader()
    reader.SetFileName(str(path))
    reader.Update()
    poly = reader.GetOutput()
    assert poly.GetNumberOfPolys() == len(faces)
    assert vtk_bounds(poly) == bounds(vertices)


def test_glb_through_the_khronos_validator(case):
    tmp, params, vertices, faces = case
    path = extract(tmp, *params, "glb")
    report = json.loads(subprocess.run(["node", str(HERE / "validate_gltf.js"), str(path)], check=True,
                                       capture_output=True, text=True).stdout)
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"]
    assert report["issues"]["numWarnings"] == 0, report["issues"]["messages"]
    assert report["info"]["totalVertexCount"] == len(vertices)
    assert report["info"]["totalTriangleCount"] == len(faces)
    data = path.read_bytes()
    (json_length,) = struct.unpack_from("<I", data, 12)
    gltf = json.loads(data[20:20 + json_length])
    if len(faces) == 0:
        assert "meshes" not in gltf
        return
    position = gltf["accessors"][gltf["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    assert (position["min"], position["max"]) == bounds(vertices)
