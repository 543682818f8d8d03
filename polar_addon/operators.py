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
        mat = context.material
        tree = mat.node_tree
        output = tree.get_output_node("ALL") or tree.nodes.new("ShaderNodeOutputMaterial")
        node = tree.nodes.new("PolarShaderNodeBSDF")
        node.model = self.model
        node.location = (output.location.x - 300, output.location.y)
        tree.links.new(node.outputs[0], output.inputs["Surface"])
        return {"FINISHED"}


classes = (POLAR_OT_add_polarising_bsdf,)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
