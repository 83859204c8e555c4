"""nurbskit.io on the real files of ../shared/data: exact counts, attributes, and agreement
with trimesh (an independent loader) and numpy where they read the same file."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
import trimesh

from nurbskit.io import read_mesh, read_nurbs, read_points, write_mesh, write_points

from _assert import assert_close
from _extras import require_extra


def canonical_triangles(corners: np.ndarray) -> np.ndarray:
    """Triangles ``(F, 3, 3)`` as a sorted ``(F, 9)`` table, each rotated to start at its
    smallest corner: two meshes with the same oriented triangles give the same table."""
    key = corners[:, :, 0] * 1e6 + corners[:, :, 1] * 1e3 + corners[:, :, 2]
    start = np.argmin(key, axis=1)
    idx = (start[:, None] + np.arange(3)[None, :]) % 3
    rolled = np.take_along_axis(corners, idx[:, :, None], axis=1).reshape(-1, 9)
    return rolled[np.lexsort(rolled.T[::-1])]


THESIS_MESHES = [
    # file, vertices, faces, has normals (NOFF)
    ("cat.off", 366, 698, True),
    ("hound.off", 12515, 25030, True),
    ("luigi.off", 2502, 5000, True),  # counts on the keyword line
    ("sphere.off", 642, 1280, True),
    ("plane.off", 25, 32, False),
    ("plane_n.off", 25, 32, False),
]
THESIS_SAMPLES = [
    ("cat_2500.off", 2509), ("horse_2500.off", 2512), ("hound_2500.off", 10042), ("luigi_2500.off", 2504),
    ("sphere_2500.off", 2512), ("plane_100.off", 100), ("plane_400.off", 402), ("plane_900.off", 903),
    ("plane_2500.off", 2510),
]


@pytest.mark.parametrize("name, nv, nf, normals", THESIS_MESHES)
def test_thesis_meshes_counts_and_normals(shared_data, name, nv, nf, normals):
    path = shared_data / "thesis_nurbsdiff/meshes" / name
    mesh = read_mesh(path)
    assert mesh.vertices.shape == (nv, 3) and mesh.faces.shape == (nf, 3)
    assert mesh.vertices.dtype == np.float64 and mesh.faces.dtype == np.int64
    assert (mesh.normals is not None) == normals
    # oracle: the text itself, read line by line without nurbskit
    lines = [ln for ln in path.read_text().splitlines() if ln.strip()]
    first_vertex = 1 if len(lines[0].split()) > 1 else 2
    expected = np.array(lines[first_vertex].split(), dtype=float)
    np.testing.assert_array_equal(mesh.vertices[0], expected[:3])
    if normals:
        np.testing.assert_array_equal(mesh.normals[0], expected[3:6])
    last_face = np.array(lines[-1].split(), dtype=int)
    assert last_face[0] == 3
    np.testing.assert_array_equal(mesh.faces[-1], last_face[1:4])


@pytest.mark.parametrize("name, n", THESIS_SAMPLES)
def test_thesis_point_samples(shared_data, name, n):
    cloud = read_points(shared_data / "thesis_nurbsdiff/meshes" / name)
    assert cloud.num_points == n and cloud.normals.shape == (n, 3)
    assert cloud.labels is None and cloud.dropped == 0


def test_thesis_point_samples_are_not_meshes(shared_data):
    from nurbskit.errors import InputError

    with pytest.raises(InputError, match="no faces"):
        read_mesh(shared_data / "thesis_nurbsdiff/meshes/cat_2500.off")


@pytest.mark.parametrize("name", ["bunny.off", "stanford-bunny.obj", "spot.obj", "cow.obj", "teapot.obj",
                                  "fandisk.obj", "horse_quad.obj", "suzanne.obj", "camelhead.off",
                                  "cheburashka.off", "beetle.obj", "sphere.obj", "cylinder.obj"])
def test_classic_meshes_same_triangles_as_trimesh(shared_data, name):
    path = shared_data / "classic_meshes" / name
    mesh = read_mesh(path)
    ref = trimesh.load(path, process=False, force="mesh")
    # trimesh splits OBJ vertices that carry several texture coordinates; compare the
    # triangles' corner coordinates, which do not depend on how vertices are shared
    assert mesh.faces.shape == ref.faces.shape
    # (quads are split along a different diagonal order by trimesh: compare as sets)
    np.testing.assert_allclose(canonical_triangles(mesh.vertices[mesh.faces]),
                               canonical_triangles(np.asarray(ref.vertices)[ref.faces]), rtol=0, atol=1e-12)


def test_bunny_counts(shared_data):
    assert read_points(shared_data / "classic_meshes/stanford-bunny.obj").num_points == 35947
    assert read_points(shared_data / "classic_meshes/bunny.off").num_points == 3485


def test_horse_zip_holds_a_binary_ply(shared_data):
    path = shared_data / "classic_meshes/horse.zip"
    mesh = read_mesh(path)
    with zipfile.ZipFile(path) as archive:
        ref = trimesh.load(trimesh.util.wrap_as_stream(archive.read("horse.ply")), file_type="ply", process=False)
    assert mesh.vertices.shape == (48485, 3) and mesh.faces.shape == (96966, 3)
    np.testing.assert_array_equal(mesh.vertices, np.asarray(ref.vertices, dtype=np.float64))
    np.testing.assert_array_equal(mesh.faces, ref.faces)
    # the file's normals (not unit length), as trimesh reads them
    np.testing.assert_allclose(mesh.normals, ref.vertex_normals, rtol=1e-7, atol=0)


def test_abc_stl_matches_trimesh(shared_data):
    path = shared_data / "abc/00000050_80d90bfdd2e74e709956122a_trimesh_000.stl"
    mesh = read_mesh(path)
    ref = trimesh.load(path)  # trimesh merges equal corners, as nurbskit does
    assert mesh.vertices.shape == ref.vertices.shape == (3795, 3)
    assert mesh.faces.shape == ref.faces.shape == (7614, 3)
    np.testing.assert_allclose(mesh.vertices[mesh.faces], ref.vertices[ref.faces], rtol=0, atol=0)


@pytest.mark.parametrize("name, n, labels", [("abc_00470.xyzc", 10000, 3), ("abc_00949.xyzc", 10000, 16),
                                             ("abc_00000000.xyzc", 17111, 25)])
def test_abc_labelled_clouds(shared_data, name, n, labels):
    path = shared_data / "abc" / name
    cloud = read_points(path)
    ref = np.loadtxt(path)
    assert cloud.num_points == n and np.unique(cloud.labels).size == labels
    np.testing.assert_array_equal(cloud.points, ref[:, :3])
    np.testing.assert_array_equal(cloud.labels, ref[:, 3].astype(np.int64))


@pytest.mark.parametrize("name, kept, dropped, labels", [
    ("test0.pcd", 189198, 118002, [1, 20, 30]),
    ("test16.pcd", 187775, 119425, [1, 20, 30, 40]),
    ("test31.pcd", 170909, 136291, [1, 20, 30, 40]),
])
def test_kinect_pcd_binary_compressed(shared_data, name, kept, dropped, labels):
    cloud = read_points(shared_data / "kinect_scans" / name)
    assert cloud.num_points == kept and cloud.dropped == dropped and kept + dropped == 640 * 480
    assert np.isfinite(cloud.points).all()
    assert sorted(np.unique(cloud.labels).tolist()) == labels
    assert cloud.colors.shape == (kept, 4) and cloud.colors.dtype == np.uint8
    # a Kinect sees between half a metre and a few metres
    assert 0.3 < cloud.points[:, 2].min() and cloud.points[:, 2].max() < 5
    # `nurbskit info` counts the labels of the points, not the label of the NaN holes
    from nurbskit.cli.io_commands import describe

    assert describe(shared_data / "kinect_scans" / name)["num_labels"] == len(labels)


def test_kinect_pcd_decoder_agrees_with_python_lzf(shared_data):
    lzf = require_extra("lzf", "pcd")
    from nurbskit.io.lzf import decompress

    data = (shared_data / "kinect_scans/test0.pcd").read_bytes()
    pos = data.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n")
    csize, usize = (int(v) for v in np.frombuffer(data, "<u4", 2, pos))
    stream = data[pos + 8: pos + 8 + csize]
    assert decompress(stream, usize, use_c=False) == lzf.decompress(stream, usize + 1)


def test_text_clouds(shared_data):
    c5 = read_points(shared_data / "thesis_nurbsdiff/pointclouds/c5dataReg.txt")
    np.testing.assert_array_equal(c5.points, np.loadtxt(shared_data / "thesis_nurbsdiff/pointclouds/c5dataReg.txt"))
    assert c5.num_points == 11330
    horse = read_points(shared_data / "thesis_nurbsdiff/pointclouds/horse.xyz.npy")
    np.testing.assert_array_equal(horse.points, np.load(shared_data / "thesis_nurbsdiff/pointclouds/horse.xyz.npy"))
    rows = shared_data / "thesis_nurbsdiff/pointclouds_rows/dfs_duck_900.txt"
    text = rows.read_text().splitlines()
    assert read_points(rows).num_points == sum(1 for ln in text if ln.strip() and not ln.startswith("#"))


def test_duck_ctrlpts_with_weights_and_knots(shared_data):
    require_extra("geomdl", "dev")
    from geomdl import NURBS, compatibility, exchange

    folder = shared_data / "thesis_nurbsdiff/ducky"
    knots = json.loads((folder / "duck_knots.json").read_text())["duck1_body"]
    duck = read_nurbs(folder / "duck1.ctrlpts", sizes=(14, 13), degrees=(3, 3),
                      knot_vectors=[knots["knotvector_u_raw"], knots["knotvector_v_raw"]])
    assert duck.sizes == (14, 13) and sorted(duck.weights.flatten().tolist()).count(0.5) == 2
    # oracle: the thesis's own geomdl code path (Listing 2.7)
    ctrlpts = exchange.import_txt(str(folder / "duck1.ctrlpts"), separator=" ")
    weights = [float(w) for w in (folder / "duck1.weights").read_text().replace("\n", "").split(",") if w.strip()]
    g = NURBS.Surface()
    g.degree_u = g.degree_v = 3
    g.ctrlpts_size_u, g.ctrlpts_size_v = 14, 13
    g.ctrlptsw = compatibility.combine_ctrlpts_weights(ctrlpts, weights)
    g.knotvector_u, g.knotvector_v = knots["knotvector_u_raw"], knots["knotvector_v_raw"]
    # geomdl rescales knot vectors to [0, 1] when they are set; nurbskit keeps them as given
    unit = [(u, v) for u in np.linspace(0, 1, 7) for v in np.linspace(0, 1, 7)]
    raw = [(-1.5708 + u * 2 * 1.5708, -3.14159 + v * 2 * 3.14159) for u, v in unit]
    import torch

    ours = duck.evaluate(torch.tensor(raw, dtype=torch.float64)).numpy()
    assert_close(ours, np.array(g.evaluate_list(unit)), atol=1e-9)


def test_cylinder_ctrlpts_and_roof_smesh(shared_data):
    require_extra("geomdl", "dev")
    from geomdl import exchange

    import nurbskit

    cyl = read_nurbs(shared_data / "thesis_nurbsdiff/nurbs_surfaces/u_cylinder_7x9.ctrlpts", sizes=(7, 9), degrees=(3, 3))
    assert cyl.sizes == (7, 9) and not cyl.is_rational
    roof_path = shared_data / "thesis_nurbsdiff/nurbs_surfaces/roof_smesh.1.dat"
    roof = read_nurbs(roof_path)
    ref = nurbskit.from_geomdl(exchange.import_smesh(str(roof_path))[0])
    assert roof.sizes == ref.sizes == (7, 7) and roof.is_rational
    assert_close(roof.control_points.numpy(), ref.control_points.numpy(), atol=1e-12)
    np.testing.assert_array_equal(roof.weights.numpy(), ref.weights.numpy())
    for a, b in zip(roof.knot_vectors, ref.knot_vectors):  # geomdl rescales knots to [0, 1]
        assert_close((a.numpy() - a[0].item()) / (a[-1] - a[0]).item(), b.numpy(), atol=1e-15)
    assert roof.domain[0] == (0.0, 34.9065850398866)


def test_amsurface_geomdl_style_json(shared_data):
    path = shared_data / "thesis_nurbsdiff/nurbs_surfaces/AMSurface.json"
    surface = read_nurbs(path)
    data = json.loads(path.read_text())["shape"]["data"]
    assert surface.sizes == (168, 8) and surface.degrees == (5, 4)
    assert [len(k) for k in surface.knot_vectors] == [174, 13]
    np.testing.assert_array_equal(surface.control_points.numpy(), np.array(data["control_points"]["points"]))


@pytest.fixture(scope="module")
def kinect16(shared_data):
    """Read once for the round trips (decoding LZF in pure Python takes about a second)."""
    return read_points(shared_data / "kinect_scans/test16.pcd")


@pytest.mark.parametrize("ext", [".ply", ".pcd", ".xyz", ".txt", ".csv", ".npy", ".npz", ".off", ".obj"])
def test_real_clouds_round_trip_every_point_format(kinect16, tmp_path, ext):
    cloud = kinect16
    out = tmp_path / f"cloud{ext}"
    write_points(out, cloud.points, labels=cloud.labels if ext in (".ply", ".pcd", ".xyz", ".txt", ".csv", ".npz") else None)
    back = read_points(out)
    # the PCD coordinates are float32 in the file: every format keeps them to float32 precision
    np.testing.assert_allclose(back.points, cloud.points, rtol=1e-7, atol=0)
    if back.labels is not None:
        np.testing.assert_array_equal(back.labels, cloud.labels)


@pytest.mark.parametrize("ext", [".ply", ".off", ".obj", ".stl", ".npz"])
def test_real_mesh_round_trip_every_mesh_format(shared_data, tmp_path, ext):
    mesh = read_mesh(shared_data / "thesis_nurbsdiff/meshes/hound.off")
    out = tmp_path / f"hound{ext}"
    write_mesh(out, mesh.vertices, mesh.faces, mesh.normals)
    back = read_mesh(out)
    assert back.faces.shape == mesh.faces.shape
    tol = dict(rtol=1e-7, atol=1e-7 * np.abs(mesh.vertices).max()) if ext == ".stl" else dict(rtol=0, atol=0)
    np.testing.assert_allclose(back.vertices[back.faces], mesh.vertices[mesh.faces], **tol)
    if ext != ".stl":
        np.testing.assert_array_equal(back.normals, mesh.normals)


@pytest.mark.parametrize("ext", [".json", "geomdl", ".ctrlpts", ".cptw", ".smesh", ".3dm"])
def test_real_nurbs_round_trip_every_nurbs_format(shared_data, tmp_path, ext):
    from nurbskit.io import write_nurbs

    if ext == ".3dm":
        require_extra("rhino3dm", "cad")
    folder = shared_data / "thesis_nurbsdiff"
    knots = json.loads((folder / "ducky/duck_knots.json").read_text())["duck1_body"]
    objects = [
        read_nurbs(folder / "ducky/duck1.ctrlpts", sizes=(14, 13), degrees=(3, 3),
                   knot_vectors=[knots["knotvector_u_raw"], knots["knotvector_v_raw"]]),
        read_nurbs(folder / "nurbs_surfaces/roof_smesh.1.dat"),
        read_nurbs(folder / "nurbs_surfaces/AMSurface.json"),
    ]
    for i, obj in enumerate(objects):
        path = tmp_path / (f"o{i}.json" if ext == "geomdl" else f"o{i}{ext}")
        write_nurbs(path, obj, format="geomdl" if ext == "geomdl" else None)
        back = read_nurbs(path)
        assert back.sizes == obj.sizes and back.degrees == obj.degrees
        np.testing.assert_allclose(back.control_points.numpy(), obj.control_points.numpy(), rtol=1e-15, atol=1e-13)
        np.testing.assert_allclose(back.weights.numpy(), obj.weights.numpy(), rtol=1e-15)
        for a, b in zip(back.knot_vectors, obj.knot_vectors):
            np.testing.assert_array_equal(a.numpy(), b.numpy())
