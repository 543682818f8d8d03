"""CompiledScene.unblock_own_hits with one emitter per shadow ray (PathTracer._unblock_own_hits puts every light's
blocked rays into one Embree query): the same answers as one call per emitter."""

import numpy as np

from engine.materials.lambert import Lambert
from engine.render.accel import CompiledScene
from engine.render.lights import LightSet
from engine.scene.description import Camera, Mesh, RenderSettings, Scene
from engine.spectral import ConstantSpectrum


def panel(name, corner, ex, ey, n=4):
    """An n × n grid of quads, two-sided and emitting (Blender's emissive mesh)."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="xy")
    s, t = (i / n).ravel(), (j / n).ravel()
    vertices = np.asarray(corner, float) + s[:, None] * np.asarray(ex, float) + t[:, None] * np.asarray(ey, float)
    faces = []
    for b in range(n):
        for a in range(n):
            v00, v01 = b * (n + 1) + a, (b + 1) * (n + 1) + a
            faces += [[v00, v00 + 1, v01 + 1], [v00, v01 + 1, v01]]
    mesh = Mesh(name, vertices, np.array(faces, np.int64), ["grey"], np.zeros(len(faces), np.int32),
                emission=ConstantSpectrum(1.0))
    mesh.two_sided = True
    return mesh


def test_one_query_for_several_emitters_answers_as_one_per_emitter():
    cam = Camera(origin=np.array([0.0, 0.0, 5.0]), target=np.zeros(3), up=np.array([0.0, 1.0, 0.0]), width=4, height=4)
    scene = Scene(camera=cam, meshes=[panel("a", (0.5, -1, 0.1), (0, 0, 1), (0, 2, 0)),
                                      panel("b", (-0.5, -1, 0.1), (0, 2, 0), (0, 0, 1))],
                  materials={"grey": Lambert(ConstantSpectrum(0.5))}, lights=[], settings=RenderSettings(spp=1))
    compiled = CompiledScene(scene)
    lights = LightSet(scene, compiled)               # fills compiled.tri_emitter
    assert all(light.blocks_own_shadow_rays for light in lights.lights)
    rng = np.random.default_rng(5)
    n = 400
    emitter = rng.integers(0, 2, n)
    tris = [np.flatnonzero(compiled.tri_emitter == e) for e in (0, 1)]
    assert all(t.size for t in tris)
    prim = np.array([rng.choice(tris[e]) for e in emitter])
    w = rng.dirichlet(np.ones(3), n)                                     # a point on the chosen triangle
    x = np.einsum("nk,nkc->cn", w, compiled.vertices[compiled.faces[prim]].astype(np.float64))
    p = np.stack((rng.uniform(-0.3, 0.3, n), rng.uniform(-0.8, 0.8, n), np.zeros(n)))    # on the floor between
    n_g = np.tile([[0.0], [0.0], [1.0]], (1, n))
    v = x - p
    dist = np.sqrt((v * v).sum(0))
    wi = v / dist
    cos_l = np.abs((wi * compiled.tri_normal[prim].T.astype(np.float64)).sum(0))
    blocked = rng.random(n) < 0.8
    one = compiled.unblock_own_hits(emitter, p, n_g, wi, dist, cos_l, blocked)
    each = blocked.copy()
    for e in (0, 1):
        sel = np.flatnonzero(emitter == e)
        each[sel] = compiled.unblock_own_hits(e, p[:, sel], n_g[:, sel], wi[:, sel], dist[sel], cos_l[sel],
                                              blocked[sel])
    np.testing.assert_array_equal(one, each)
    for e in (0, 1):        # both emitters' own hits were cleared, the others' rays left blocked
        assert (blocked & ~one & (emitter == e)).any()
    assert not (one & ~blocked).any()
