"""Operators: put a Polarising BSDF into the active material."""

import bpy


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
        tree = context.material.node_tree
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


classes = (POLAR_OT_add_polarising_bsdf, POLAR_OT_add_virtual_polariser)

register, unregister = bpy.utils.register_classes_factory(classes)
