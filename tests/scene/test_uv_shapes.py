"""UV maps of scene-file spheres, PLY texture coordinates and vertex colours, OBJ ``vt``.

Sphere convention (Blender's UV sphere): u = ½ + atan2(y, x)/2π, v = 1 − acos(z)/π in the sphere's
own frame; the seam (u = 0 ≡ 1) at −X."""

import json

import numpy as np
import pytest
from PIL import Image

from engine.errors import SceneError
from engine.render.renderer import Renderer
from engine.scene.loader import parse_scene
from engine.scene.meshio import read_mesh
from engine.scene.obj import read_obj
from engine.scene.ply import read_ply
from engine.scene.shapes import icosphere
from engine.textures.image import read_image, srgb_to_linear


def _sphere_u(p):
    return 0.5 + np.arctan2(p[..., 1], p[..., 0]) / (2 * np.pi)


# --------------------------------------------------------------------------- the sphere's map


@pytest.mark.parametrize("level", [0, 2, 4])
def test_sphere_uv_is_longitude_latitude_and_keeps_the_geometry(level):
    plain, mapped = icosphere(level), icosphere(level, uv=True)
    n = plain.n_vertices
    # the original vertices first and unchanged, faces in their order with the same corner positions
    np.testing.assert_array_equal(mapped.vertices[:n], plain.vertices)
    np.testing.assert_array_equal(mapped.vertices[mapped.faces], plain.vertices[plain.faces])
    np.testing.assert_array_equal(mapped.vertex_normals[mapped.faces], plain.vertex_normals[plain.faces])
    p = mapped.vertices
    np.testing.assert_allclose(mapped.uv[:, 1], 1 - np.arccos(np.clip(p[:, 2], -1, 1)) / np.pi, atol=1e-15)
    off_pole = np.abs(p[:, 2]) < 1
    du = (mapped.uv[:, 0] - _sphere_u(p)) % 1.0          # equal modulo 1 (the seam side may add 1)
    assert np.all(np.minimum(du, 1 - du)[off_pole] < 1e-12)
    assert mapped.uv[:, 0].min() >= 0 and mapped.uv[:, 0].max() < 1.25


def test_sphere_uv_does_not_smear_across_the_seam():
    """Anywhere on any triangle the interpolated u is the point's own longitude (mod 1) to within
    the facet's size; without seam handling triangles at −X would interpolate through u ≈ ½."""
    m = icosphere(3, uv=True)
    rng = np.random.default_rng(0)
    b = rng.dirichlet([1, 1, 1], size=(m.n_faces, 8))                  # (F, 8, 3) barycentrics
    pts = np.einsum("fsk,fkd->fsd", b, m.vertices[m.faces])
    uvs = np.einsum("fsk,fkd->fsd", b, m.uv[m.faces])
    pole_face = (np.abs(m.vertices[m.faces][:, :, 2]) == 1).any(axis=1)
    pts, uvs = pts[~pole_face], uvs[~pole_face]
    du = (uvs[..., 0] - _sphere_u(pts)) % 1.0
    assert np.minimum(du, 1 - du).max() < 0.05             # unhandled, the seam faces give ~0.45
    dv = uvs[..., 1] - (1 - np.arccos(pts[..., 2] / np.linalg.norm(pts, axis=-1)) / np.pi)
    assert np.abs(dv).max() < 0.05


def _sphere_scene(albedo, tmp_path, origin):
    return parse_scene(json.loads(json.dumps({
        "format": "polar-scene/1",
        "camera": {"origin": origin, "target": [0, 0, 0], "up": [0, 0, 1], "projection": "orthographic",
                   "ortho_width": 2.2, "width": 16, "height": 16},
        "render": {"spp": 4, "max_depth": 2, "spectral": "spectral", "reduce_spectral": "off"},
        "materials": {"ball": {"type": "lambert", "albedo": albedo}},
        "objects": [{"shape": "sphere", "subdivisions": 3, "material": "ball"}],
        "lights": [{"type": "environment", "radiance": 1.0}]})), str(tmp_path))


@pytest.mark.parametrize("origin, left, right", [([5, 0, 0], 1, 2),      # sees u = ½: y < 0 left (u < ½)
                                                 ([-5, 0, 0], 3, 0)])    # sees the seam: y > 0 left (u → 1)
def test_textured_sphere_renders_each_hemisphere_with_its_texel(tmp_path, origin, left, right):
    """A 4×1 texture (Closest) on the sphere: seen from +X the left half of the ball shows texel 1
    (u ∈ [¼, ½)) and the right half texel 2; from −X (the seam) texel 3 and texel 0.  Each pixel
    equals the render of the untextured sphere with that texel's constant albedo."""
    cells = np.array([[[200, 30, 30], [20, 180, 40], [30, 40, 220], [230, 200, 20]]], np.uint8)
    Image.fromarray(cells).save(tmp_path / "bands.png")
    texels = read_image(str(tmp_path / "bands.png"))[0]
    scene = _sphere_scene({"texture": "bands.png", "interpolation": "Closest"}, tmp_path, origin)
    S = Renderer(scene).render().stokes()
    c = (np.arange(16) + 0.5) / 16 * 2.2 - 1.1                           # pixel centres
    radius = np.hypot(c[None, :], c[:, None])
    inside = radius < 0.75                                               # far from the silhouette
    for texel, cols in ((left, c < -0.2), (right, c > 0.2)):             # away from the dividing meridian
        const = Renderer(_sphere_scene(texels[texel].astype(np.float64).tolist(), tmp_path, origin)).render().stokes()
        mask = inside & cols[None, :]
        assert mask.sum() > 20
        np.testing.assert_allclose(S[:, mask], const[:, mask], rtol=1e-12, atol=1e-15)


def test_untextured_spheres_keep_the_peer_mesh_numbering(tmp_path):
    scene = _sphere_scene([0.5, 0.5, 0.5], tmp_path, [5, 0, 0])
    mesh = scene.meshes[0]
    assert mesh.uv is None and len(mesh.vertices) == icosphere(3).n_vertices
    textured = parse_scene(json.loads(json.dumps({
        "format": "polar-scene/1", "camera": {"origin": [5, 0, 0], "target": [0, 0, 0], "up": [0, 0, 1],
                                              "width": 4, "height": 4},
        "materials": {"a": {"type": "lambert", "albedo": 0.5},
                      "b": {"type": "lambert", "albedo": {"vertex_color": "Col"}}},
        "objects": [{"shape": "sphere", "subdivisions": 2, "material": "a"},
                    {"shape": "sphere", "subdivisions": 2, "materials": ["a", "b"]}]})), str(tmp_path))
    assert textured.meshes[0].uv is None
    assert textured.meshes[1].uv is not None and len(textured.meshes[1].vertices) > icosphere(2).n_vertices


# --------------------------------------------------------------------------- PLY


def _write_ply(path, vertex_fields, faces, text=False):
    import plyfile
    vertex = np.empty(len(vertex_fields["x"]), dtype=[(k, v.dtype) for k, v in vertex_fields.items()])
    for k, v in vertex_fields.items():
        vertex[k] = v
    face = np.empty(len(faces), dtype=[("vertex_indices", "i4", (len(faces[0]),))])
    face["vertex_indices"] = faces
    plyfile.PlyData([plyfile.PlyElement.describe(vertex, "vertex"), plyfile.PlyElement.describe(face, "face")],
                    text=text).write(str(path))


QUAD = np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
QUAD_UV = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])


@pytest.mark.parametrize("names", [("u", "v"), ("s", "t"), ("texture_u", "texture_v"), ("texture_s", "texture_t")])
@pytest.mark.parametrize("text", [False, True])
def test_ply_texture_coordinates_round_trip(tmp_path, names, text):
    uv = np.array([[0.1, 0.2], [0.9, 0.25], [0.8, 0.7], [0.05, 0.95]], np.float32)
    fields = {"x": QUAD[:, 0].astype(np.float32), "y": QUAD[:, 1].astype(np.float32),
              "z": QUAD[:, 2].astype(np.float32), names[0]: uv[:, 0], names[1]: uv[:, 1]}
    _write_ply(tmp_path / "q.ply", fields, [[0, 1, 2], [0, 2, 3]], text=text)
    m = read_ply(tmp_path / "q.ply")
    np.testing.assert_array_equal(m.uv, uv.astype(np.float64))
    assert m.colors == {}


def test_ply_vertex_colours_are_decoded_from_srgb_by_type(tmp_path):
    rgb8 = np.array([[255, 0, 10], [128, 64, 200], [0, 0, 0], [12, 240, 99]], np.uint8)
    alpha = np.array([255, 128, 0, 64], np.uint8)
    base = {"x": QUAD[:, 0], "y": QUAD[:, 1], "z": QUAD[:, 2]}
    _write_ply(tmp_path / "c8.ply", {**base, "red": rgb8[:, 0], "green": rgb8[:, 1], "blue": rgb8[:, 2],
                                     "alpha": alpha}, [[0, 1, 2], [0, 2, 3]])
    m = read_ply(tmp_path / "c8.ply")
    expect = np.column_stack((srgb_to_linear(rgb8 / 255.0), alpha / 255.0))
    np.testing.assert_array_equal(m.colors["Col"], expect)
    rgb16 = (rgb8.astype(np.uint16) * 257)
    _write_ply(tmp_path / "c16.ply", {**base, "red": rgb16[:, 0], "green": rgb16[:, 1], "blue": rgb16[:, 2]},
               [[0, 1, 2], [0, 2, 3]], text=True)
    np.testing.assert_allclose(read_ply(tmp_path / "c16.ply").colors["Col"], srgb_to_linear(rgb8 / 255.0), rtol=1e-15)
    rgbf = (rgb8 / 255.0).astype(np.float32)
    _write_ply(tmp_path / "cf.ply", {**base, "red": rgbf[:, 0], "green": rgbf[:, 1], "blue": rgbf[:, 2]},
               [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_array_equal(read_ply(tmp_path / "cf.ply").colors["Col"], srgb_to_linear(rgbf.astype(np.float64)))
    bad = rgbf.copy()
    bad[2, 1] = 1.5
    _write_ply(tmp_path / "bad.ply", {**base, "red": bad[:, 0], "green": bad[:, 1], "blue": bad[:, 2]},
               [[0, 1, 2], [0, 2, 3]])
    with pytest.raises(SceneError, match=r"bad\.ply'.*vertex 2 has a colour outside \[0, 1\]"):
        read_ply(tmp_path / "bad.ply", field="objects[0].file")


# --------------------------------------------------------------------------- OBJ


def test_obj_vt_splits_only_vertices_with_several_uvs(tmp_path):
    text = """
v -1 -1 0
v 1 -1 0
v 1 1 0
v -1 1 0
v 3 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vt 0 1
vt 0.5 1
f 1/1 2/2 3/3 4/4
f 2/2 5/6 3/5
"""
    (tmp_path / "m.obj").write_text(text)
    m = read_obj(tmp_path / "m.obj")
    # vertex 3 (1-based) meets (1, 1) and (0, 1): split once; vt 4 and 5 are equal values: no split
    assert m.n_vertices == 6
    np.testing.assert_array_equal(m.vertices[:5], [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0], [3, 1, 0]])
    np.testing.assert_array_equal(m.vertices[5], [1, 1, 0])
    corner_uv = m.uv[m.faces]
    np.testing.assert_array_equal(corner_uv[:2], [[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]])
    np.testing.assert_array_equal(corner_uv[2], [[1, 0], [0.5, 1], [0, 1]])


def test_obj_per_corner_uv_round_trip_with_normals(tmp_path):
    """A UV-mapped cube written per corner (v/vt/vn, every face its own UV square and normal) reads
    back with each corner's position, normal and UV; no (v, vn, vt) triple is lost or merged."""
    verts = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    lines = [f"v {x} {y} {z}" for x, y, z in verts]
    normals, uvs, faces = [], [], []
    for k, q in enumerate(quads):
        p = verts[q]
        n = np.cross(p[1] - p[0], p[2] - p[0])
        normals.append(n / np.linalg.norm(n))
        square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]]) * 0.1 + [0.15 * k, 0.5]
        uvs += list(square)
        faces.append([(q[i], 4 * k + i, k) for i in range(4)])
    lines += [f"vn {a} {b} {c}" for a, b, c in normals] + [f"vt {a} {b}" for a, b in uvs]
    lines += ["f " + " ".join(f"{v + 1}/{t + 1}/{n + 1}" for v, t, n in f) for f in faces]
    (tmp_path / "cube.obj").write_text("\n".join(lines))
    m = read_mesh(tmp_path / "cube.obj")
    assert m.n_faces == 12 and m.n_vertices == 24
    for k, f in enumerate(faces):
        for t, corners in enumerate(((0, 1, 2), (0, 2, 3))):   # fan triangulation
            tri = m.faces[2 * k + t]
            np.testing.assert_array_equal(m.vertices[tri], verts[[f[c][0] for c in corners]])
            np.testing.assert_array_equal(m.uv[tri], np.array(uvs)[[f[c][1] for c in corners]])
            np.testing.assert_allclose(m.vertex_normals[tri], [normals[k]] * 3, atol=1e-15)


def test_obj_bad_vt_index_names_the_line(tmp_path):
    (tmp_path / "b.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n")
    with pytest.raises(SceneError, match=r"line 5: texture coordinate index 2 is out of range \(1 texture"):
        read_obj(tmp_path / "b.obj", field="objects[0].file")


# --------------------------------------------------------------------------- renders of mesh files


def _plane_scene(obj, albedo, tmp_path):
    return parse_scene(json.loads(json.dumps({
        "format": "polar-scene/1",
        "camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0], "projection": "orthographic",
                   "ortho_width": 2.0, "width": 8, "height": 8},
        "render": {"spp": 4, "max_depth": 2, "spectral": "spectral", "reduce_spectral": "off"},
        "materials": {"plane": {"type": "lambert", "albedo": albedo}},
        "objects": [{**obj, "material": "plane"}],
        "lights": [{"type": "point", "position": [0.3, 0.2, 3], "intensity": 20}]})), str(tmp_path))


def test_textured_ply_and_obj_planes_render_as_the_uv_mapped_quad(tmp_path):
    """The same plane with the same UVs from a quad, a PLY (u, v) and an OBJ (vt) renders the same
    image of a 2×2 checker (the quad's render is checked texel by texel in test_textures)."""
    cells = np.array([[[200, 30, 30], [20, 180, 40]], [[30, 40, 220], [128, 128, 128]]], np.uint8)
    Image.fromarray(cells).save(tmp_path / "checker.png")
    albedo = {"texture": "checker.png", "interpolation": "Closest"}
    uv = QUAD_UV[[1, 2, 3, 0]]                   # a quarter turn, so the default would differ
    quad = {"shape": "quad", "vertices": QUAD.tolist(), "uv": uv.tolist()}
    fields = {"x": QUAD[:, 0], "y": QUAD[:, 1], "z": QUAD[:, 2], "u": uv[:, 0], "v": uv[:, 1]}
    _write_ply(tmp_path / "plane.ply", fields, [[0, 1, 2], [0, 2, 3]])
    obj = ["v " + " ".join(map(str, p)) for p in QUAD] + ["vt " + " ".join(map(str, t)) for t in uv]
    (tmp_path / "plane.obj").write_text("\n".join(obj + ["f 1/1 2/2 3/3 4/4"]))
    S = Renderer(_plane_scene(quad, albedo, tmp_path)).render().stokes()
    S_default = Renderer(_plane_scene({**quad, "uv": QUAD_UV.tolist()}, albedo, tmp_path)).render().stokes()
    assert not np.array_equal(S, S_default)
    for name in ("plane.ply", "plane.obj"):
        got = Renderer(_plane_scene({"shape": "mesh", "file": name}, albedo, tmp_path)).render().stokes()
        np.testing.assert_array_equal(got, S)


def test_ply_vertex_colours_drive_a_vertex_colour_albedo(tmp_path):
    """PLY colours (one colour on every vertex) as ``{"vertex_color": "Col"}`` render as that constant."""
    rgb8 = np.array([[180, 90, 40]] * 4, np.uint8)
    fields = {"x": QUAD[:, 0], "y": QUAD[:, 1], "z": QUAD[:, 2],
              "red": rgb8[:, 0], "green": rgb8[:, 1], "blue": rgb8[:, 2]}
    _write_ply(tmp_path / "plane.ply", fields, [[0, 1, 2], [0, 2, 3]])
    got = Renderer(_plane_scene({"shape": "mesh", "file": "plane.ply"}, {"vertex_color": "Col"}, tmp_path)).render()
    const = Renderer(_plane_scene({"shape": "mesh", "file": "plane.ply"},
                                  srgb_to_linear(rgb8[0] / 255.0).tolist(), tmp_path)).render()
    np.testing.assert_allclose(got.stokes(), const.stokes(), rtol=1e-12, atol=1e-15)
    assert got.stokes()[0].max() > 0
