"""The viewport's background session, headless: what each kind of edit re-exports (fake depsgraph:
plain objects with the attributes Blender's have), that tracing happens only on the session's
thread, never in draw, and that stopping ends the thread promptly."""

import dataclasses
import threading
import time

import numpy as np
import pytest

from tests.blender_support import load_addon


@pytest.fixture(scope="module")
def vp():
    load_addon()
    from polar_render.polar_addon import viewport
    return viewport


# ------------------------------------------------------------------ a fake depsgraph

class ID:
    def __init__(self, name, id_type="OBJECT"):
        self.name = self.name_full = name
        self.id_type = id_type
        self.original = self


class Slot:
    def __init__(self, material):
        self.material = material


class Obj(ID):
    def __init__(self, name, type_="MESH", data=None, materials=()):
        super().__init__(name)
        self.type = type_
        self.data = data if data is not None else ID(f"{name}-data", type_)
        self.material_slots = [Slot(m) for m in materials]


class Instance:
    def __init__(self, obj, matrix):
        self.object, self.matrix_world, self.is_instance = obj, matrix, False


class Update:
    def __init__(self, id_, geometry=False, transform=False, shading=False):
        self.id, self.is_updated_geometry, self.is_updated_transform, self.is_updated_shading = \
            id_, geometry, transform, shading


class Depsgraph:
    def __init__(self, instances, world=None, updates=()):
        self.object_instances = instances
        self.updates = list(updates)
        self.scene = ID("Scene", "SCENE")
        self.scene.world = world


def translate(x):
    m = np.eye(4)
    m[0, 3] = x
    return m


class Exporter:
    """Records every export call; geometry is a unit triangle per object."""

    def __init__(self, vp):
        from polar_render.engine.materials.lambert import Lambert
        from polar_render.engine.spectral import ConstantSpectrum
        self.calls = []
        self.lambert = lambda v: Lambert(ConstantSpectrum(v))
        self.emissive = set()
        self.reshaped = set()      # objects whose evaluated geometry differs from what was read
        from polar_render.polar_addon.export.geometry import object_meshes
        self.export = vp.SceneWalk(geometry_arrays=self.mesh_arrays, object_meshes=object_meshes,
                                           material_entry=self.material, export_light=self.light,
                                           export_world=self.world,
                                           geometry_unchanged=self.geometry_unchanged)

    def geometry_unchanged(self, obj, arrays):
        self.calls.append(("compare", obj.name))
        return obj.name not in self.reshaped

    def mesh_arrays(self, obj):
        self.calls.append(("mesh", obj.name))
        P = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
        return P, np.array([[0, 1, 2]]), np.tile([0.0, 0, 1], (3, 1)), np.zeros(1, np.int32)

    def material(self, material, warnings, bake=None):
        from polar_render.engine.spectral import ConstantSpectrum
        name = material.name_full if material is not None else None
        self.calls.append(("material", name))
        return self.lambert(0.5), (ConstantSpectrum(1.0) if name in self.emissive else None), 1.0

    def light(self, obj, M, warnings):
        from polar_render.engine.scene.description import PointLight
        from polar_render.engine.spectral import ConstantSpectrum
        self.calls.append(("light", obj.name))
        return PointLight(M[:3, 3].copy(), ConstantSpectrum(1.0))

    def world(self, world, warnings):
        self.calls.append(("world", None if world is None else world.name))
        return None

    def sync(self, depsgraph, updates=None, settings=None):
        from polar_render.engine.scene.description import RenderSettings
        from polar_render.polar_addon.viewport import classify, depsgraph_updates
        # (the walk reads the settings' light_tree; seed 1: later syncs with other settings restart the render)
        settings = RenderSettings(seed=1) if settings is None else settings
        self.calls.clear()
        changes = classify(depsgraph_updates(depsgraph)) if self.export.initialised else None
        return self.export.sync(depsgraph, changes, settings)


@pytest.fixture()
def scene(vp):
    red, blue = ID("Red", "MATERIAL"), ID("Blue", "MATERIAL")
    a = Obj("A", materials=[red])
    b = Obj("B", materials=[blue])
    lamp = Obj("Lamp", "LIGHT")
    instances = [Instance(a, translate(0)), Instance(b, translate(2)), Instance(lamp, translate(5))]
    ex = Exporter(vp)
    first = ex.sync(Depsgraph(instances))
    assert first.rebuild and first.restart
    assert sorted(ex.calls) == sorted([("mesh", "A"), ("mesh", "B"), ("material", "Red"), ("material", "Blue"),
                                       ("light", "Lamp"), ("world", None)])
    return ex, instances, (a, b, lamp, red, blue)


def test_classify_names_what_each_update_invalidates(vp):
    c = vp.classify([("OBJECT", "A", True, False, False), ("OBJECT", "B", False, True, False),
                     ("MESH", "A-data", True, False, False), ("MATERIAL", "Red", False, False, True),
                     ("OBJECT", "C", False, False, False)])
    assert c.objects_geometry == {"A"} and c.objects_transform == {"B"} and c.data_geometry == {"A-data"}
    assert c.materials == {"Red"} and not c.all_materials and not c.world
    assert vp.classify([("NODETREE", "Group", False, False, True)]).all_materials
    assert not vp.classify([("OBJECT", "C", False, False, False)]).any()       # selection only


def test_material_edit_that_also_flags_object_geometry_re_reads_only_changed_geometry(vp, scene):
    """Blender 5.3 flags the geometry of every object using an edited material (its mesh data only
    with shading); 4.5-5.2 do not.  The viewport compares the geometry instead of re-reading it."""
    ex, instances, (a, b, lamp, red, blue) = scene
    updates = [Update(a, geometry=True, shading=True), Update(a.data, shading=True), Update(red, shading=True)]
    changes = vp.classify(vp.depsgraph_updates(Depsgraph(instances, updates=updates)))
    assert changes.objects_geometry_unconfirmed == {"A"} and not changes.objects_geometry
    r = ex.sync(Depsgraph(instances, updates=updates))
    assert sorted(ex.calls) == [("compare", "A"), ("material", "Red")]
    assert r.restart and not r.rebuild
    ex.reshaped.add("A")                                  # e.g. a driver moved its vertices too
    r = ex.sync(Depsgraph(instances, updates=updates))
    assert sorted(ex.calls) == [("compare", "A"), ("material", "Red"), ("mesh", "A")] and r.rebuild
    # a modifier edit (no material update) and a mesh edit in the same batch as a material edit stay confirmed
    assert vp.classify([("OBJECT", "A", True, False, False)]).objects_geometry == {"A"}
    mixed = vp.classify([("OBJECT", "A", True, False, True), ("MESH", "B-data", True, False, True),
                         ("MATERIAL", "Red", False, False, True)])
    assert mixed.objects_geometry == {"A"} and not mixed.objects_geometry_unconfirmed


def test_selection_change_re_exports_nothing(scene):
    ex, instances, (a, *_rest) = scene
    r = ex.sync(Depsgraph(instances, updates=[Update(a)]))
    assert ex.calls == [] and not r.restart and not r.rebuild


def test_moving_an_object_re_places_it_without_reading_its_mesh(scene):
    ex, instances, (a, b, *_rest) = scene
    before = {m.name: m for m in ex.export.placed[("B",)][1]}
    instances[0].matrix_world = translate(1)
    r = ex.sync(Depsgraph(instances, updates=[Update(a, transform=True)]))
    assert ex.calls == []                                  # no to_mesh, no material, no light export
    assert ex.export.counts["placed"] == 1 and ex.export.counts["arrays"] == 0
    assert r.rebuild and r.restart
    a_mesh = next(m for m in r.scene.meshes if m.name.startswith("A:"))
    np.testing.assert_allclose(a_mesh.vertices[:, 0], [1, 2, 1])
    assert next(m for m in r.scene.meshes if m.name.startswith("B:")) is before["B:0"]   # untouched


def test_editing_one_mesh_reads_only_that_mesh(scene):
    ex, instances, (a, b, *_rest) = scene
    r = ex.sync(Depsgraph(instances, updates=[Update(b, geometry=True), Update(b.data, geometry=True)]))
    assert ex.calls == [("mesh", "B")] and r.rebuild and r.restart


def test_editing_a_material_swaps_it_without_a_bvh_rebuild(vp, scene):
    ex, instances, (a, b, lamp, red, blue) = scene
    old = ex.export.materials["Red"][1]
    from polar_render.engine.scene.description import RenderSettings
    order = list(ex.export.sync(Depsgraph(instances), vp.Changes(), RenderSettings()).scene.materials)
    r = ex.sync(Depsgraph(instances, updates=[Update(red, shading=True)]))
    assert ex.calls == [("material", "Red")]
    assert r.restart and not r.rebuild
    assert list(r.scene.materials) == order          # same indices: the compiled scene stays valid
    assert r.scene.materials["mat:Red"] is not old and r.scene.materials["mat:Blue"] is ex.export.materials["Blue"][1]


def test_a_material_becoming_emissive_rebuilds_the_light_set(scene):
    ex, instances, (a, b, lamp, red, blue) = scene
    ex.emissive.add("Red")
    r = ex.sync(Depsgraph(instances, updates=[Update(red, shading=True)]))
    assert ex.calls == [("material", "Red")] and r.rebuild
    assert next(m for m in r.scene.meshes if m.name.startswith("A:")).emission is not None


def test_shared_node_group_re_converts_all_materials_and_world(scene):
    ex, instances, _ = scene
    r = ex.sync(Depsgraph(instances, updates=[Update(ID("Group", "NODETREE"), shading=True)]))
    assert sorted(ex.calls) == [("material", "Blue"), ("material", "Red"), ("world", None)]
    assert r.restart and not r.rebuild


def test_light_edit_and_object_removal(scene):
    ex, instances, (a, b, lamp, *_rest) = scene
    r = ex.sync(Depsgraph(instances, updates=[Update(lamp.data, shading=True)]))
    assert ex.calls == [("light", "Lamp")] and r.restart
    r = ex.sync(Depsgraph(instances[1:], updates=[Update(ID("Scene", "SCENE"))]))
    assert ex.calls == [] and r.rebuild and [m.name for m in r.scene.meshes] == ["B:0"]
    assert ("A",) not in ex.export.placed and ("A", "MESH", "A-data") not in ex.export.arrays


def test_settings_change_restarts_without_re_export(scene):
    ex, instances, _ = scene
    from polar_render.engine.scene.description import RenderSettings
    r = ex.sync(Depsgraph(instances, updates=[Update(ID("Scene", "SCENE"))]), settings=RenderSettings(spp=2))
    assert ex.calls == [] and r.restart and not r.rebuild


def test_more_viewport_samples_continue_accumulating(vp, scene):
    from polar_render.engine.scene.description import RenderSettings
    ex, instances, _ = scene
    scene_update = [Update(ID("Scene", "SCENE"))]
    assert ex.sync(Depsgraph(instances, updates=scene_update), settings=RenderSettings(spp=4)).restart
    r = ex.sync(Depsgraph(instances, updates=scene_update), settings=RenderSettings(spp=64))
    assert not r.restart and not r.rebuild               # only the target changes
    assert ex.sync(Depsgraph(instances, updates=scene_update), settings=RenderSettings(spp=64, seed=3)).restart


# ------------------------------------------------------------------ the render thread

class FakeOut:
    def __init__(self, image, cancelled=False):
        self.image, self.cancelled = image, cancelled

    def stokes(self):
        return self.image


class FakeRenderer:
    """Records the thread of every render call; each pass returns a constant image of its seed."""

    def __init__(self, scene, log, delay=0.0, block=None):
        self.scene = scene
        self.compiled = type("C", (), {"material_names": list(scene.materials)})()
        self.log, self.delay, self.block = log, delay, block
        log.append(("build", threading.current_thread().name))

    def set_camera(self, camera):
        import dataclasses
        self.scene = dataclasses.replace(self.scene, camera=camera)

    def render(self, request):
        settings, should_stop = request.settings, request.should_stop
        self.log.append(("render", threading.current_thread().name))
        if self.block is not None:
            while not should_stop():       # like the tracer: polls between bounces
                time.sleep(0.005)
            return FakeOut(None, cancelled=True)
        time.sleep(self.delay)
        cam = self.scene.camera
        return FakeOut(np.full((4, cam.height, cam.width, 3), float(settings.seed)))


def _scene_result(vp, restart=True, rebuild=True):
    from polar_render.engine.scene.description import Camera, RenderSettings, Scene
    cam = Camera(origin=np.zeros(3), target=np.array([0.0, 0, -1]), up=np.array([0.0, 1, 0]), width=1, height=1)
    scene = Scene(camera=cam, materials={"m": None}, settings=RenderSettings(seed=10))
    return vp.SyncResult(scene, rebuild=rebuild, restart=restart, warnings=[])


def _view(w=8, h=6, x=0.0):
    from polar_render.engine.scene.description import Camera
    return Camera(origin=np.array([x, 0, 0.0]), target=np.array([x, 0, -1.0]), up=np.array([0.0, 1, 0]),
                  width=w, height=h)


def builds_and_renders_since(log):
    """(number of builds, number of renders after the last build) in a FakeRenderer log."""
    kinds = [k for k, _ in list(log)]
    last = max((i for i, k in enumerate(kinds) if k == "build"), default=-1)
    return kinds.count("build"), kinds[last + 1:].count("render")


def wait_for(predicate, timeout=10.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.01)
    return False


def converged_session(vp, log, target_samples):
    """A session over FakeRenderer (logging to ``log``) that has traced ``target_samples`` passes of
    the default view; stop it when done."""
    session = vp.ViewportSession(renderer_factory=lambda s: FakeRenderer(s, log))
    session.update_scene(_scene_result(vp), target_samples=target_samples)
    session.set_view(_view())
    if not wait_for(session.finished):
        session.stop()
        pytest.fail(f"the session did not finish {target_samples} passes")
    return session


def test_session_accumulates_on_its_thread_and_draw_never_traces(vp):
    log = []
    session = converged_session(vp, log, 4)
    try:
        image, samples, version = session.latest()
        assert samples == 4 and image.shape == (4, 6, 8, 3)
        np.testing.assert_allclose(image, np.mean([10, 11, 12, 13]))     # running mean of the 4 passes
        for _ in range(50):                                               # what view_draw does
            session.latest()
            session.finished()
        assert {t for _, t in log} == {"polar-viewport"}                  # never on this (the UI) thread
        assert [k for k, _ in log].count("build") == 1
    finally:
        assert session.stop()


def test_view_change_restarts_without_rebuild_and_material_change_keeps_the_bvh(vp):
    log = []
    session = converged_session(vp, log, 2)
    try:
        session.set_view(_view(4, 3, x=1.0))                              # orbit + resize
        assert wait_for(lambda: session.finished() and session.latest()[0].shape == (4, 3, 4, 3))
        session.update_scene(_scene_result(vp, rebuild=False))            # a material edit
        assert wait_for(lambda: session.finished() and session.latest()[2] >= 6)
        assert [k for k, _ in log].count("build") == 1
        session.update_scene(_scene_result(vp, rebuild=True))             # an object moved
        # the rebuilt scene's two passes must be done before "nothing more happens" can be checked
        assert wait_for(lambda: builds_and_renders_since(log) == (2, 2) and session.finished())
        before = len(log)
        session.update_scene(_scene_result(vp, restart=False, rebuild=False))   # selection only
        time.sleep(0.1)
        assert len(log) == before
        session.update_scene(_scene_result(vp, restart=False, rebuild=False), target_samples=5)  # more samples
        assert wait_for(lambda: session.finished() and session.latest()[1] == 5)
        assert len(log) == before + 3                                     # 3 more passes, no rebuild
    finally:
        assert session.stop()


def test_stop_interrupts_a_pass_in_progress(vp):
    log = []
    session = vp.ViewportSession(renderer_factory=lambda s: FakeRenderer(s, log, block=True))
    session.update_scene(_scene_result(vp), target_samples=4)
    session.set_view(_view())
    assert wait_for(lambda: ("render", "polar-viewport") in log)
    assert session.stop(timeout=2.0)                  # the pass polls should_stop and gives up
    assert not session.thread.is_alive()


def test_session_reports_renderer_errors(vp):
    from polar_render.engine.errors import SceneError

    def factory(scene):
        raise SceneError("objects", "the scene has no geometry: add at least one object")
    session = vp.ViewportSession(renderer_factory=factory)
    try:
        session.update_scene(_scene_result(vp))
        session.set_view(_view())
        assert wait_for(lambda: session.error is not None)
        assert session.finished() and "no geometry" in session.error
    finally:
        assert session.stop()


def test_session_renders_a_real_scene(vp):
    """The real renderer on a small exported scene: finite Stokes images, on the session thread."""
    from polar_render.engine.scene.loader import load_scene
    import os
    from tests.conftest import REPO
    scene = load_scene(os.path.join(REPO, "examples", "demo.json"))
    scene.settings = dataclasses.replace(scene.settings, spp=1)
    session = vp.ViewportSession()
    try:
        session.update_scene(vp.SyncResult(scene, rebuild=True, restart=True, warnings=[]), target_samples=2)
        session.set_view(vp.camera_from_view(np.linalg.inv(_lookat(scene.camera)), np.diag([2.0, 2.0, -1, 0]),
                                             24, 16, True))
        assert wait_for(session.finished, timeout=120)
        assert session.error is None, session.error
        image, samples, _ = session.latest()
        assert samples == 2 and image.shape == (4, 16, 24, 3) and np.isfinite(image).all() and image[0].max() > 0
    finally:
        assert session.stop()


def _lookat(cam):
    """4×4 camera-to-world matrix of an engine Camera (Blender view convention: looks along −Z)."""
    f = np.asarray(cam.target, float) - np.asarray(cam.origin, float)
    f /= np.linalg.norm(f)
    r = np.cross(f, cam.up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = r, u, -f, cam.origin
    return m


def test_view_draw_path_hands_the_view_to_the_thread_and_only_draws(vp):
    """ViewportSession.draw (what view_draw calls) with a fake region: sets the view, never traces."""
    log, drawn, stats = [], [], []
    session = vp.ViewportSession(renderer_factory=lambda s: FakeRenderer(s, log))
    session._draw_image = lambda engine, context, image, version: drawn.append((image.shape, version))

    class Region:
        width, height = 640, 360

    class RV3D:
        view_matrix = np.eye(4)
        window_matrix = np.diag([2.0, 2.0, -1.0, 0.0])
        is_perspective = True

    class Context:
        region, region_data = Region(), RV3D()

    class Engine:
        def update_stats(self, a, b):
            stats.append(b)

    try:
        session.update_scene(_scene_result(vp), target_samples=3)
        more = session.draw(Engine(), Context())                  # first draw: the view starts sampling
        assert more and not drawn
        assert wait_for(session.finished)
        assert session.draw(Engine(), Context()) is False         # done: no more redraws needed
        assert drawn[-1][0] == (4, 180, 320, 3)                   # 640×360 region → 320×180 ≤ 65536 pixels
        assert stats[-1] == "Polar | sample 3/3"
        assert {t for k, t in log if k == "render"} == {"polar-viewport"}
        n = len(log)
        for _ in range(20):                                       # redraws of an unchanged view
            session.draw(Engine(), Context())
        assert len(log) == n
    finally:
        assert session.stop()


def test_session_holds_the_heap_settings_while_sampling_and_releases_them_when_idle(vp, monkeypatch):
    # per 1-spp render, engine.render.allocator.render_heap would hand the memory back and fault it in
    # again every sample: the session holds it over a run of samples instead
    events = []

    class Probe:
        def __enter__(self):
            events.append("hold")

        def __exit__(self, *exc):
            events.append("release")

    monkeypatch.setattr(vp, "render_heap", Probe)
    log = []
    session = converged_session(vp, log, 4)
    try:
        assert wait_for(lambda: events == ["hold", "release"])           # 4 passes, one hold; idle: released
        assert [k for k, _ in log].count("render") == 4
        session.update_scene(_scene_result(vp, restart=False, rebuild=False), target_samples=6)
        assert wait_for(lambda: session.finished() and session.latest()[1] == 6)
        assert wait_for(lambda: events == ["hold", "release"] * 2)
    finally:
        assert session.stop()
    assert events[-1] == "release"
