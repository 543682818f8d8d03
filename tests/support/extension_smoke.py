"""The extension smoke set, run by one Blender's Python (``bpy``) after the zip is installed:

    BLENDER_USER_RESOURCES=<user folder> <python with bpy> tests/support/extension_smoke.py OUT_DIR ANGLE

Enables the installed extension, renders a small Principled + Polarising BSDF scene (every pass
into ``OUT_DIR/render.exr``), adds the Virtual Polariser at ANGLE degrees (``polariser.exr``) and the
Polar Denoise group (``denoise.exr``) with their operators and renders each, and feeds a material
edit, a mesh edit and a modifier edit through the viewport's incremental export.  Prints one line
``POLAR_SMOKE=<json>``: {stage: "ok" or the error}, what the viewport re-exported per edit, the
Blender and Python versions.  tests/support/extension_run.py starts it and judges the EXR files; this
script only reports, so a failing stage never hides the next.
"""

import json
import math
import os
import sys
import traceback

import bpy

EXTENSION = "bl_ext.user_default.polar_render"
WIDTH, HEIGHT, SAMPLES = 16, 12, 2


def stage(report, name):
    """Decorator: run the function as stage ``name``; record "ok" or the error's last lines."""
    def run(fn):
        try:
            fn()
            report[name] = "ok"
        except Exception as e:          # noqa: BLE001 — reported, the next stages still run
            report[name] = f"{type(e).__name__}: {e}"
            traceback.print_exc()
        return fn
    return run


def build_scene(ext):
    compat = sys.modules[ext.__name__ + ".polar_addon.compat"]
    bsdf = sys.modules[ext.__name__ + ".polar_addon.nodes.bsdf"]
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "POLAR"
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.render.resolution_percentage = 100
    scene.polar.samples = SAMPLES
    scene.polar.seed = 7
    compat.set_multilayer_exr(scene.render.image_settings)
    bpy.ops.mesh.primitive_plane_add(size=40)
    floor, _ = bsdf.polarising_material("Floor", "BLACK_GLASS")
    bpy.context.object.data.materials.append(floor)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0.0, 0.0, 1.0), segments=24, ring_count=12)
    ball = bpy.data.materials.new("Ball")
    principled = compat.ensure_node_tree(ball).nodes["Principled BSDF"]
    principled.inputs["Base Color"].default_value = (0.8, 0.3, 0.1, 1.0)
    principled.inputs["Roughness"].default_value = 0.4
    bpy.context.object.data.materials.append(ball)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    th = math.atan(1.5)                       # the floor seen near Brewster's angle
    cam.location, cam.rotation_euler = (0.0, -12 * math.sin(th), 12 * math.cos(th)), (th, 0.0, 0.0)
    cam.data.lens = 60
    scene.camera = cam
    world = bpy.data.worlds.new("World")
    background = compat.ensure_node_tree(world).nodes["Background"]
    background.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    scene.world = world
    return scene, compat


def render(scene, out_dir, name):
    scene.render.filepath = os.path.join(out_dir, name)
    bpy.ops.render.render(write_still=True)
    if not os.path.exists(scene.render.filepath + ".exr"):
        raise RuntimeError(f"the render wrote no {name}.exr")


def viewport_edits(ext, scene):
    """What the viewport's incremental export re-reads for a material, a mesh and a modifier edit."""
    vp = sys.modules[ext.__name__ + ".polar_addon.viewport"]
    engine_settings = sys.modules[ext.__name__ + ".polar_addon.render_engine"].engine_settings
    export = vp.SceneWalk()
    counts = []

    def on_update(_scene, depsgraph):
        export.sync(depsgraph, vp.classify(vp.depsgraph_updates(depsgraph)),
                    engine_settings(depsgraph.scene, preview=True))
        counts[-1].update(arrays=counts[-1].get("arrays", 0) + export.counts["arrays"],
                          materials=counts[-1].get("materials", 0) + export.counts["materials"])

    bpy.context.view_layer.update()
    export.sync(bpy.context.evaluated_depsgraph_get(), None, engine_settings(scene, preview=True))
    sphere = next(o for o in scene.objects if o.type == "MESH" and o.data.materials[0].name == "Ball")
    edits = {
        "material": lambda: setattr(bpy.data.materials["Ball"].node_tree.nodes["Principled BSDF"]
                                    .inputs["Roughness"], "default_value", 0.5),
        "mesh": lambda: (sphere.data.vertices[0].co.__setitem__(2, 1.5), sphere.data.update()),
        "modifier": lambda: sphere.modifiers.new("Subdivision", "SUBSURF"),
    }
    result = {}
    bpy.app.handlers.depsgraph_update_post.append(on_update)
    try:
        for name, edit in edits.items():
            counts.append({})
            edit()
            bpy.context.view_layer.update()
            result[name] = counts[-1]
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(on_update)
    return result


def normal_map_convention(ext):
    """How the exporter reads a Normal Map set to DirectX (Blender 5.1 on; "absent" before): the engine
    material's green-channel direction, "directx" or "opengl"."""
    compat = sys.modules[ext.__name__ + ".polar_addon.compat"]
    materials = sys.modules[ext.__name__ + ".polar_addon.export.materials"]
    mat = bpy.data.materials.new("Normal mapped")
    tree = compat.ensure_node_tree(mat)
    image = bpy.data.images.new("flat normal", 4, 4, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"     # first: changing it regenerates a generated image's pixels
    image.pixels.foreach_set([0.5, 0.5, 1.0, 1.0] * 16)
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = image
    normal = tree.nodes.new("ShaderNodeNormalMap")
    if not hasattr(normal, "convention"):
        return "absent"
    normal.convention = "DIRECTX"
    tree.links.new(texture.outputs["Color"], normal.inputs["Color"])
    tree.links.new(normal.outputs["Normal"], tree.nodes["Principled BSDF"].inputs["Normal"])
    bsdf, _ = materials.export_material(mat, [])

    def mapped(m):          # the ShadingNormal wrappers (a Principled is mapped closure by closure)
        if hasattr(m, "normal_green_down"):
            yield m
        for part in getattr(m, "components", ()):
            yield from mapped(part)
    maps = list(mapped(bsdf))
    if not maps:
        return "unmapped"
    return "directx" if all(m.normal_green_down for m in maps) else "opengl"


def polarised_sources(ext):
    """Light ▸ Polarisation with the LCD preset and World ▸ Sky Polarisation on every Sky Texture type of this
    Blender, through the extension's exporters: {"light": angle, "skies": {type: (model, sun)}}."""
    lights = sys.modules[ext.__name__ + ".polar_addon.export.lights"]
    world_export = sys.modules[ext.__name__ + ".polar_addon.export.world"]
    compat = sys.modules[ext.__name__ + ".polar_addon.compat"]
    data = bpy.data.lights.new("Screen", "AREA")
    obj = bpy.data.objects.new("Screen", data)
    bpy.context.scene.collection.objects.link(obj)
    with bpy.context.temp_override(light=data):
        if bpy.ops.polar.lcd_screen_preset(target="LIGHT") != {"FINISHED"}:
            raise RuntimeError("the LCD Screen preset did not finish")
    mesh = lights.export_light(obj, obj.matrix_world, [])
    out = {"light": [mesh.emission_polarisation.kind, round(mesh.emission_polarisation.angle_deg, 3)], "skies": {}}
    world = bpy.data.worlds.new("Sky")
    tree = compat.ensure_node_tree(world)
    sky = tree.nodes.new("ShaderNodeTexSky")
    tree.links.new(sky.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    for kind in [item.identifier for item in sky.bl_rna.properties["sky_type"].enum_items]:
        sky.sky_type = kind
        light = world_export.export_world(world, [], bake_width=32, bake_samples=1)
        out["skies"][kind] = [light.sky.model, [round(c, 6) for c in light.sky.sun_direction]]
    return out


def main(out_dir, angle):
    import addon_utils
    os.makedirs(out_dir, exist_ok=True)
    report = {"blender": bpy.app.version_string, "python": "{}.{}".format(*sys.version_info[:2])}
    state = {}

    @stage(report, "enable")
    def _enable():
        addon_utils.enable(EXTENSION, default_set=True)
        if EXTENSION not in sys.modules:
            raise RuntimeError("the extension did not enable (see Blender's messages above)")
        bpy.context.scene.render.engine = "POLAR"        # TypeError if the engine is not registered
        state["ext"] = sys.modules[EXTENSION]
        state["backend"] = sys.modules[EXTENSION + ".engine.kernels"].BACKEND

    if "ext" not in state:
        return report
    report["backend"] = state["backend"]

    @stage(report, "render")
    def _render():
        scene, compat = build_scene(state["ext"])
        state["scene"], state["compat"] = scene, compat
        render(scene, out_dir, "render")

    if "scene" not in state:
        return report
    scene, compat = state["scene"], state["compat"]

    @stage(report, "processes")
    def _processes():       # the same render on the worker processes (engine.render.processes): judged identical
        processes = sys.modules[EXTENSION + ".engine.render.processes"]
        scene.polar.parallel = "PROCESSES"
        try:
            render(scene, out_dir, "processes")
        finally:
            scene.polar.parallel = "AUTO"
        if processes.pool_running() < 1:
            raise RuntimeError("no worker process ran")
        state["pids"] = [w.proc.pid for w in processes.pool().workers]

    @stage(report, "polariser")
    def _polariser():
        scene.polar.polariser_type = "LINEAR"
        scene.polar.polariser_angle = angle
        if bpy.ops.polar.add_virtual_polariser() != {"FINISHED"}:
            raise RuntimeError("the Virtual Polariser operator did not finish")
        render(scene, out_dir, "polariser")

    @stage(report, "denoise")
    def _denoise():
        tree = compat.compositor_tree(scene)
        for node in [n for n in tree.nodes if n.bl_idname in ("CompositorNodeGroup", "CompositorNodeViewer")]:
            tree.nodes.remove(node)          # the polariser's group: the denoised S0 becomes the image
        if bpy.ops.polar.add_polar_denoise() != {"FINISHED"}:
            raise RuntimeError("the Polar Denoise operator did not finish")
        render(scene, out_dir, "denoise")

    @stage(report, "viewport")
    def _viewport():
        report["viewport_counts"] = viewport_edits(state["ext"], scene)

    @stage(report, "normal_map")
    def _normal_map():
        report["normal_map_convention"] = normal_map_convention(state["ext"])

    @stage(report, "sources")
    def _sources():
        report["polarised_sources"] = polarised_sources(state["ext"])

    addon_utils.disable(EXTENSION, default_set=False)
    if state.get("pids"):       # unregister ends the worker processes
        alive = [p for p in state["pids"] if os.path.exists(f"/proc/{p}") and "Z" not in _state_of(p)]
        report["processes_after_disable"] = len(alive) if sys.platform.startswith("linux") else 0
    return report


def _state_of(pid) -> str:
    """A Linux process's state letter ("Z": ended, not yet reaped)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "Z"


if __name__ == "__main__":
    result = main(sys.argv[-2], float(sys.argv[-1]))
    print("POLAR_SMOKE=" + json.dumps(result), flush=True)
