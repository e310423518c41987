"""The Python face (python/isotope, python/src/module.cpp): the same meshes as the command, byte
for byte; arrays of every supported dtype, borrowed when they are float32 in C order; stores and
repeated extraction; progress, cancellation and the GIL; errors with the command's words; and,
against scikit-image's marching_cubes on the same volume, the same enclosed volume and box."""

import ctypes
import json
import os
import re
import subprocess
import threading
import time

import numpy as np
import pytest

import isotope

# (file, isovalue, a coarse eps in data units): every shared volume at its first suggested isovalue.
VOLUMES = [
    ("bolt_70x123x66_uint8.raw", 64.5, 8),
    ("neghip_66x66x66_uint8.raw", 32.5, 8),
    ("ironProt_68x68x68_uint8.raw", 32.5, 8),
    ("hydrogen_64x64x64_float32.raw", 0.005, 0.01),
    ("embryo_256x256x256_uint8.raw", 64.5, 16),
]


def load(data, name):
    m = re.search(r"_(\d+)x(\d+)x(\d+)_(\w+)\.raw$", name)
    x, y, z = (int(v) for v in m.group(1, 2, 3))
    return np.fromfile(data / name, dtype=m.group(4)).reshape(z, y, x)  # a[z, y, x]


def command(isotope_command, *args):
    return subprocess.run([isotope_command, *args], capture_output=True, text=True)


def cli_mesh(isotope_command, tmp_path, volume, iso, eps):
    out = tmp_path / "cli.ply"
    r = command(isotope_command, "extract", str(volume), "--iso", repr(iso), "--eps", repr(eps), "-q", "-o", str(out))
    assert r.returncode == 0, r.stderr
    return out.read_bytes()


def ply_bytes(mesh, tmp_path, name="py.ply"):
    mesh.save(tmp_path / name)
    return (tmp_path / name).read_bytes()


def test_three_lines_from_a_numpy_array(data):
    volume = load(data, "bolt_70x123x66_uint8.raw")
    mesh = isotope.extract(volume, iso=64.5, eps=4)
    assert mesh.vertices.dtype == np.float32 and mesh.vertices.shape[1] == 3
    assert mesh.faces.dtype == np.uint32 and mesh.faces.shape[1] == 3
    assert mesh.normals.shape == mesh.vertices.shape
    assert mesh.stats["triangles"] == len(mesh.faces) > 1000
    assert mesh.faces.max() < len(mesh.vertices)
    np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1, atol=1e-5)
    # x, y, z columns: the box of a[z, y, x] is x < 70, y < 123, z < 66
    assert (mesh.vertices.max(axis=0) <= [69, 122, 65]).all()
    topology = mesh.topology()
    assert topology["boundary_edges"] == 0 and topology["components"] >= 1


@pytest.mark.parametrize("name,iso,coarse", VOLUMES, ids=[v[0].split("_")[0] for v in VOLUMES])
def test_same_bytes_as_the_command_from_an_array_and_from_the_file(data, isotope_command, tmp_path, name, iso, coarse):
    volume = load(data, name)
    for eps in (0, coarse):
        want = cli_mesh(isotope_command, tmp_path, data / name, iso, eps)
        assert ply_bytes(isotope.extract(volume, iso=iso, eps=eps), tmp_path) == want, f"array, eps {eps}"
        assert ply_bytes(isotope.extract(data / name, iso=iso, eps=eps), tmp_path) == want, f"file, eps {eps}"


def test_every_dtype_and_layout_gives_the_same_mesh(data):
    base = load(data, "neghip_66x66x66_uint8.raw")
    want = isotope.extract(base, iso=32.5, eps=4)
    for dtype in (np.uint8, np.uint16, np.int16, np.float32, np.float64):
        got = isotope.extract(base.astype(dtype), iso=32.5, eps=4)
        np.testing.assert_array_equal(got.vertices, want.vertices, err_msg=str(dtype))
        np.testing.assert_array_equal(got.faces, want.faces, err_msg=str(dtype))
    # A view that is not in C order (Fortran order, a reversed axis) is read as the values it shows.
    fortran = np.asfortranarray(base.astype(np.float32))
    np.testing.assert_array_equal(isotope.extract(fortran, iso=32.5, eps=4).faces, want.faces)
    flipped = isotope.extract(base[:, :, ::-1], iso=32.5)
    copied = isotope.extract(np.ascontiguousarray(base[:, :, ::-1]), iso=32.5)
    np.testing.assert_array_equal(flipped.vertices, copied.vertices)


def resident_bytes():
    # Freed memory the allocator keeps (the library raises glibc's trim threshold for its brick
    # cache) would hold a new copy without growing the resident set: give it back first.
    ctypes.CDLL(None).malloc_trim(0)
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def test_a_float32_array_in_c_order_is_read_without_a_copy(data):
    # The process's resident memory sees a copy wherever it is made, numpy's or the library's.
    floats = load(data, "embryo_256x256x256_uint8.raw").astype(np.float32)  # 64 MiB, touched
    before = resident_bytes()
    source = isotope.Source(floats)
    borrowed = resident_bytes() - before
    before = resident_bytes()
    converted = isotope.Source(floats.astype(np.float64))  # held as a float32 copy (the float64 is freed)
    copied = resident_bytes() - before
    assert borrowed < 4 << 20, borrowed
    assert copied > 48 << 20, copied  # the measure sees a copy: this one is 64 MiB
    del converted
    assert source.info["dims"] == [256, 256, 256]
    # and the borrowed array is held: the source outlives the name
    del floats
    assert len(source.extract(iso=64.5).faces) > 0


def test_a_store_is_opened_once_and_extracted_from_repeatedly(data, tmp_path):
    volume = load(data, "bolt_70x123x66_uint8.raw")
    stats = isotope.convert(volume, tmp_path / "bolt.isotope", memory_mb=64)
    assert stats["dims"] == [70, 123, 66] and stats["output_bytes"] > 0
    store = isotope.Source(tmp_path / "bolt.isotope", cache_mb=16)
    assert store.info["store"] and store.info["shape"] == (66, 123, 70)
    for eps in (0, 8, 0):
        a, b = store.extract(iso=64.5, eps=eps), isotope.extract(volume, iso=64.5, eps=eps)
        np.testing.assert_array_equal(a.vertices, b.vertices)
        np.testing.assert_array_equal(a.faces, b.faces)
    assert store.info["bytes_read"] > 0
    # reads that waited for the disk, and read-ahead hints only once one has
    waits, hints = store.info["read_waits"], store.info["read_hints"]
    assert isinstance(waits, int) and isinstance(hints, int)
    assert waits >= 0 and (hints == 0 or waits > 0)
    # a budget asked for again of the same Source is the first choice, remembered
    first, again = (store.extract(iso=64.5, topology="none", max_triangles=5000) for _ in range(2))
    assert not first.stats["budget_remembered"] and again.stats["budget_remembered"]
    assert again.stats["chosen_eps"] == first.stats["chosen_eps"] > 0
    np.testing.assert_array_equal(again.faces, first.faces)
    np.testing.assert_array_equal(again.vertices, first.vertices)
    # the file converted by the command is the same store
    isotope.convert(data / "bolt_70x123x66_uint8.raw", tmp_path / "from_file.isotope")
    assert (tmp_path / "from_file.isotope").read_bytes() != b""


def test_the_command_and_the_module_report_the_stats_under_the_same_names(data, isotope_command, tmp_path):
    # a budget (its choice reported) under simplify with an automatic delta (its choice reported)
    volume = data / "bolt_70x123x66_uint8.raw"
    mesh = isotope.Source(volume).extract(iso=64.5, max_triangles=20000, topology="simplify")
    report = tmp_path / "r.json"
    r = command(isotope_command, "extract", str(volume), "--iso", "64.5", "--max-triangles", "20000",
                "--topology", "simplify", "-q", "-o", str(tmp_path / "m.ply"), "--report", str(report))
    assert r.returncode == 0, r.stderr
    j = json.loads(report.read_text())
    fields = {**{k: v for k, v in j["extract"].items() if k != "seconds"},
              **{k: j[k] for k in ("chosen_eps", "chosen_eps_ties", "next_eps", "next_eps_ties", "next_triangles",
                                   "budget_steps", "budget_sampled", "budget_remembered", "chosen_delta",
                                   "delta_floor_triangles")}}
    assert j["triangles"] == mesh.stats["triangles"] > 0 and fields["chosen_delta"] >= 0
    assert {k: mesh.stats[k] for k in fields} == fields
    assert set(mesh.stats) == set(fields) | {"seconds", "vertices", "triangles"}


def test_options_reach_the_library(data):
    volume = load(data, "bolt_70x123x66_uint8.raw")
    full = isotope.extract(volume, iso=64.5)
    budget = isotope.extract(volume, iso=64.5, max_triangles=20000)
    assert len(budget.faces) <= 20000 < len(full.faces) and budget.stats["chosen_eps"] > 0
    # the budget's mesh again from its eps and tie classes
    again = isotope.extract(volume, iso=64.5, eps=budget.stats["chosen_eps"], eps_ties=budget.stats["chosen_eps_ties"])
    assert budget.stats["chosen_eps_ties"] >= 0
    np.testing.assert_array_equal(again.faces, budget.faces)
    # a budget the full-resolution mesh fits is that mesh, counted, with no hierarchy built
    store = isotope.Source(volume)
    whole = store.extract(iso=64.5, max_triangles=len(full.faces))
    np.testing.assert_array_equal(whole.faces, full.faces)
    np.testing.assert_array_equal(whole.vertices, full.vertices)
    assert whole.stats["chosen_eps"] == 0 and whole.stats["next_triangles"] == 0
    assert not store.info["hierarchy_built"]
    store.extract(iso=64.5, max_triangles=len(full.faces) - 1)
    assert store.info["hierarchy_built"]
    # mode none builds the records' core alone, its critical points not counted; preserve counts them
    source = isotope.Source(volume)
    source.extract(iso=64.5, eps=8, topology="none")
    assert source.info["hierarchy_built"] and not source.info["critical_counted"]
    assert source.info["critical_exact"] is None and source.info["critical_paper"] is None
    source.extract(iso=64.5, eps=8)
    assert source.info["critical_counted"] and sum(source.info["critical_exact"]) > 0
    simplified = isotope.extract(volume, iso=64.5, eps=32, topology="simplify", delta=50)
    preserved = isotope.extract(volume, iso=64.5, eps=32)
    assert len(simplified.faces) <= len(preserved.faces)
    focused = isotope.extract(volume, iso=64.5, eps=32, focus=(35, 60, 30), radius=10)
    assert len(preserved.faces) < len(focused.faces) < len(full.faces)
    spaced = isotope.extract(volume, iso=64.5, spacing=(0.5, 0.5, 2), origin=(10, 0, 0))
    np.testing.assert_allclose(spaced.vertices, full.vertices * [0.5, 0.5, 2] + [10, 0, 0], rtol=1e-6)


def test_options_are_set_from_their_values(data):
    # Numbers go to the library as numbers (numpy's too), names and typed text ("1/64") as the
    # command reads them: the same options, the same mesh.
    volume = load(data, "bolt_70x123x66_uint8.raw")
    base = isotope.extract(volume, iso=64.5, eps=4, focus=(35, 60, 30), radius=10)
    assert len(base.faces) != len(isotope.extract(volume, iso=64.5, eps=4, focus=(35, 60, 30), radius=20).faces)
    for kw in (dict(eps="8/2"), dict(eps=np.float32(4)), dict(iso=np.float64(64.5)),
               dict(focus=np.array([35, 60, 30])), dict(focus=("70/2", 60, 30)), dict(radius="10"),
               dict(radius=10.0)):
        args = dict(iso=64.5, eps=4, focus=(35, 60, 30), radius=10)
        args.update(kw)
        mesh = isotope.extract(volume, **args)
        np.testing.assert_array_equal(mesh.faces, base.faces, err_msg=str(kw))
        np.testing.assert_array_equal(mesh.vertices, base.vertices, err_msg=str(kw))
    budget = isotope.extract(volume, iso=64.5, max_triangles=1000)
    assert len(isotope.extract(volume, iso=64.5, max_triangles=1000.0).faces) == len(budget.faces)
    for kw, option, words in ((dict(focus=(1, 2), radius=3), "focus", "must be three numbers X,Y,Z"),
                              (dict(max_triangles=1.5), "max-triangles", "must be an integer in 1 .."),
                              (dict(eps=True), "eps", "must be a number or a name"),
                              (dict(eps=[1]), "eps", "must be a number"),
                              (dict(eps=1j), "eps", "must be a number"),
                              (dict(focus=(True, 2, 3), radius=3), "focus", "must be three numbers X,Y,Z"),
                              (dict(iso=10 ** 40), "iso", "is out of the float range"),
                              (dict(max_triangles=2 ** 70), "max-triangles", "got '1180591620717411303424'"),
                              (dict(eps="1" * 200), "eps", "is too long")):
        with pytest.raises(isotope.OptionError) as e:
            isotope.extract(volume, **{"iso": 64.5, **kw})
        assert e.value.option == option and words in str(e.value), (kw, str(e.value))


def test_errors_carry_the_commands_words(data, isotope_command, tmp_path):
    missing = str(tmp_path / "missing_8x8x8_uint8.raw")
    with pytest.raises(isotope.IoError) as e:
        isotope.extract(missing, iso=1)
    cli = command(isotope_command, "extract", missing, "--iso", "1", "-o", str(tmp_path / "m.ply"))
    assert cli.returncode == 1 and f"isotope: error: {e.value}" in cli.stderr
    assert isinstance(e.value, OSError)

    volume = load(data, "neghip_66x66x66_uint8.raw")
    for option, value, flag in (("eps", -1, "--eps"), ("topology", "bogus", "--topology"),
                                ("delta", 2, "--delta")):
        with pytest.raises(isotope.OptionError) as e:
            isotope.extract(volume, iso=30, **{option: value})
        assert e.value.option == option
        assert isinstance(e.value, ValueError)
        cli = command(isotope_command, "extract", str(data / "neghip_66x66x66_uint8.raw"), "--iso", "30", flag,
                      str(value), "-o", str(tmp_path / "m.ply"))
        assert cli.returncode == 2
        assert str(e.value)[len(option) + 1:] in cli.stderr, (str(e.value), cli.stderr)

    with pytest.raises(ValueError, match="a volume is a 3-D array"):
        isotope.extract(np.zeros((4, 4)), iso=0)
    with pytest.raises(TypeError, match="got int32"):
        isotope.extract(np.zeros((4, 4, 4), dtype=np.int32), iso=0)
    with pytest.raises(ValueError, match="not finite"):
        isotope.extract(np.full((4, 4, 4), np.nan, dtype=np.float32), iso=0)
    with pytest.raises(isotope.IoError, match="unknown mesh format '.xyz'"):
        isotope.extract(volume, iso=30).save(tmp_path / "m.xyz")
    assert not (tmp_path / "m.xyz").exists()


def test_progress_is_heard_and_an_exception_in_it_cancels(data, tmp_path):
    volume = load(data, "embryo_256x256x256_uint8.raw")
    heard = []
    store = isotope.Source(volume, progress=heard.append)
    store.extract(iso=64.5, eps=16)  # builds the hierarchy: the step that reports
    assert len(heard) > 10 and heard == sorted(heard) and heard[-1] == 1.0

    def stop(fraction):
        if fraction > 0.2:
            raise KeyError("stop here")

    with pytest.raises(KeyError, match="stop here"):
        isotope.convert(volume, tmp_path / "embryo.isotope", progress=stop)
    assert list(tmp_path.iterdir()) == []  # nothing half-written


def test_the_gil_is_released_while_the_library_works(data):
    volume = load(data, "embryo_256x256x256_uint8.raw")
    done = threading.Event()
    result = {}

    def work():
        result["mesh"] = isotope.extract(volume, iso=64.5, eps=16)
        done.set()

    thread = threading.Thread(target=work)
    ticks = 0
    thread.start()
    while not done.is_set():
        ticks += 1
        time.sleep(0.005)
    thread.join()
    assert len(result["mesh"].faces) > 0
    assert ticks > 20  # about a second of work: this thread ran all along


def test_every_mesh_format_is_written(data, tmp_path):
    mesh = isotope.extract(load(data, "bolt_70x123x66_uint8.raw"), iso=64.5, eps=8)
    for ext in ("ply", "obj", "stl", "glb", "vtp"):
        mesh.save(tmp_path / f"bolt.{ext}")
        assert (tmp_path / f"bolt.{ext}").stat().st_size > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"bolt.{e}" for e in ("glb", "obj", "ply", "stl", "vtp")]


def test_a_tiff_stack_is_a_volume(data, tmp_path):
    tifffile = pytest.importorskip("tifffile")  # python3-tifffile; a skip fails the run (conftest.py)
    volume = load(data, "bolt_70x123x66_uint8.raw")
    tifffile.imwrite(tmp_path / "bolt.tif", volume, compression="zlib", photometric="minisblack")  # one page per z
    (tmp_path / "slices").mkdir()
    for z in range(volume.shape[0]):
        tifffile.imwrite(tmp_path / "slices" / f"bolt{z}.tif", volume[z], photometric="minisblack")
    want = isotope.extract(volume, iso=64.5, eps=8)
    for stack in (tmp_path / "bolt.tif", tmp_path / "slices"):
        got = isotope.extract(stack, iso=64.5, eps=8)
        np.testing.assert_array_equal(got.vertices, want.vertices)
        np.testing.assert_array_equal(got.faces, want.faces)


def enclosed_volume(vertices, faces):
    v = vertices.astype(np.float64)
    a, b, c = v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]]
    return abs(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)


def area(vertices, faces):
    v = vertices.astype(np.float64)
    return np.linalg.norm(np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]]), axis=1).sum() / 2


@pytest.mark.parametrize("name,iso,coarse", VOLUMES, ids=[v[0].split("_")[0] for v in VOLUMES])
def test_eps_zero_against_scikit_image_marching_cubes(data, name, iso, coarse):
    from skimage import measure

    # A border below the isovalue closes every surface, for both, so that volumes are defined.
    volume = np.pad(load(data, name).astype(np.float32), 1, constant_values=min(0.0, iso - 1))
    mesh = isotope.extract(volume, iso=iso)
    verts, faces, _, _ = measure.marching_cubes(volume, level=iso)
    verts = verts[:, ::-1]  # skimage gives (z, y, x)
    ours, theirs = enclosed_volume(mesh.vertices, mesh.faces), enclosed_volume(verts, faces)
    ratio = area(mesh.vertices, mesh.faces) / area(verts, faces)
    print(f"\n{name} iso {iso}: enclosed volume {ours:.1f} vs {theirs:.1f} ({ours / theirs - 1:+.3%}), "
          f"area ratio marching tetrahedra / cubes {ratio:.3f}, triangles {len(mesh.faces)} vs {len(faces)}")
    assert abs(ours / theirs - 1) < 0.01
    np.testing.assert_allclose(mesh.vertices.min(axis=0), verts.min(axis=0), atol=1)
    np.testing.assert_allclose(mesh.vertices.max(axis=0), verts.max(axis=0), atol=1)


def test_the_arrays_make_a_closed_vtk_surface(data):
    """What the README hands to pyvista (a thin layer over VTK): points and [3, a, b, c, ...] cells."""
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray

    mesh = isotope.extract(load(data, "bolt_70x123x66_uint8.raw"), iso=64.5, eps=8)
    cells = np.column_stack([np.full(len(mesh.faces), 3), mesh.faces]).ravel()  # as in the README
    points = vtk.vtkPoints()
    points.SetData(numpy_to_vtk(mesh.vertices, deep=True))
    polys = vtk.vtkCellArray()
    polys.SetCells(len(mesh.faces), numpy_to_vtkIdTypeArray(cells.astype(np.int64), deep=True))
    poly = vtk.vtkPolyData()
    poly.SetPoints(points)
    poly.SetPolys(polys)
    edges = vtk.vtkFeatureEdges()
    edges.SetInputData(poly)
    edges.BoundaryEdgesOn()
    edges.NonManifoldEdgesOn()
    edges.FeatureEdgesOff()
    edges.ManifoldEdgesOff()
    edges.Update()
    assert poly.GetNumberOfCells() == len(mesh.faces)
    assert edges.GetOutput().GetNumberOfCells() == 0  # closed and manifold, as VTK sees it
    mass = vtk.vtkMassProperties()
    mass.SetInputData(poly)
    mass.Update()
    assert abs(mass.GetVolume() - enclosed_volume(mesh.vertices, mesh.faces)) < 1e-3 * mass.GetVolume()


def test_ctrl_c_stops_the_work_and_leaves_nothing(tmp_path):
    import signal
    import sys

    # Noise of 320^3 takes seconds to convert on 2 cores: long enough to be interrupted anywhere.
    # Python leaves SIGINT ignored when it starts ignored (as in a job a shell put in the
    # background): the child asks for Ctrl-C's usual handler, as an interactive session has it.
    script = ("import signal, sys, numpy as np, isotope\n"
              "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
              "a = np.random.default_rng(0).random((320, 320, 320), dtype=np.float32)\n"
              "print('ready', flush=True)\n"
              "isotope.convert(a, sys.argv[1])\n"
              "print('finished', flush=True)\n")
    output = tmp_path / "noise.isotope"
    child = subprocess.Popen([sys.executable, "-c", script, str(output)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    assert child.stdout.readline().strip() == "ready"
    time.sleep(0.5)
    start = time.monotonic()
    child.send_signal(signal.SIGINT)
    out, err = child.communicate(timeout=60)
    assert "KeyboardInterrupt" in err and "finished" not in out, (out, err)
    assert time.monotonic() - start < 2.0  # stopped at its next tile, not at the end
    assert list(tmp_path.iterdir()) == []


def test_mesh_arrays_are_read_only_views(data):
    mesh = isotope.extract(load(data, "neghip_66x66x66_uint8.raw"), iso=32.5)
    with pytest.raises(ValueError, match="read-only"):
        mesh.faces[0, 0] = 2**31  # would send normals(), topology() and save() outside the mesh
    with pytest.raises(ValueError, match="read-only"):
        mesh.vertices[0, 0] = 1
    first = int(mesh.faces[0, 0])
    edited = mesh.faces.copy()  # what to edit instead
    edited[0, 0] = first + 1
    assert mesh.faces[0, 0] == first


def test_a_misaligned_float32_array_is_copied_not_borrowed(data):
    base = load(data, "embryo_256x256x256_uint8.raw").astype(np.float32)
    raw = np.empty(base.nbytes + 1, dtype=np.uint8)
    raw[1:] = base.view(np.uint8).ravel()
    misaligned = np.frombuffer(raw.data, dtype=np.float32, offset=1).reshape(base.shape)
    assert not misaligned.flags.aligned
    before = resident_bytes()
    source = isotope.Source(misaligned)
    assert resident_bytes() - before > 48 << 20  # an aligned float32 copy (64 MiB), not the bytes as they lie
    np.testing.assert_array_equal(source.extract(iso=64.5, eps=16).faces, isotope.extract(base, iso=64.5, eps=16).faces)


def test_an_exception_at_the_last_progress_report_is_raised(data, tmp_path):
    def fail_at_the_end(fraction):
        if fraction == 1.0:
            raise KeyError("the last report")

    volume = load(data, "bolt_70x123x66_uint8.raw")
    with pytest.raises(KeyError, match="the last report"):  # the build's last report: the extraction stops
        isotope.extract(volume, iso=64.5, eps=8, progress=fail_at_the_end)
    with pytest.raises(KeyError, match="the last report"):  # convert's comes when nothing is left to stop
        isotope.convert(volume, tmp_path / "bolt.isotope", progress=fail_at_the_end)


def test_a_forked_child_extracts_too(data):
    volume = load(data, "neghip_66x66x66_uint8.raw")
    want = len(isotope.extract(volume, iso=32.5).faces)  # this thread's worker exists before the fork
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child inherits the worker's pointer, not its thread
        try:
            os.write(write, str(len(isotope.extract(volume, iso=32.5).faces)).encode())
        finally:
            os._exit(0)
    os.close(write)
    got = b""
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        if os.waitpid(pid, os.WNOHANG)[0] == pid:
            break
        time.sleep(0.05)
    else:
        os.kill(pid, 9)
        pytest.fail("the forked child hung")
    got = os.read(read, 64)
    assert int(got) == want


def test_spacing_and_origin_are_checked_as_a_files_are(data, isotope_command, tmp_path):
    # NaN or infinite positions, a mesh flattened or mirrored, and a .glb with "min":[nan,...]
    # before: now refused by the library's one check of a volume, for arrays as for files.
    volume = load(data, "neghip_66x66x66_uint8.raw")
    for kw, words in ((dict(spacing=(float("nan"), 1, 1)), "spacing (nan, 1, 1) must be 3 finite numbers > 0"),
                      (dict(spacing=(0, 1, 1)), "spacing (0, 1, 1) must be 3 finite numbers > 0"),
                      (dict(spacing=(-1, 1, 1)), "spacing (-1, 1, 1) must be 3 finite numbers > 0"),
                      (dict(origin=(float("inf"), 0, 0)), "origin (inf, 0, 0) must be 3 finite numbers"),
                      (dict(spacing=(1e300, 1, 1)), "beyond the mesh's float32 coordinates")):
        for call in (lambda: isotope.extract(volume, iso=30, **kw),
                     lambda: isotope.convert(volume, tmp_path / "v.isotope", **kw)):
            with pytest.raises(ValueError) as e:
                call()
            assert words in str(e.value), (kw, str(e.value))
    assert list(tmp_path.iterdir()) == []
    # A file's header that puts its far corner beyond float32: the command's words are the same.
    nhdr = tmp_path / "far.nhdr"
    volume.tofile(tmp_path / "far.raw")
    nhdr.write_text("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 66 66 66\nspacings: 1e300 1 1\nencoding: raw\n"
                    "data file: far.raw\n")
    r = command(isotope_command, "extract", str(nhdr), "--iso", "30", "-o", str(tmp_path / "m.glb"))
    assert r.returncode == 1 and "beyond the mesh's float32 coordinates" in r.stderr, r.stderr


def test_options_that_mean_nothing_are_refused_with_the_commands_words(data, isotope_command, tmp_path):
    volume = load(data, "bolt_70x123x66_uint8.raw")
    raw = str(data / "bolt_70x123x66_uint8.raw")
    cases = [(dict(max_triangles=0), ["--max-triangles", "0"], "max-triangles"),
             (dict(max_triangles=1000, eps=2), ["--max-triangles", "1000", "--eps", "2"], "max-triangles"),
             (dict(eps=2, eps_ties=10 ** 5), ["--eps", "2", "--eps-ties", "100000"], "eps-ties"),
             (dict(eps=2, eps_ties=-1), ["--eps", "2", "--eps-ties", "-1"], "eps-ties"),
             (dict(max_triangles=1000, eps_ties=3), ["--max-triangles", "1000", "--eps-ties", "3"], "eps-ties"),
             (dict(threads=-1), ["--threads", "-1"], "threads"),
             (dict(threads=10 ** 6), ["--threads", "1000000"], "threads"),
             (dict(threads=1.5), ["--threads", "1.5"], "threads")]
    for kw, flags, option in cases:
        with pytest.raises(isotope.OptionError) as e:
            isotope.extract(volume, iso=64.5, **kw)
        assert e.value.option == option, kw
        cli = command(isotope_command, "extract", raw, "--iso", "64.5", *flags, "-o", str(tmp_path / "m.ply"))
        assert cli.returncode == 2, (flags, cli.stderr)
        assert f"--{option}: {str(e.value)[len(option) + 1:]}" in cli.stderr, (str(e.value), cli.stderr)
    # Beyond 64 bits: refused by the library in its words, not by pybind11's "incompatible arguments".
    for call, option in ((lambda: isotope.extract(volume, iso=64.5, threads=2 ** 70), "threads"),
                         (lambda: isotope.extract(volume, iso=64.5, cache_mb=2 ** 70), "cache-mb"),
                         (lambda: isotope.extract(raw, iso=64.5, dims=(2 ** 63, 2, 2), type="uint8"), "dims"),
                         (lambda: isotope.convert(volume, tmp_path / "c.isotope", zstd_level=2 ** 70), "zstd-level"),
                         (lambda: isotope.convert(volume, tmp_path / "c.isotope", threads=-3), "threads")):
        with pytest.raises(isotope.OptionError) as e:
            call()
        assert e.value.option == option
    assert not (tmp_path / "c.isotope").exists()


def test_a_store_used_from_its_own_progress_callback_is_refused_not_a_hang(data):
    import sys
    # In a child with a timeout: before, the callback waited for the build it was called from.
    script = ("import sys, numpy as np, isotope\n"
              "a = np.fromfile(sys.argv[1], np.uint8).reshape(66, 66, 66)\n"
              "for use in ('info', 'extract'):\n"
              "    calls = []\n"
              "    def report(fraction):\n"
              "        if not calls:\n"
              "            calls.append(1)\n"
              "            store.info if use == 'info' else store.extract(32.5, eps=8)\n"
              "    store = isotope.Source(a, progress=report)\n"
              "    try:\n"
              "        store.extract(32.5, eps=4)\n"
              "    except RuntimeError as e:\n"
              "        print(use, 'refused:', e, flush=True)\n"
              "    print(use, 'then', len(store.extract(32.5, eps=4).faces) > 0, flush=True)\n")
    r = subprocess.run([sys.executable, "-c", script, str(data / "neghip_66x66x66_uint8.raw")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    for use in ("info", "extract"):
        assert f"{use} refused: a progress callback may not use the Source that reports to it" in r.stdout, r.stdout
        assert f"{use} then True" in r.stdout  # and the Source works once the call is over


def test_messages_name_what_is_wrong(data, tmp_path):
    import sys
    a = np.zeros((4, 5, 6), dtype=np.float32)
    a[1, 2, 3] = np.nan  # a[z, y, x]
    with pytest.raises(ValueError, match=re.escape("volume value nan at (x,y,z) = (3,2,1) is not finite")):
        isotope.extract(a, iso=0)
    with pytest.raises(ValueError, match=re.escape("volume dimensions 1x1x1 (x by y by z): every axis needs 2")):
        isotope.extract(np.zeros((1, 1, 1), dtype=np.float32), iso=0)
    # Nested lists of Python numbers, as the docstring says: read as their values.
    nested = [[[0, 1], [2, 3]], [[4, 5], [6, 7]]]
    assert len(isotope.extract(nested, iso=3.5).faces) == len(isotope.extract(np.array(nested, np.float32), 3.5).faces) > 0
    # A copy that fails (no memory for the float32 copy under a limit): Python's MemoryError, not
    # "pybind11::error_already_set called while Python error indicator not set".
    script = ("import resource, numpy as np, isotope\n"
              "a = np.ones((256, 256, 512), np.uint8)\n"
              "soft, hard = resource.getrlimit(resource.RLIMIT_AS)\n"
              "used = int(open('/proc/self/statm').read().split()[0]) * resource.getpagesize()\n"
              "resource.setrlimit(resource.RLIMIT_AS, (used + (96 << 20), hard))\n"
              "try:\n"
              "    isotope.extract(a, iso=0.5)\n"
              "except MemoryError:\n"
              "    print('MemoryError')\n")
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert "MemoryError" in r.stdout and "error_already_set" not in r.stderr, (r.stdout, r.stderr)


def test_source_keeps_its_former_name_store():
    # Source is the C++ API's name; code written when the module called it Store still runs.
    assert isotope.Store is isotope.Source
    assert {"Source", "Store"} <= set(isotope.__all__)
