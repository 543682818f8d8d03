"""Tests for engine.scene.meshio and engine.scene.shapes."""
import os
import re
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from engine.errors import SceneError
from engine.scene.meshio import (MeshData, compute_vertex_normals, face_normals,
                                 read_mesh, read_obj, read_ply, triangle_areas)
from engine.scene.shapes import icosphere, quad, transform_matrix, transform_mesh
from tests.conftest import REPO

SHARED_PLY = "/work/shared/peers/meshes/sphere_ico6.ply"


# ---------------------------------------------------------------------------
# helpers


def outward(mesh, centre=(0.0, 0.0, 0.0)):
    """Geometric normal . (centroid - centre) for every face."""
    fn = face_normals(mesh.vertices, mesh.faces)
    c = mesh.vertices[mesh.faces].mean(axis=1) - np.asarray(centre)
    return np.einsum("ij,ij->i", fn, c)


def write_ply(path, fmt, vprops, vrows, face_spec, faces, extra_face_props=(),
              extra_elements_before_face=()):
    """Write a PLY file.

    vprops: list of (type, name); vrows: list of tuples (one per vertex).
    face_spec: (count type, index type, name); faces: list of index lists.
    extra_face_props: list of (type, name, values) scalar props after the list.
    extra_elements_before_face: list of (name, [(type, pname)], rows).
    """
    codes = {"char": "b", "uchar": "B", "short": "h", "ushort": "H", "int": "i",
             "uint": "I", "float": "f", "double": "d", "int32": "i", "uint8": "B",
             "float32": "f", "float64": "d", "int64": "q", "uint64": "Q"}
    head = ["ply", f"format {fmt} 1.0", "comment test fixture",
            f"element vertex {len(vrows)}"]
    head += [f"property {t} {n}" for t, n in vprops]
    for name, props, rows in extra_elements_before_face:
        head.append(f"element {name} {len(rows)}")
        head += [f"property {t} {n}" for t, n in props]
    ct, it, fname = face_spec
    head += [f"element face {len(faces)}", f"property list {ct} {it} {fname}"]
    head += [f"property {t} {n}" for t, n, _ in extra_face_props]
    head.append("end_header")
    out = ("\n".join(head) + "\n").encode("ascii")
    if fmt == "ascii":
        lines = [" ".join(repr(x.item() if hasattr(x, "item") else x) for x in r) for r in vrows]
        for _name, _props, rows in extra_elements_before_face:
            lines += [" ".join(str(x) for x in r) for r in rows]
        for k, f in enumerate(faces):
            lines.append(" ".join([str(len(f))] + [str(i) for i in f]
                                  + [str(vals[k]) for _, _, vals in extra_face_props]))
        out += ("\n".join(lines) + "\n").encode("ascii")
    else:
        import struct
        bo = "<" if fmt == "binary_little_endian" else ">"
        vfmt = bo + "".join(codes[t] for t, _ in vprops)
        for r in vrows:
            out += struct.pack(vfmt, *r)
        for _name, props, rows in extra_elements_before_face:
            efmt = bo + "".join(codes[t] for t, _ in props)
            for r in rows:
                out += struct.pack(efmt, *r)
        for k, f in enumerate(faces):
            out += struct.pack(bo + codes[ct] + codes[it] * len(f), len(f), *f)
            for t, _, vals in extra_face_props:
                out += struct.pack(bo + codes[t], vals[k])
    with open(path, "wb") as fh:
        fh.write(out)
    return path


CUBE_V = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0),
          (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
# outward (counter-clockwise seen from outside) quads
CUBE_Q = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5),
          (0, 4, 7, 3)]


# ---------------------------------------------------------------------------
# icosphere


@pytest.mark.parametrize("level", [0, 1, 2, 3, 4])
def test_icosphere_counts_unit_and_outward(level):
    m = icosphere(level)
    assert m.vertices.shape == (10 * 4 ** level + 2, 3)
    assert m.faces.shape == (20 * 4 ** level, 3)
    assert m.vertices.dtype == np.float64 and m.faces.dtype == np.int32
    np.testing.assert_allclose(np.linalg.norm(m.vertices, axis=1), 1.0, atol=1e-14)
    assert (outward(m) > 0).all()
    np.testing.assert_array_equal(m.vertex_normals, m.vertices)
    # closed 2-manifold: every undirected edge is used by exactly 2 faces, and
    # every directed edge once (consistent orientation)
    e = m.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).astype(np.int64)
    directed = e[:, 0] * len(m.vertices) + e[:, 1]
    assert np.unique(directed).size == directed.size
    und = np.sort(e, axis=1)
    _, cnt = np.unique(und[:, 0] * len(m.vertices) + und[:, 1], return_counts=True)
    assert (cnt == 2).all()
    assert len(np.unique(m.faces)) == len(m.vertices)   # no unused vertices
    # pole aligned
    np.testing.assert_array_equal(m.vertices[0], [0, 0, 1])
    np.testing.assert_array_equal(m.vertices[11], [0, 0, -1])


def test_icosphere_no_duplicate_vertices():
    v = icosphere(3).vertices
    q = np.round(v, 9)
    assert np.unique(q, axis=0).shape[0] == v.shape[0]


@pytest.mark.parametrize("bad", [-1, 10, 2.5, True, "3", None])
def test_icosphere_rejects_bad_level(bad):
    with pytest.raises(SceneError, match="subdivisions"):
        icosphere(bad, field="objects[0].subdivisions")


def test_icosphere_accepts_numpy_int():
    assert icosphere(np.int64(1)).faces.shape == (80, 3)


@pytest.mark.skipif(not os.path.exists(SHARED_PLY), reason="shared mesh missing")
def test_icosphere6_matches_shared_ply():
    m = icosphere(6)
    p = read_ply(SHARED_PLY)
    assert m.vertices.shape == p.vertices.shape == (40962, 3)
    assert m.faces.shape == p.faces.shape == (81920, 3)
    # same construction order -> identical faces, positions equal to float32
    np.testing.assert_array_equal(m.faces, p.faces)
    np.testing.assert_allclose(m.vertices, p.vertices, atol=1e-7)


# ---------------------------------------------------------------------------
# shared PLY


@pytest.mark.skipif(not os.path.exists(SHARED_PLY), reason="shared mesh missing")
def test_read_shared_ply_correct():
    m = read_mesh(SHARED_PLY)
    assert m.vertices.shape == (40962, 3) and m.faces.shape == (81920, 3)
    assert m.vertices.dtype == np.float64 and m.faces.dtype == np.int32
    np.testing.assert_allclose(m.vertex_normals, m.vertices, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(m.vertices, axis=1), 1.0, atol=1e-6)
    assert (outward(m) > 0).all()
    assert m.face_groups is None and m.group_names == []


# ---------------------------------------------------------------------------
# PLY fixtures


def _cube_faces_tri_and_quad():
    # mix: first face as two triangles, the rest as quads
    q0 = CUBE_Q[0]
    return [(q0[0], q0[1], q0[2]), (q0[0], q0[2], q0[3])] + [list(q) for q in CUBE_Q[1:]]


def _check_cube(m, ntri=12):
    assert m.vertices.shape == (8, 3)
    assert m.faces.shape == (ntri, 3)
    np.testing.assert_allclose(m.vertices, CUBE_V)
    assert (outward(m, (0.5, 0.5, 0.5)) > 0).all()
    np.testing.assert_allclose(triangle_areas(m.vertices, m.faces).sum(), 6.0)


def test_ply_ascii_mixed_polygons_and_extra_props(tmp_path):
    # normals given in an unusual order with extra properties interleaved
    vprops = [("float", "nz"), ("uchar", "red"), ("double", "x"), ("float", "y"),
              ("float", "nx"), ("int", "z"), ("float", "ny")]
    rows = []
    for x, y, z in CUBE_V:
        n = np.array([x - 0.5, y - 0.5, z - 0.5]) * 2  # length sqrt(3)
        rows.append((n[2], 200, float(x), float(y), n[0], z, n[1]))
    edge = ("edge", [("int", "vertex1"), ("int", "vertex2")], [(0, 1), (1, 2)])
    p = write_ply(tmp_path / "cube.ply", "ascii", vprops, rows,
                  ("uchar", "int", "vertex_indices"), _cube_faces_tri_and_quad(),
                  extra_face_props=[("uchar", "flags", [7] * 7)],
                  extra_elements_before_face=[edge])
    m = read_ply(p)
    _check_cube(m)
    expect = (np.array(CUBE_V) - 0.5) / (0.5 * np.sqrt(3))
    np.testing.assert_allclose(m.vertex_normals, expect, atol=1e-7)


def test_ply_ascii_all_triangles_crlf(tmp_path):
    m0 = icosphere(1)
    p = write_ply(tmp_path / "ico.ply", "ascii", [("double", c) for c in "xyz"],
                  [tuple(r) for r in m0.vertices.tolist()],
                  ("uchar", "int", "vertex_index"), m0.faces.tolist())
    data = open(p, "rb").read().replace(b"\n", b"\r\n")
    open(p, "wb").write(data)
    m = read_mesh(p)
    np.testing.assert_array_equal(m.faces, m0.faces)
    np.testing.assert_allclose(m.vertices, m0.vertices, rtol=0, atol=1e-15)
    assert m.vertex_normals is None


def test_ply_big_endian_variable_polygons(tmp_path):
    # big endian, double coords, ushort count, uint indices, trailing scalar
    # face property, mixed triangle/quad faces -> slow (variable) path
    rows = [tuple(float(c) for c in v) for v in CUBE_V]
    p = write_ply(tmp_path / "cube_be.ply", "binary_big_endian",
                  [("double", "x"), ("double", "y"), ("double", "z")], rows,
                  ("ushort", "uint", "vertex_indices"), _cube_faces_tri_and_quad(),
                  extra_face_props=[("short", "flags", list(range(7)))])
    m = read_ply(p)
    _check_cube(m)
    assert m.vertex_normals is None


def test_ply_big_endian_uniform_quads_fast_path(tmp_path):
    rows = [tuple(float(c) for c in v) for v in CUBE_V]
    p = write_ply(tmp_path / "cube_q.ply", "binary_big_endian",
                  [("float", "x"), ("float", "y"), ("float", "z")], rows,
                  ("uchar", "int", "vertex_indices"), [list(q) for q in CUBE_Q])
    m = read_ply(p)
    _check_cube(m)
    # fan triangulation (q0,q1,q2),(q0,q2,q3)
    np.testing.assert_array_equal(m.faces[:2], [[0, 3, 2], [0, 2, 1]])


def test_ply_binary_little_endian_round_trip(tmp_path):
    m0 = transform_mesh(icosphere(2), transform_matrix(scale=(1, 2, 3)))
    vp = [("float", "x"), ("float", "y"), ("float", "z"),
          ("float", "nx"), ("float", "ny"), ("float", "nz"), ("uchar", "alpha")]
    rows = [tuple(list(v) + list(n) + [255])
            for v, n in zip(m0.vertices.tolist(), m0.vertex_normals.tolist())]
    p = write_ply(tmp_path / "ell.ply", "binary_little_endian", vp, rows,
                  ("uchar", "uint", "vertex_indices"), m0.faces.tolist())
    m = read_ply(p)
    np.testing.assert_array_equal(m.faces, m0.faces)
    np.testing.assert_allclose(m.vertices, m0.vertices, atol=1e-6)
    np.testing.assert_allclose(m.vertex_normals, m0.vertex_normals, atol=1e-6)


def test_ply_zero_length_normals_are_computed(tmp_path):
    vp = [("float", c) for c in ("x", "y", "z", "nx", "ny", "nz")]
    rows = [(0, 0, 0, 0, 0, 0), (1, 0, 0, 0, 0, 0), (0, 1, 0, 0, 0, 0)]
    p = write_ply(tmp_path / "t.ply", "ascii", vp, rows,
                  ("uchar", "int", "vertex_indices"), [(0, 1, 2)])
    m = read_ply(p)
    np.testing.assert_allclose(m.vertex_normals, [[0, 0, 1]] * 3)


# ---------------------------------------------------------------------------
# PLY errors


def _tri_ply(tmp_path, name="t.ply", fmt="binary_little_endian", faces=((0, 1, 2),),
             rows=((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))):
    return write_ply(tmp_path / name, fmt, [("float", c) for c in "xyz"], list(rows),
                     ("uchar", "int", "vertex_indices"), [list(f) for f in faces])


def test_ply_truncated_binary(tmp_path):
    m0 = icosphere(1)
    p = write_ply(tmp_path / "trunc.ply", "binary_little_endian",
                  [("float", c) for c in "xyz"], [tuple(r) for r in m0.vertices.tolist()],
                  ("uchar", "int", "vertex_indices"), m0.faces.tolist())
    data = open(p, "rb").read()
    for cut in (5, 13 * 10, 13 * 80 + 12 * 42 - 100):   # inside faces / vertices
        open(p, "wb").write(data[:len(data) - cut])
        with pytest.raises(SceneError) as ei:
            read_mesh(p, field="objects[1].file")
        msg = str(ei.value)
        assert "trunc.ply" in msg and "truncated" in msg
        assert msg.startswith("objects[1].file: ")
        assert ei.value.field == "objects[1].file"


def test_ply_truncated_variable_rows(tmp_path):
    rows = [tuple(float(c) for c in v) for v in CUBE_V]
    p = write_ply(tmp_path / "tv.ply", "binary_little_endian",
                  [("float", c) for c in "xyz"], rows,
                  ("uchar", "int", "vertex_indices"), _cube_faces_tri_and_quad())
    data = open(p, "rb").read()
    open(p, "wb").write(data[:-3])
    with pytest.raises(SceneError, match=r"tv\.ply.*truncated"):
        read_ply(p)


def test_ply_truncated_ascii(tmp_path):
    p = _tri_ply(tmp_path, fmt="ascii", faces=[(0, 1, 2), (0, 2, 1)])
    text = open(p).read().rstrip("\n").rsplit("\n", 1)[0] + "\n"
    open(p, "w").write(text)
    with pytest.raises(SceneError, match=r"t\.ply.*ends early"):
        read_ply(p)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_index_out_of_range(tmp_path, fmt):
    p = _tri_ply(tmp_path, "oor.ply", fmt, faces=[(0, 1, 2), (0, 2, 3)])
    with pytest.raises(SceneError) as ei:
        read_ply(p)
    msg = str(ei.value)
    assert "oor.ply" in msg and "face 1" in msg and "3" in msg and "out of range" in msg


def test_ply_negative_index(tmp_path):
    p = _tri_ply(tmp_path, "neg.ply", faces=[(0, 1, -1)])
    with pytest.raises(SceneError, match=r"neg\.ply.*-1.*out of range"):
        read_ply(p)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_non_finite_vertex(tmp_path, fmt):
    p = _tri_ply(tmp_path, "nan.ply", fmt,
                 rows=((0.0, 0.0, 0.0), (float("nan"), 0.0, 0.0), (0.0, 1.0, 0.0)))
    with pytest.raises(SceneError, match=r"nan\.ply.*vertex 1 is not finite"):
        read_ply(p)


def test_ply_zero_faces(tmp_path):
    p = _tri_ply(tmp_path, "empty.ply", faces=[])
    with pytest.raises(SceneError, match=r"empty\.ply.*zero faces"):
        read_ply(p)


def test_ply_degenerate_polygon(tmp_path):
    p = _tri_ply(tmp_path, "two.ply", fmt="ascii", faces=[(0, 1, 2), (0, 1)])
    with pytest.raises(SceneError, match=r"two\.ply.*face 1 has 2 corner"):
        read_ply(p)


def test_ply_bad_headers(tmp_path):
    p = tmp_path / "bad.ply"
    p.write_bytes(b"solid cube\n")
    with pytest.raises(SceneError, match=r"bad\.ply.*not a PLY"):
        read_ply(p)
    p.write_bytes(b"ply\nformat binary_middle_endian 1.0\nelement vertex 0\nend_header\n")
    with pytest.raises(SceneError, match=r"bad\.ply.*unsupported PLY format"):
        read_ply(p)
    p.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n")
    with pytest.raises(SceneError, match=r"bad\.ply.*end_header"):
        read_ply(p)
    p.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                  b"property float y\nelement face 1\n"
                  b"property list uchar int vertex_indices\nend_header\n0 0\n3 0 0 0\n")
    with pytest.raises(SceneError, match=r"bad\.ply.*no 'z' property"):
        read_ply(p)
    p.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\n"
                  b"end_header\n")
    with pytest.raises(SceneError, match=r"bad\.ply.*unsupported property"):
        read_ply(p)
    p.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                  b"property float y\nproperty float z\nelement face 1\n"
                  b"property list uchar int vertex_indices\nend_header\n"
                  b"0 0 0\n1 0 0\n0 one 0\n3 0 1 2\n")
    with pytest.raises(SceneError, match=r"bad\.ply.*non-numeric value 'one'"):
        read_ply(p)


def test_missing_file_and_unsupported_format(tmp_path):
    with pytest.raises(SceneError, match=r"nowhere\.ply.*not found"):
        read_mesh(tmp_path / "nowhere.ply")
    with pytest.raises(SceneError, match=r"nowhere\.obj.*not found"):
        read_mesh(str(tmp_path / "nowhere.obj"), field="objects[3].file")
    with pytest.raises(SceneError, match=r"model\.stl.*unsupported mesh format '\.stl'"):
        read_mesh(tmp_path / "model.stl")
    with pytest.raises(SceneError, match="directory"):
        read_ply(tmp_path)


def test_extension_is_case_insensitive(tmp_path):
    p = _tri_ply(tmp_path, "UPPER.PLY")
    assert read_mesh(p).faces.shape == (1, 3)


# ---------------------------------------------------------------------------
# OBJ


def test_obj_quads_negative_indices_and_groups(tmp_path):
    lines = ["# cube", "mtllib cube.mtl", "o Cube", "g side"]
    lines += [f"v {x} {y} {z}" for x, y, z in CUBE_V]
    lines += ["usemtl red"]
    # first two faces with positive 1-based indices
    lines += ["f " + " ".join(str(i + 1) for i in q) for q in CUBE_Q[:2]]
    lines += ["usemtl blue", "s off"]
    # two with negative (relative) indices, v/vt form
    lines += ["vt 0 0"]
    lines += ["f " + " ".join(f"{i - 8}/1" for i in q) for q in CUBE_Q[2:4]]
    lines += ["usemtl red"]
    lines += ["f " + " ".join(str(i + 1) for i in q) + "   # trailing comment"
              for q in CUBE_Q[4:]]
    p = tmp_path / "cube.obj"
    p.write_text("\n".join(lines) + "\n")
    m = read_mesh(p)
    _check_cube(m)
    assert m.vertex_normals is None
    assert m.group_names == ["red", "blue"]
    np.testing.assert_array_equal(m.face_groups, [0, 0, 0, 0, 1, 1, 1, 1, 0, 0, 0, 0])
    np.testing.assert_array_equal(m.faces[:2], [[0, 3, 2], [0, 2, 1]])


def test_obj_per_corner_normals_split_vertices(tmp_path):
    # flat-shaded cube: each face has its own normal -> 24 (v, vn) pairs
    normals = []
    lines = [f"v {x} {y} {z}" for x, y, z in CUBE_V]
    for q in CUBE_Q:
        p0, p1, p2 = (np.array(CUBE_V[i], float) for i in q[:3])
        n = np.cross(p1 - p0, p2 - p0)
        normals.append(n / np.linalg.norm(n))
        lines.append("vn " + " ".join(str(c) for c in normals[-1] * 3.0))  # unnormalised
    for k, q in enumerate(CUBE_Q):
        lines.append("f " + " ".join(f"{i + 1}//{k + 1}" for i in q))
    p = tmp_path / "flat.obj"
    p.write_text("\n".join(lines))
    m = read_obj(p)
    assert m.vertices.shape == (24, 3) and m.faces.shape == (12, 3)
    assert (outward(m, (0.5, 0.5, 0.5)) > 0).all()
    fn = face_normals(m.vertices, m.faces)
    fn /= np.linalg.norm(fn, axis=1, keepdims=True)
    # every corner's normal equals its face's geometric normal
    for c in range(3):
        np.testing.assert_allclose(m.vertex_normals[m.faces[:, c]], fn, atol=1e-12)
    assert m.face_groups is None


def test_obj_v_vt_vn_negative_and_shared_pairs(tmp_path):
    text = """
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vn 0 0 2
f -4/-1/-1 -3/-1/-1 -2/-1/-1 -1/-1/-1
"""
    p = tmp_path / "q.obj"
    p.write_text(text)
    m = read_obj(p)
    assert m.vertices.shape == (4, 3) and m.faces.shape == (2, 3)
    np.testing.assert_allclose(m.vertex_normals, [[0, 0, 1]] * 4)
    assert (face_normals(m.vertices, m.faces)[:, 2] > 0).all()


def test_obj_mixed_faces_without_normals_get_computed_normals(tmp_path):
    text = """
v 0 0 0
v 1 0 0
v 0 1 0
v 0 0 1
vn 0 0 -1
f 1//1 3//1 2//1
f 1 2 4
"""
    p = tmp_path / "mixed.obj"
    p.write_text(text)
    m = read_obj(p)
    # vertices 1, 2 appear with and without a normal -> 3 + 3 split vertices
    assert m.vertices.shape == (6, 3)
    fn = face_normals(m.vertices, m.faces)
    np.testing.assert_allclose(m.vertex_normals[m.faces[0]], [[0, 0, -1]] * 3)
    np.testing.assert_allclose(m.vertex_normals[m.faces[1]],
                               [fn[1] / np.linalg.norm(fn[1])] * 3)


def test_obj_group_before_usemtl_is_minus_one(tmp_path):
    p = tmp_path / "g.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nusemtl glass\nf 1 2 3\n")
    m = read_obj(p)
    np.testing.assert_array_equal(m.face_groups, [-1, 0])
    assert m.group_names == ["glass"]


@pytest.mark.parametrize("text, pattern", [
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", r"line 4: vertex index 4 is out of range"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", r"line 4: vertex index 0 is out of range"),
    ("v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n", r"line 3: vertex index -3"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//2\n",
     r"line 5: normal index 2 is out of range"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", r"line 4: bad vertex index 'x'"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", r"face 0 \(line 4\) has 2 corner"),
    ("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", r"line 2: 'v' needs 3 numbers"),
    ("v 0 0 0\nv 1 0 a\nv 0 1 0\nf 1 2 3\n", r"line 2: non-numeric 'v'"),
    ("v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n", r"vertex 1 \(line 2\) is not finite"),
    ("v 0 0 0\n", r"zero faces"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/2/3/4 2 3\n", r"malformed face corner"),
])
def test_obj_errors(tmp_path, text, pattern):
    p = tmp_path / "broken.obj"
    p.write_text(text)
    with pytest.raises(SceneError, match=r"broken\.obj.*" + pattern):
        read_obj(p, field="objects[0].file")


def test_obj_large_reads_exactly(tmp_path):
    """A 20k-triangle OBJ with normals reads back the icosphere (speed lives in tests/bench, not here)."""
    m0 = icosphere(6)
    v = m0.vertices
    lines = [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in v.tolist()]
    lines += [f"vn {x:.9f} {y:.9f} {z:.9f}" for x, y, z in v.tolist()]
    lines += [f"f {a}//{a} {b}//{b} {c}//{c}"
              for a, b, c in (m0.faces + 1).tolist()]
    p = tmp_path / "sphere.obj"
    p.write_text("\n".join(lines))
    m = read_obj(p)
    np.testing.assert_array_equal(m.faces, m0.faces)   # pairs (i, i) keep order
    np.testing.assert_allclose(m.vertex_normals, m0.vertex_normals, atol=1e-8)


# ---------------------------------------------------------------------------
# geometry helpers


def test_face_normals_and_areas():
    v = np.array([[0, 0, 0], [2, 0, 0], [0, 3, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 1]])
    np.testing.assert_allclose(face_normals(v, f), [[0, 0, 6], [0, 0, -6]])
    np.testing.assert_allclose(triangle_areas(v, f), [3, 3])
    np.testing.assert_allclose(compute_vertex_normals(v, f[:1]), [[0, 0, 1]] * 3)


def test_meshdata_coerces_dtypes():
    m = MeshData([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    assert m.vertices.dtype == np.float64 and m.faces.dtype == np.int32
    assert m.n_vertices == 3 and m.n_faces == 1 and m.group_names == []


# ---------------------------------------------------------------------------
# quad and transforms


def test_quad():
    m = quad((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0))
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3]])
    assert m.vertex_normals is None
    fn = face_normals(m.vertices, m.faces)
    np.testing.assert_allclose(fn / np.linalg.norm(fn, axis=1, keepdims=True),
                               [[0, 0, 1]] * 2)
    np.testing.assert_allclose(triangle_areas(m.vertices, m.faces).sum(), 1.0)
    with pytest.raises(SceneError, match=r"light\.p2"):
        quad((0, 0, 0), (1, 0, 0), (1, float("nan"), 0), (0, 1, 0), field="light")
    with pytest.raises(SceneError, match="degenerate"):
        quad((0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0))


def test_transform_matrix_order():
    # scale first, then rotate X then Y then Z, then translate
    m = transform_matrix(translate=(10, 20, 30), scale=(2, 3, 4), rotate_deg=(90, 90, 0))
    p = m @ np.array([0, 1, 0, 1.0])      # scale -> (0,3,0); Rx90 -> (0,0,3); Ry90 -> (3,0,0)
    np.testing.assert_allclose(p, [13, 20, 30, 1], atol=1e-12)
    p = transform_matrix(rotate_deg=(0, 0, 90)) @ np.array([1, 0, 0, 1.0])
    np.testing.assert_allclose(p, [0, 1, 0, 1], atol=1e-12)
    np.testing.assert_allclose(transform_matrix(scale=2.5)[:3, :3], 2.5 * np.eye(3))
    np.testing.assert_array_equal(transform_matrix(), np.eye(4))
    with pytest.raises(SceneError, match=r"objects\[0\]\.transform\.scale"):
        transform_matrix(scale=(1, 0, 1), field="objects[0].transform")
    with pytest.raises(SceneError, match=r"translate"):
        transform_matrix(translate=(1, 2))
    with pytest.raises(SceneError, match=r"rotate_deg"):
        transform_matrix(rotate_deg=(0, float("inf"), 0))


def test_transform_negative_determinant_flips_winding():
    s = icosphere(2)
    for scale in [(-1, 1, 1), (1, -2, 1), (-1, -1, -1)]:
        t = transform_mesh(s, transform_matrix(translate=(1, 2, 3), scale=scale,
                                               rotate_deg=(10, 20, 30)))
        assert (outward(t, (1, 2, 3)) > 0).all(), scale
        # the transformed vertex normals still agree with the geometric normals
        fn = face_normals(t.vertices, t.faces)
        assert (np.einsum("ij,ij->i", fn, t.vertex_normals[t.faces[:, 0]]) > 0).all()
    t = transform_mesh(s, transform_matrix(scale=(-1, 1, 1)))
    np.testing.assert_array_equal(t.faces, s.faces[:, [0, 2, 1]])
    t = transform_mesh(s, transform_matrix(scale=(1, 2, 1)))
    np.testing.assert_array_equal(t.faces, s.faces)


def test_transform_normals_non_uniform_scale():
    s = icosphere(3)
    a, b, c = 2.0, 1.0, 0.5
    t = transform_mesh(s, transform_matrix(translate=(5, 0, 0), scale=(a, b, c),
                                           rotate_deg=(0, 0, 30)))
    # ellipsoid: exact normal ∝ R (x/a^2, y/b^2, z/c^2) with (x,y,z) in the
    # unrotated, untranslated frame
    r = transform_matrix(rotate_deg=(0, 0, 30))[:3, :3]
    q = (t.vertices - (5, 0, 0)) @ r          # undo rotation (row vectors)
    g = q / np.array([a * a, b * b, c * c])
    g = g @ r.T
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    np.testing.assert_allclose(t.vertex_normals, g, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(t.vertex_normals, axis=1), 1.0)
    # the original mesh is untouched
    np.testing.assert_allclose(np.linalg.norm(s.vertices, axis=1), 1.0)


def test_transform_mesh_errors_and_groups():
    s = icosphere(0)
    m = np.eye(4)
    m[2, 2] = 0.0
    with pytest.raises(SceneError, match=r"obj\.transform: .*singular"):
        transform_mesh(s, m, field="obj.transform")
    m = np.eye(4)
    m[3, 0] = 1.0
    with pytest.raises(SceneError, match="affine"):
        transform_mesh(s, m)
    with pytest.raises(SceneError, match="4x4"):
        transform_mesh(s, np.eye(3))
    g = MeshData(s.vertices, s.faces, None, np.arange(20) % 2, ["a", "b"])
    t = transform_mesh(g, transform_matrix(scale=(-1, 1, 1)))
    np.testing.assert_array_equal(t.face_groups, g.face_groups)
    assert t.group_names == ["a", "b"] and t.vertex_normals is None


def test_obj_whitespace_tabs_and_extra_components(tmp_path):
    text = ("  v 0 0 0 1.0\nv\t1\t0\t0\nv 0 1 0 0.5 0.5 0.5\n"
            "\tusemtl  metal \nf\t1 2 3\n")
    p = tmp_path / "ws.obj"
    p.write_text(text)
    m = read_obj(p)
    np.testing.assert_allclose(m.vertices, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    np.testing.assert_array_equal(m.faces, [[0, 1, 2]])
    assert m.group_names == ["metal"]


# ---------------------------------------------------------------------------
# property test: every PLY encoding of a random polygon mesh reads the same

@settings(max_examples=25, deadline=None)
@given(st.data())
def test_ply_encodings_agree(tmp_path_factory, data):
    nv = data.draw(st.integers(3, 12))
    sizes = data.draw(st.lists(st.integers(3, 6), min_size=1, max_size=8))
    faces = [data.draw(st.lists(st.integers(0, nv - 1), min_size=k, max_size=k))
             for k in sizes]
    rng = np.random.default_rng(len(faces) * 31 + nv)
    verts = rng.normal(size=(nv, 3)).astype(np.float32).astype(float)
    d = tmp_path_factory.mktemp("enc")
    results = []
    for fmt in ("ascii", "binary_little_endian", "binary_big_endian"):
        p = write_ply(d / f"{fmt}.ply", fmt, [("float", c) for c in "xyz"],
                      [tuple(r) for r in verts.tolist()],
                      ("uchar", "int", "vertex_indices"), faces)
        results.append(read_ply(p))
    # expected fan triangulation
    expect = [(f[0], f[i], f[i + 1]) for f in faces for i in range(1, len(f) - 1)]
    for m in results:
        np.testing.assert_array_equal(m.faces, np.array(expect).reshape(-1, 3))
        np.testing.assert_array_equal(m.vertices, verts)


# ---------------------------------------------------------------------------
# issue 13: defects in mesh files


@pytest.mark.parametrize("fmt", ["binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("count_type", ["int64", "uint64"])
@pytest.mark.parametrize("index_type", ["int", "int64"])
def test_ply_64bit_list_counts_mixed_polygons(tmp_path, fmt, count_type, index_type):
    # was rejected for big endian ("face 0 has 0 corner(s)": '>l' read 4 of 8 bytes)
    rows = [tuple(float(c) for c in v) for v in CUBE_V]
    faces = _cube_faces_tri_and_quad()
    p = write_ply(tmp_path / "c64.ply", fmt, [("float", c) for c in "xyz"], rows,
                  (count_type, index_type, "vertex_indices"), faces)
    m = read_ply(p)
    _check_cube(m)
    expect = [(f[0], f[i], f[i + 1]) for f in faces for i in range(1, len(f) - 1)]
    np.testing.assert_array_equal(m.faces, expect)


@pytest.mark.parametrize("corners", [3, 4])
@pytest.mark.parametrize("fmt", ["binary_little_endian", "binary_big_endian"])
def test_ply_uniform_polygons_int64_counts(tmp_path, corners, fmt):
    # the memory-mapped path (all faces of one size) with 8-byte counts
    faces = (_cube_faces_tri_and_quad()[:2] if corners == 3 else [list(q) for q in CUBE_Q])
    p = write_ply(tmp_path / "u.ply", fmt, [("double", c) for c in "xyz"],
                  [tuple(float(c) for c in v) for v in CUBE_V],
                  ("uint64", "uint", "vertex_indices"), faces)
    m = read_ply(p)
    expect = [(f[0], f[i], f[i + 1]) for f in faces for i in range(1, len(f) - 1)]
    np.testing.assert_array_equal(m.faces, expect)


_PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
             "property float z\nelement face 1\nproperty list {count} int vertex_indices\n"
             "end_header\n")
_PLY_VERTS = "0 0 0\n1 0 0\n0 1 0\n"


def _one_line_scene_error(path, pattern):
    with pytest.raises(SceneError) as ei:
        read_mesh(path, field="objects[0].file")
    msg = str(ei.value)
    assert ei.value.field == "objects[0].file" and os.path.basename(path) in msg
    assert "\n" not in msg                     # one line, no traceback
    assert re.search(pattern, msg), msg


# One rule: a value that is not what the format says (a word or boolean where a number
# belongs, an index beyond any integer, a list longer than its row) is a one-line
# SceneError naming the file, the line or row, and the reason.
@pytest.mark.parametrize("name, text, pattern", [
    # OBJ index beyond int64 (was StopIteration)
    ("big.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999\n",
     r"line 4: vertex index 99999999999999999999999 is out of range"),
    ("bign.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//-99999999999999999999999\n",
     r"line 5: normal index -99999999999999999999999 is out of range"),
    # OBJ words / booleans / decimals where numbers or indices belong
    ("wv.obj", "v 0 0 0\nv 1 0 true\nv 0 1 0\nf 1 2 3\n", r"line 2: non-numeric 'v' value"),
    ("wn.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 yes\nf 1//1 2//1 3//1\n",
     r"line 4: non-numeric 'vn' value"),
    ("wf.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 True\n", r"line 4: bad vertex index 'True'"),
    ("df.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3.0\n", r"line 4: bad vertex index '3.0'"),
    # ASCII PLY list length of 10^12 (was MemoryError), whatever the declared count type
    ("cu.ply", _PLY_HEAD.format(count="uchar") + _PLY_VERTS + "1000000000000 0 1 2\n",
     r"element 'face' row 0 \(line 13: '1000000000000 0 1 2'\).*fewer values"),
    ("ci.ply", _PLY_HEAD.format(count="int") + _PLY_VERTS + "1000000000000 0 1 2\n",
     r"element 'face' row 0 \(line 13.*fewer values"),
    ("cn.ply", _PLY_HEAD.format(count="int") + _PLY_VERTS + "-1 0 1 2\n",
     r"element 'face' row 0 \(line 13.*list lengths must be integers >= 0"),
    # ASCII PLY words, booleans and decimals where numbers or integers belong
    ("wv.ply", _PLY_HEAD.format(count="uchar") + "0 0 0\n1 0 true\n0 1 0\n3 0 1 2\n",
     r"non-numeric value 'true' in element 'vertex' row 1 \(line 11"),
    ("wf.ply", _PLY_HEAD.format(count="uchar") + _PLY_VERTS + "3 0 1 False\n",
     r"non-numeric value 'False' in element 'face' row 0"),
    ("df.ply", _PLY_HEAD.format(count="uchar") + _PLY_VERTS + "3 0 1 2.5\n",
     r"face 0 has a non-integer vertex index 2\.5"),
    ("dc.ply", _PLY_HEAD.format(count="uchar") + _PLY_VERTS + "3.0 0 1 2\n",
     r"element 'face' row 0 .*list lengths must be integers"),
    # values that would wrap in their declared type are range checked, not wrapped
    ("wr.ply", _PLY_HEAD.format(count="uchar") + _PLY_VERTS + "3 0 1 4294967298\n",
     r"face 0 references vertex index 4294967298, out of range for 3 vertices"),
    ("xl.ply", _PLY_HEAD.format(count="uchar") + _PLY_VERTS + "3 0 1 2 7\n",
     r"row 0 \(line 13.*more values than the header declares"),
])
def test_mesh_values_of_the_wrong_kind(tmp_path, name, text, pattern):
    p = tmp_path / name
    p.write_text(text)
    _one_line_scene_error(p, pattern)


@pytest.mark.parametrize("header_change, pattern", [
    (("element face 1\n", "element face 1000000000000\n"),
     r"truncated data in element 'face' \(1000000000000 rows\)"),
    (("element face 1\n", "element face -1\n"), r"bad element count on header line 7"),
    (("format ascii 1.0\n", ""), r"no 'format' line"),
    (("element face", "banana\nelement face"), r"header line 7 'banana'"),
    (("list uchar int", "list float int"), r"list count type must be an integer type"),
    (("list uchar int", "list uchar float"), r"vertex indices must have an integer type"),
])
def test_ply_header_errors_are_one_line(tmp_path, header_change, pattern):
    p = tmp_path / "h.ply"
    p.write_text(_PLY_HEAD.format(count="uchar").replace(*header_change)
                 + _PLY_VERTS + "3 0 1 2\n")
    _one_line_scene_error(p, pattern)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_tolerated_header_oddities(tmp_path, fmt):
    # blank lines, a non-ASCII comment and double spaces in the header (plyfile 1.0 alone
    # rejects the first two); the binary body is then read through the normalised header
    rows = [tuple(float(c) for c in v) for v in CUBE_V]
    p = write_ply(tmp_path / "odd.ply", fmt, [("float", c) for c in "xyz"], rows,
                  ("uchar", "int", "vertex_indices"), _cube_faces_tri_and_quad())
    data = p.read_bytes()
    odd = data.replace(b"element face", "\ncomment caf\u00e9 \u00e0 la cr\u00e8me\n\n"
                                        "element  face".encode("utf-8"), 1)
    p.write_bytes(odd)
    _check_cube(read_ply(p))


def test_obj_faces_before_first_usemtl_name_their_line(tmp_path):
    # decision (engine/scene/obj.py docstring): such faces keep group -1 and the mesh
    # records the line of the first one, for the loader's error message
    p = tmp_path / "g.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n# comment\nf 1 2 3\nusemtl glass\nf 1 2 3\n")
    m = read_obj(p)
    np.testing.assert_array_equal(m.face_groups, [-1, 0])
    assert m.ungrouped_line == 5
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl glass\nf 1 2 3\nf 1 2 3\n")
    assert read_obj(p).ungrouped_line is None
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    m = read_obj(p)
    assert m.ungrouped_line is None and m.face_groups is None


@pytest.mark.subprocess
def test_plyfile_is_needed_only_for_ply(tmp_path):
    # The Blender extension ships without plyfile: importing the scene loader must not
    # import it, OBJ must read without it, and PLY must say what is missing.
    obj = tmp_path / "t.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    ply = _tri_ply(tmp_path)
    script = (
        "import sys\n"
        "sys.modules['plyfile'] = None\n"   # makes 'import plyfile' fail
        "import engine.scene.loader\n"
        "from engine.errors import SceneError\n"
        "from engine.scene.meshio import read_mesh\n"
        "assert read_mesh(sys.argv[1]).faces.shape == (1, 3)\n"
        "try:\n"
        "    read_mesh(sys.argv[2], field='objects[0].file')\n"
        "except SceneError as e:\n"
        "    print(e)\n")
    out = subprocess.run([sys.executable, "-c", script, str(obj), str(ply)], capture_output=True,
                         text=True, cwd=REPO)
    assert out.returncode == 0, out.stderr
    assert "objects[0].file: " in out.stdout and "needs the 'plyfile' package" in out.stdout


# every PLY type for coordinates, list counts and indices, extra properties and elements,
# in all three encodings, reads back what was written
_COORD_TYPES = ["char", "uchar", "short", "ushort", "int", "uint", "float", "double", "int64"]
_COUNT_TYPES = ["uchar", "char", "ushort", "short", "uint", "int", "int64", "uint64"]
_INDEX_TYPES = ["int", "uint", "ushort", "short", "int64", "uint64", "int32"]


@settings(max_examples=30, deadline=None)
@given(st.data())
def test_ply_types_and_layouts_agree(tmp_path_factory, data):
    coord = data.draw(st.sampled_from(_COORD_TYPES))
    count_t = data.draw(st.sampled_from(_COUNT_TYPES))
    index_t = data.draw(st.sampled_from(_INDEX_TYPES))
    fmt = data.draw(st.sampled_from(["ascii", "binary_little_endian", "binary_big_endian"]))
    nv = data.draw(st.integers(3, 9))
    sizes = data.draw(st.lists(st.integers(3, 5), min_size=1, max_size=6))
    faces = [data.draw(st.lists(st.integers(0, nv - 1), min_size=k, max_size=k)) for k in sizes]
    rng = np.random.default_rng(nv * 7 + len(faces))
    verts = rng.integers(0, 100, size=(nv, 3)).astype(float)   # exact in every coord type
    vprops = [("uchar", "red"), (coord, "x"), (coord, "y"), (coord, "z"), ("float", "w")]
    rows = [(7, *v, 0.5) for v in verts.tolist()]
    if coord in ("char", "uchar", "short", "ushort", "int", "uint", "int64"):
        rows = [(7, *map(int, v), 0.5) for v in verts.tolist()]
    extra = ("edge", [("int", "a"), ("int", "b")], [(0, 1)])
    d = tmp_path_factory.mktemp("types")
    p = write_ply(d / "m.ply", fmt, vprops, rows, (count_t, index_t, "vertex_indices"), faces,
                  extra_face_props=[("short", "flags", [1] * len(faces))],
                  extra_elements_before_face=[extra])
    m = read_ply(p)
    expect = [(f[0], f[i], f[i + 1]) for f in faces for i in range(1, len(f) - 1)]
    np.testing.assert_array_equal(m.faces, np.array(expect).reshape(-1, 3))
    np.testing.assert_array_equal(m.vertices, verts)
