"""Non-occluding emitters (Cycles' lamps) are looked for only along segments that pass near their bounding box
(CompiledScene.passthrough_hits, engine.kernels.rays.segments_near_box): the crossings are the ones every segment
handed to Embree gives, bit for bit, also for segments that graze the box's faces, edges and corners."""

import numpy as np

from engine.materials.lambert import Lambert
from engine.render import accel
from engine.render.accel import CompiledScene
from engine.scene.description import Camera, Mesh, Scene
from engine.spectral import ConstantSpectrum


def lamp_scene():
    """A floor and two non-occluding emissive quads (one tilted) above it."""
    cam = Camera(origin=np.array([0.0, -4.0, 1.0]), target=np.zeros(3), up=np.array([0.0, 0.0, 1.0]), width=8,
                 height=8, fov_deg=40.0)
    two = np.array([[0, 1, 2], [0, 2, 3]])
    floor = Mesh("floor", np.array([[-5.0, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]]), two, ["grey"],
                 np.zeros(2, np.int32))
    quad = np.array([[-0.5, -0.5, 2.0], [0.5, -0.5, 2.0], [0.5, 0.5, 2.0], [-0.5, 0.5, 2.0]])
    tilted = quad @ np.array([[1.0, 0, 0], [0, 0.8, -0.6], [0, 0.6, 0.8]]).T + np.array([1.5, 0.0, 0.5])
    lamps = [Mesh(name, v, two, ["grey"], np.zeros(2, np.int32),
                  emission=ConstantSpectrum(1.0), occluder=False) for name, v in (("lamp", quad), ("panel", tilted))]
    return CompiledScene(Scene(camera=cam, meshes=[floor, *lamps], materials={"grey": Lambert(ConstantSpectrum(0.5))}))


def segments(compiled, n=6000, seed=3):
    """Rays from around the scene: uniform directions, rays aimed at the box's corners, edges and faces (a hair
    either side), axis-parallel rays, unbounded and finite lengths (some ending just short of the lamps)."""
    rng = np.random.default_rng(seed)
    lo, hi = compiled.passthrough_box
    o = rng.uniform(-4, 4, (3, n)) + np.array([[0.0], [0.0], [1.5]])
    target = rng.uniform(lo, hi, (n, 3)).T
    k = n // 3
    snap = rng.integers(0, 2, (3, k))                                 # corners and edges of the box, ± a hair
    target[:, :k] = np.where(snap == 1, hi[:, None], lo[:, None]) + rng.normal(0, 1e-7, (3, k))
    d = target - o
    d[:, -k // 4:] = rng.normal(size=(3, k // 4))                     # any direction
    d[:2, -k // 4 - 200:-k // 4] = 0.0                                # straight up or down
    d /= np.linalg.norm(d, axis=0)
    t_max = np.where(rng.random(n) < 0.5, np.inf, rng.uniform(0, 8, n))
    return o, d, t_max


def unfiltered(compiled, o, d, t_max, monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(accel, "segments_near_box", lambda o, d, t, lo, hi: np.ones(o.shape[1], bool))
        return compiled.passthrough_hits(o, d, t_max)


def test_only_segments_near_the_lamps_are_cast_and_the_crossings_are_unchanged(monkeypatch):
    compiled = lamp_scene()
    o, d, t_max = segments(compiled)
    near = accel.segments_near_box(o, d, t_max, *compiled.passthrough_box)
    assert 0 < near.sum() < 0.9 * near.size               # the test skips Embree for some segments
    got, want = compiled.passthrough_hits(o, d, t_max), unfiltered(compiled, o, d, t_max, monkeypatch)
    assert len(want) >= 2 and sum(len(w[0]) for w in want) > 500
    assert len(got) == len(want)
    for g, w in zip(got, want):
        assert all(a.dtype == b.dtype and a.tobytes() == b.tobytes() for a, b in zip(g, w))
    # every crossing's segment was kept by the box test
    assert near[np.concatenate([w[0] for w in want])].all()


def test_segments_far_from_the_lamps_cast_nothing(monkeypatch):
    compiled = lamp_scene()
    cast = []
    real = compiled.rays_passthrough.closest
    monkeypatch.setattr(compiled.rays_passthrough, "closest", lambda *a: cast.append(a[0].shape[1]) or real(*a))
    o = np.tile([[0.0], [0.0], [0.5]], 50)
    d = np.tile([[0.0], [0.0], [-1.0]], 50)                # down, away from the lamps
    assert compiled.passthrough_hits(o, d, np.full(50, np.inf)) == [] and cast == []
    d[2] = 1.0                                               # up, through the lamp
    layers = compiled.passthrough_hits(o, d, np.full(50, np.inf))
    assert cast == [50, 50] and len(layers) == 1 and layers[0][0].size == 50
