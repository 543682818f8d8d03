"""Operators: put a Polarising BSDF into the active material, add the compositor groups, estimate the cost,
the LCD screen preset of a light or an emission."""

import dataclasses

import bpy

from . import compat


class POLAR_OT_add_polarising_bsdf(bpy.types.Operator):
    """Replace the active material's surface shader with a Polarising BSDF node"""

    bl_idname = "polar.add_polarising_bsdf"
    bl_label = "Use Polarising BSDF"
    bl_options = {"REGISTER", "UNDO"}

    model: bpy.props.StringProperty(default="LAMBERT")

    @classmethod
    def poll(cls, context):
        return getattr(context, "material", None) is not None

    def execute(self, context):
        from .nodes.bsdf import link_to_surface, new_polarising_bsdf
        tree = compat.ensure_node_tree(context.material)
        link_to_surface(tree, new_polarising_bsdf(tree, self.model))
        return {"FINISHED"}


class POLAR_OT_add_virtual_polariser(bpy.types.Operator):
    """Add the Virtual Polariser node group to the compositor, fed by the Stokes passes and following
    the scene's polariser settings (angle, type) live"""

    bl_idname = "polar.add_virtual_polariser"
    bl_label = "Add Virtual Polariser to Compositor"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from .compositor import add_to_compositor
        for view_layer in context.scene.view_layers:
            for name in ("s0", "s1", "s2", "s3"):
                setattr(view_layer.polar, f"use_pass_{name}", True)
        add_to_compositor(context.scene)
        self.report({"INFO"}, "Virtual Polariser added to the compositor")
        return {"FINISHED"}


class POLAR_OT_add_polar_denoise(bpy.types.Operator):
    """Add the Polar Denoise node group to the compositor: Blender's Denoise node on the six analyser
    images (S0 ± S_k)/2, guided by the Denoising Albedo / Normal passes (turned on here)"""

    bl_idname = "polar.add_polar_denoise"
    bl_label = "Add Polar Denoise to Compositor"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from .compositor import add_denoise_to_compositor
        for view_layer in context.scene.view_layers:
            for name in ("s0", "s1", "s2", "s3", "denoising_albedo", "denoising_normal"):
                setattr(view_layer.polar, f"use_pass_{name}", True)
        add_denoise_to_compositor(context.scene)
        self.report({"INFO"}, "Polar Denoise added to the compositor")
        return {"FINISHED"}


class POLAR_OT_estimate_cost(bpy.types.Operator):
    """Render a short pilot and predict the samples per pixel and the time the current Noise Threshold
    needs (adaptive and uniform sampling)"""

    bl_idname = "polar.estimate_cost"
    bl_label = "Estimate"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        return context.scene is not None and context.scene.camera is not None

    def execute(self, context):
        from ..engine.errors import SceneError
        from ..engine.render.estimate import pilot_render, predict, round_overhead
        from ..engine.render.renderer import Renderer
        from .export.scene import export_scene
        from .properties import NOISE_QUANTITY_TO_ENGINE
        from .render_engine import engine_settings

        scene = context.scene
        p = scene.polar
        r = scene.render
        W = max(1, int(r.resolution_x * r.resolution_percentage / 100))
        H = max(1, int(r.resolution_y * r.resolution_percentage / 100))
        settings = engine_settings(scene)
        quantity = NOISE_QUANTITY_TO_ENGINE[p.noise_quantity]
        min_spp = max(2, min(p.adaptive_min_samples, p.samples))
        try:
            engine_scene, _ = export_scene(context.evaluated_depsgraph_get(), scene.camera, W, H, settings)
            renderer = Renderer(engine_scene)
            pilot, sps = pilot_render(renderer, settings, max(2, min(16, min_spp)), quantity)
            probe = dataclasses.replace(settings, spp=max(p.samples, min_spp))
            per_round = round_overhead(renderer, probe, pilot, sps, min_spp)     # the rounds' fixed time
        except SceneError as e:
            self.report({"ERROR"}, f"Polar: {e}")
            return {"CANCELLED"}
        pred = predict(pilot.film, pilot.halves, quantity, p.adaptive_threshold, min_spp, max(p.samples, min_spp),
                       sps, round_seconds=per_round, sampler=settings.sampler)
        p.estimate_report = (f"Adaptive: median {pred.median:.0f}, p95 {pred.p95:.0f} spp, "
                             f"{pred.adaptive_seconds:.1f} s\n"
                             f"Uniform: {pred.uniform_spp} spp, {pred.uniform_seconds:.1f} s"
                             + (f"\n{100 * pred.capped:.0f} % of pixels reach Max Samples first"
                                if pred.capped >= 0.005 else ""))
        self.report({"INFO"}, f"Polar estimate: {pred.describe()}")
        return {"FINISHED"}


class POLAR_OT_lcd_screen_preset(bpy.types.Operator):
    """Make this light, or this material's emission, an LCD screen: fully linearly polarised at 45° from its X
    axis (the front polariser of twisted-nematic panels; docs/guide/polariser-and-passes.md says why)"""

    bl_idname = "polar.lcd_screen_preset"
    bl_label = "LCD Screen"
    bl_options = {"REGISTER", "UNDO"}

    target: bpy.props.EnumProperty(items=[("LIGHT", "Light", ""), ("MATERIAL", "Material", "")], default="LIGHT")

    @classmethod
    def poll(cls, context):
        return getattr(context, "light", None) is not None or getattr(context, "material", None) is not None

    def execute(self, context):
        import math

        from ..engine.polarisation.sources import LCD_ANGLE_DEG
        owner = context.light if self.target == "LIGHT" else context.material
        if owner is None:
            self.report({"ERROR"}, f"Polar: no active {self.target.lower()}")
            return {"CANCELLED"}
        settings = owner.polar
        settings.polarisation, settings.degree, settings.angle = "LINEAR", 1.0, math.radians(LCD_ANGLE_DEG)
        return {"FINISHED"}


classes = (POLAR_OT_add_polarising_bsdf, POLAR_OT_add_virtual_polariser, POLAR_OT_add_polar_denoise,
           POLAR_OT_estimate_cost, POLAR_OT_lcd_screen_preset)

register, unregister = bpy.utils.register_classes_factory(classes)
