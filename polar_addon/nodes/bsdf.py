"""The "Polarising BSDF" shader node (ShaderNodeCustomGroup in the normal material node tree).

Each model uses one shared, versioned internal node group (".PolarBSDF_<MODEL>_v1") whose inputs
are exactly that model's parameters; switching the model swaps the group, so the node always shows
exactly the selected model's parameters.  Socket values are stored per node, the model and presets
as enum properties with stable numbers.  Inside the group a Principled BSDF gives Cycles and EEVEE
(material preview) a plausible look; Polar itself reads the node's model and socket values.
"""

import bpy
from bpy.props import EnumProperty

from .. import compat
from .models import DIELECTRIC_PRESETS, METAL_ITEMS, MODEL_ITEMS, MODEL_SOCKETS, SHADOWING_ITEMS, WW_FORM_ITEMS

GROUP_VERSION = 1
SOCKET_TYPES = {"FLOAT": "NodeSocketFloat", "COLOR": "NodeSocketColor", "SHADER": "NodeSocketShader"}


def group_name(model: str) -> str:
    return f".PolarBSDF_{model}_v{GROUP_VERSION}"


def _preview_look(model, principled, links, group_in):
    """Approximate the model with Principled inputs so other engines show something sensible."""
    p = principled.inputs
    if model == "LAMBERT":
        links.new(group_in.outputs["Albedo"], p["Base Color"])
        p["Roughness"].default_value = 1.0
        p["Specular IOR Level"].default_value = 0.0
    elif model in ("CONDUCTOR", "TORRANCE_SPARROW", "HTSG"):
        p["Metallic"].default_value = 1.0
        p["Base Color"].default_value = (0.9, 0.9, 0.9, 1.0)
        p["Roughness"].default_value = 0.05 if model == "CONDUCTOR" else 0.35
    elif model in ("DIELECTRIC", "THIN_DIELECTRIC"):
        p["Transmission Weight"].default_value = 1.0
        p["Roughness"].default_value = 0.0
        links.new(group_in.outputs["IOR"], p["IOR"])
    elif model == "ROUGH_DIELECTRIC":
        p["Transmission Weight"].default_value = 1.0
        links.new(group_in.outputs["IOR"], p["IOR"])
        links.new(group_in.outputs["Roughness"], p["Roughness"])
    elif model == "BLACK_GLASS":
        p["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        p["Roughness"].default_value = 0.0
        links.new(group_in.outputs["IOR"], p["IOR"])
    elif model == "WEIDLICH_WILKIE":
        p["Coat Weight"].default_value = 1.0
        links.new(group_in.outputs["Coat IOR"], p["Coat IOR"])


def _new_input(group, sname, stype, default, lo, hi, desc):
    sock = group.interface.new_socket(sname, in_out="INPUT", socket_type=SOCKET_TYPES[stype])
    sock.description = desc
    if stype == "FLOAT":
        sock.default_value, sock.min_value, sock.max_value = default, lo, hi
    elif stype == "COLOR":
        sock.default_value = (*default, 1.0)


def _add_missing_inputs(group, model: str):
    """Inputs declared after a saved file's group was made are appended (existing ones never change)."""
    have = {item.name for item in group.interface.items_tree
            if item.item_type == "SOCKET" and item.in_out == "INPUT"}
    for spec in MODEL_SOCKETS[model]:
        if spec[0] not in have:
            _new_input(group, *spec)


def ensure_group(model: str) -> bpy.types.ShaderNodeTree:
    name = group_name(model)
    group = bpy.data.node_groups.get(name)
    if group is not None:
        _add_missing_inputs(group, model)
        return group
    group = bpy.data.node_groups.new(name, "ShaderNodeTree")
    for spec in MODEL_SOCKETS[model]:
        _new_input(group, *spec)
    group.interface.new_socket("BSDF", in_out="OUTPUT", socket_type="NodeSocketShader")
    nodes, links = group.nodes, group.links
    group_in = nodes.new("NodeGroupInput")
    group_out = nodes.new("NodeGroupOutput")
    principled = nodes.new("ShaderNodeBsdfPrincipled")
    group_in.location, principled.location, group_out.location = (-400, 0), (0, 0), (300, 0)
    _preview_look(model, principled, links, group_in)
    links.new(principled.outputs["BSDF"], group_out.inputs["BSDF"])
    return group


def _model_changed(self, context):
    # Swapping the group rebuilds the sockets, which drops their links: remember and restore them
    # (inputs by name, where the new model has an input of that name).
    tree = self.id_data
    out_links = [link.to_socket for link in self.outputs[0].links] if self.outputs else []
    in_links = {s.name: s.links[0].from_socket for s in self.inputs if s.is_linked}
    self.node_tree = ensure_group(self.model)
    for to_socket in out_links:
        tree.links.new(self.outputs[0], to_socket)
    for name, from_socket in in_links.items():
        if name in self.inputs:
            tree.links.new(from_socket, self.inputs[name])


def _metal_changed(self, context):
    pass  # read at export time; the n/k sockets stay as the user left them


class PolarShaderNodeBSDF(bpy.types.ShaderNodeCustomGroup):
    """Polarising BSDF: a material model that tracks the full polarisation state of light."""

    bl_idname = "PolarShaderNodeBSDF"
    bl_label = "Polarising BSDF"
    bl_width_default = 240

    model: EnumProperty(name="Model", items=MODEL_ITEMS, default="LAMBERT", update=_model_changed)
    metal: EnumProperty(name="Metal", items=METAL_ITEMS, default="CUSTOM", update=_metal_changed,
                        description="Measured metal (spectral n, k) instead of the n and k inputs")
    dielectric_preset: EnumProperty(name="Preset", items=[i[:4] for i in DIELECTRIC_PRESETS], default="CUSTOM",
                                    description="Common dielectric instead of the IOR input")
    shadowing: EnumProperty(name="Shadowing", items=SHADOWING_ITEMS, default="TS")
    ww_form: EnumProperty(name="Form", items=WW_FORM_ITEMS, default="ENERGY")

    @classmethod
    def poll(cls, ntree):
        return ntree.bl_idname == "ShaderNodeTree"

    def init(self, context):
        self.node_tree = ensure_group(self.model)

    def copy(self, node):
        self.node_tree = node.node_tree   # groups are shared per model

    def draw_buttons(self, context, layout):
        layout.prop(self, "model", text="")
        if self.model in ("CONDUCTOR", "TORRANCE_SPARROW", "HTSG"):
            layout.prop(self, "metal")
        if self.model in ("DIELECTRIC", "BLACK_GLASS", "ROUGH_DIELECTRIC", "THIN_DIELECTRIC"):
            layout.prop(self, "dielectric_preset")
        if self.model == "TORRANCE_SPARROW":
            layout.prop(self, "shadowing")
        if self.model == "WEIDLICH_WILKIE":
            layout.prop(self, "ww_form")

    def draw_label(self):
        return dict((i[0], i[1]) for i in MODEL_ITEMS).get(self.model, "Polarising BSDF")


#: Node properties (menus) that ``new_polarising_bsdf`` sets by name; other settings are input sockets.
NODE_SETTINGS = ("metal", "dielectric_preset", "shadowing", "ww_form")


def new_polarising_bsdf(tree, model: str, **settings):
    """A Polarising BSDF node of ``model`` in the shader node ``tree``.

    ``settings`` are the node's menus (``metal``, ``dielectric_preset``, ``shadowing``, ``ww_form``)
    or input socket values by socket name, e.g. ``IOR=1.5`` or ``Albedo=(0.7, 0.05, 0.04, 1.0)``.
    """
    node = tree.nodes.new(PolarShaderNodeBSDF.bl_idname)
    node.model = model
    for key, value in settings.items():
        if key in NODE_SETTINGS:
            setattr(node, key, value)
        else:
            node.inputs[key].default_value = value
    return node


def link_to_surface(tree, node):
    """Plug ``node`` into the material output's Surface (creating the output if there is none)."""
    output = tree.get_output_node("ALL") or tree.nodes.new("ShaderNodeOutputMaterial")
    node.location = (output.location.x - 300, output.location.y)
    tree.links.new(node.outputs[0], output.inputs["Surface"])


def polarising_material(name: str, model: str, **settings):
    """(material, node): a new material whose surface is a Polarising BSDF (scripts, tests, demos)."""
    mat = bpy.data.materials.new(name)
    tree = compat.ensure_node_tree(mat)
    node = new_polarising_bsdf(tree, model, **settings)
    link_to_surface(tree, node)
    return mat, node


def draw_add_menu(self, context):
    if context.scene.render.engine == "POLAR":
        self.layout.operator("node.add_node", text="Polarising BSDF").type = "PolarShaderNodeBSDF"


def register():
    bpy.utils.register_class(PolarShaderNodeBSDF)
    menu = getattr(bpy.types, "NODE_MT_category_shader_shader", None)
    if menu is not None:
        menu.append(draw_add_menu)


def unregister():
    menu = getattr(bpy.types, "NODE_MT_category_shader_shader", None)
    if menu is not None:
        menu.remove(draw_add_menu)
    bpy.utils.unregister_class(PolarShaderNodeBSDF)
