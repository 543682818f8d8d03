"""The viewport session with real Blender data.  view_update/view_draw are never called headless
(the gpu module needs a display), so the depsgraph's real updates are fed to the session's sync
logic from a depsgraph_update_post handler, and the session renders the exported scene."""

import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import add_plane, add_sphere, brewster_camera, empty_scene, load_addon, \
    polar_material, white_world  # noqa: E402


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def test_real_depsgraph_updates_re_export_only_what_changed(addon):
    from polar_render.polar_addon import viewport as vp
    from polar_render.polar_addon.render_engine import engine_settings
    scene = empty_scene()
    white_world(scene)
    brewster_camera(scene)
    plane = add_plane(4.0, polar_material("Floor", "LAMBERT"))
    ball = add_sphere(0.5, (0, 0, 0.5), polar_material("Ball", "DIELECTRIC"))
    bpy.context.view_layer.update()

    export = vp.SceneWalk()
    results = []

    def on_update(_scene, depsgraph):
        changes = vp.classify(vp.depsgraph_updates(depsgraph))
        results.append((changes, export.sync(depsgraph, changes, engine_settings(depsgraph.scene, preview=True)),
                        dict(export.counts)))

    first = export.sync(bpy.context.evaluated_depsgraph_get(), None, engine_settings(scene, preview=True))
    assert first.rebuild and export.counts["arrays"] == 2 and export.counts["materials"] == 2
    bpy.app.handlers.depsgraph_update_post.append(on_update)
    try:
        ball.location.x = 0.7                                      # move one object
        bpy.context.view_layer.update()
        changes, moved, counts = results[-1]
        assert ball.name in changes.objects_transform
        assert counts["arrays"] == 0 and counts["placed"] == 1 and counts["materials"] == 0
        assert moved.rebuild and moved.restart
        ball_mesh = next(m for m in moved.scene.meshes if m.name.startswith(ball.name))
        assert ball_mesh.vertices[:, 0].mean() == pytest.approx(0.7, abs=1e-3)

        node = bpy.data.materials["Floor"].node_tree.nodes["Polarising BSDF"]   # edit one material
        node.inputs[0].default_value = node.inputs[0].default_value
        bpy.data.materials["Floor"].diffuse_color = (0.2, 0.3, 0.4, 1.0)
        bpy.context.view_layer.update()
        changes, shaded, counts = results[-1]
        assert "Floor" in changes.materials
        assert counts["arrays"] == 0 and counts["placed"] == 0 and counts["materials"] == 1
        assert shaded.restart and not shaded.rebuild

        plane.data.vertices[0].co.z += 0.1                           # edit one mesh
        plane.data.update()
        bpy.context.view_layer.update()
        changes, edited, counts = results[-1]
        assert counts["arrays"] == 1 and counts["placed"] == 1 and edited.rebuild
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(on_update)

    # The session renders what the sync produced, on its own thread.
    session = vp.ViewportSession()
    try:
        session.update_scene(edited, target_samples=2)
        view = np.linalg.inv(np.array(scene.camera.matrix_world))
        session.set_view(vp.camera_from_view(view, np.diag([2.0, 2.0, -1.0, 0.0]), 24, 18, True))
        end = time.monotonic() + 120
        while not session.finished() and time.monotonic() < end:
            time.sleep(0.05)
        assert session.error is None, session.error
        image, samples, _ = session.latest()
        assert samples == 2 and image.shape == (4, 18, 24, 3) and np.isfinite(image).all() and image[0].max() > 0
    finally:
        assert session.stop()


def test_ui_names_cover_every_exported_field(addon):
    import dataclasses
    from polar_render.engine.scene.description import Camera, RenderSettings
    from polar_render.polar_addon.ui_names import RENDER_SETTINGS, UI_NAMES
    for cls, prefix in ((Camera, "camera"), (RenderSettings, "render")):
        missing = [f.name for f in dataclasses.fields(cls) if f"{prefix}.{f.name}" not in UI_NAMES]
        assert not missing, f"{prefix} fields without a UI label: {missing}"
    rna = bpy.context.scene.polar.bl_rna.properties
    for field, (prop, label) in RENDER_SETTINGS.items():
        if prop is not None:
            assert prop in rna, prop
            assert rna[prop].name in label, (field, rna[prop].name, label)   # the label Blender shows
    assert UI_NAMES["camera.width"] == "Output Properties ▸ Format ▸ Resolution X (× %)"
    assert UI_NAMES["render.batch_rays"].endswith("Batch Size")


def test_engine_field_names_become_ui_labels_in_messages(addon):
    from polar_render.engine.errors import SceneError
    from polar_render.polar_addon.ui_names import ui_message
    e = SceneError("camera.width", "a 90000×90000 render needs about 600 GiB: use at most ~1,000 pixels "
                                   "(or a smaller render.batch_rays)")
    msg = ui_message(e)
    assert msg.startswith("Output Properties ▸ Format ▸ Resolution X (× %): a 90000")
    assert "“Render Properties ▸ Performance ▸ Batch Size”" in msg and "render.batch_rays" not in msg
    assert ui_message(SceneError("material 'Floor'.Polarising BSDF.k", "must be finite")) == \
        "material 'Floor'.Polarising BSDF.k: must be finite"                   # already Blender names
    # A real Blender error names the UI setting.
    scene = empty_scene()
    brewster_camera(scene)
    add_plane(10)
    scene.render.resolution_x = scene.render.resolution_y = 90000        # too large a render
    with pytest.raises(RuntimeError, match=r"Output Properties ▸ Format ▸ Resolution X"):
        bpy.ops.render.render(write_still=False)


def test_geometry_unchanged_compares_the_evaluated_mesh(addon):
    """The check behind the viewport's unconfirmed geometry flags (Blender 5.3's material edits): true
    for the geometry that was read, with or without modifiers; false once positions or triangles differ."""
    from polar_render.polar_addon.export.geometry import geometry_arrays, geometry_unchanged
    empty_scene()
    sphere = add_sphere(0.5, (0, 0, 0.5))
    sphere.modifiers.new("Subdivision", "SUBSURF").levels = 1

    def evaluated():
        return sphere.evaluated_get(bpy.context.evaluated_depsgraph_get())

    arrays = geometry_arrays(evaluated())
    assert len(arrays[0]) > len(sphere.data.vertices)                  # the subdivided mesh was read
    assert geometry_unchanged(evaluated(), arrays)
    sphere.modifiers["Subdivision"].levels = 2                         # a modifier edit
    assert not geometry_unchanged(evaluated(), arrays)
    sphere.modifiers["Subdivision"].levels = 1
    assert geometry_unchanged(evaluated(), arrays)
    sphere.data.vertices[0].co.z += 0.01                               # same counts, moved vertex
    sphere.data.update()
    assert not geometry_unchanged(evaluated(), arrays)
    assert not geometry_unchanged(evaluated(), None)
