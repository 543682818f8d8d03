"""The "Virtual Polariser" compositor node group: what a polarising filter in front of the camera
would show, computed from the Stokes passes, live, without re-rendering.

The group evaluates row 0 of P(θ)·R(φ, δ) (engine.postprocess.filters): a linear retarder with fast
axis φ and retardance δ followed by a linear polariser at θ with extinction ratio ε
(t_min/t_max).  With δ = 0 it is a plain polariser (Malus's law); circular analysers are a
quarter-wave plate at 45° followed by a polariser at 90° (right) or 0° (left).  Angles in degrees,
from image right towards image up.  Output: I = r0·S0 + r1·S1 + r2·S2 + r3·S3 per colour channel.
"""

import math

import bpy

GROUP_NAME = "Virtual Polariser"
GROUP_VERSION = 1
TYPE_PRESETS = {   # type → (fixed polariser angle or None, retarder angle, retardance)
    "LINEAR": (None, 0.0, 0.0),
    "CIRCULAR_RIGHT": (90.0, 45.0, 90.0),
    "CIRCULAR_LEFT": (0.0, 45.0, 90.0),
    "RETARDER": (None, None, None),
}


class _Graph:
    """Tiny helper to build arithmetic out of ShaderNodeMath nodes."""

    def __init__(self, tree):
        self.tree, self.nodes, self.links = tree, tree.nodes, tree.links
        self.x = 0

    def _link(self, value, socket):
        if isinstance(value, (int, float)):
            socket.default_value = float(value)
        else:
            self.links.new(value, socket)

    def op(self, operation, a, b=None):
        node = self.nodes.new("ShaderNodeMath")
        node.operation = operation
        node.use_clamp = False
        node.location = (self.x, 0)
        self.x += 20
        self._link(a, node.inputs[0])
        if b is not None:
            self._link(b, node.inputs[1])
        return node.outputs[0]

    def add(self, a, b):
        return self.op("ADD", a, b)

    def sub(self, a, b):
        return self.op("SUBTRACT", a, b)

    def mul(self, a, b):
        return self.op("MULTIPLY", a, b)

    def scale_colour(self, colour, factor):
        node = self.nodes.new("ShaderNodeVectorMath")
        node.operation = "SCALE"
        self.links.new(colour, node.inputs[0])
        self._link(factor, node.inputs["Scale"])
        return node.outputs[0]

    def add_colour(self, a, b):
        node = self.nodes.new("ShaderNodeVectorMath")
        node.operation = "ADD"
        self.links.new(a, node.inputs[0])
        self.links.new(b, node.inputs[1])
        return node.outputs[0]


def ensure_group():
    name = f"{GROUP_NAME} v{GROUP_VERSION}"
    group = bpy.data.node_groups.get(name)
    if group is not None:
        return group
    group = bpy.data.node_groups.new(name, "CompositorNodeTree")
    iface = group.interface
    for s in ("S0", "S1", "S2", "S3"):
        iface.new_socket(s, in_out="INPUT", socket_type="NodeSocketColor")
    for sname, default, lo, hi, desc in (
            ("Angle", 0.0, -360.0, 360.0, "Polariser transmission axis (degrees from image right towards up)"),
            ("Extinction", 0.0, 0.0, 1.0, "t_min/t_max of the polariser (0 = ideal)"),
            ("Retarder Angle", 0.0, -360.0, 360.0, "Fast axis of the retarder before the polariser (degrees)"),
            ("Retardance", 0.0, -360.0, 360.0, "Retardance of the retarder in degrees (0 = no retarder)")):
        sock = iface.new_socket(sname, in_out="INPUT", socket_type="NodeSocketFloat")
        sock.default_value, sock.min_value, sock.max_value, sock.description = default, lo, hi, desc
    iface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    g = _Graph(group)
    gin = group.nodes.new("NodeGroupInput")
    gout = group.nodes.new("NodeGroupOutput")
    o = gin.outputs
    rad2 = math.pi / 90.0                                   # degrees → 2·angle in radians
    th2 = g.mul(o["Angle"], rad2)
    c2t, s2t = g.op("COSINE", th2), g.op("SINE", th2)
    ph2 = g.mul(o["Retarder Angle"], rad2)
    c, s = g.op("COSINE", ph2), g.op("SINE", ph2)
    dl = g.mul(o["Retardance"], math.pi / 180.0)
    cd, sd = g.op("COSINE", dl), g.op("SINE", dl)
    a = g.mul(g.add(1.0, o["Extinction"]), 0.5)
    b = g.mul(g.sub(1.0, o["Extinction"]), 0.5)
    one_m_cd = g.sub(1.0, cd)
    cs1 = g.mul(g.mul(c, s), one_m_cd)
    R11 = g.add(g.mul(c, c), g.mul(g.mul(s, s), cd))
    R22 = g.add(g.mul(s, s), g.mul(g.mul(c, c), cd))
    r1 = g.mul(b, g.add(g.mul(c2t, R11), g.mul(s2t, cs1)))
    r2 = g.mul(b, g.add(g.mul(c2t, cs1), g.mul(s2t, R22)))
    r3 = g.mul(b, g.mul(sd, g.sub(g.mul(s2t, c), g.mul(c2t, s))))
    total = g.scale_colour(o["S0"], a)
    total = g.add_colour(total, g.scale_colour(o["S1"], r1))
    total = g.add_colour(total, g.scale_colour(o["S2"], r2))
    total = g.add_colour(total, g.scale_colour(o["S3"], r3))
    group.links.new(total, gout.inputs["Image"])
    return group


def polariser_inputs(settings):
    """(Angle, Extinction, Retarder Angle, Retardance) for the scene's polariser settings."""
    angle, r_angle, retardance = TYPE_PRESETS[settings.polariser_type]
    return (settings.polariser_angle if angle is None else angle, settings.polariser_extinction,
            settings.retarder_angle if r_angle is None else r_angle,
            settings.retardance if retardance is None else retardance)


def sync_group_nodes(scene):
    """Copy the scene's polariser settings into every Virtual Polariser node of its compositor."""
    tree = getattr(scene, "compositing_node_group", None)
    if tree is None:
        return 0
    values = polariser_inputs(scene.polar)
    count = 0
    for node in tree.nodes:
        if node.bl_idname == "CompositorNodeGroup" and node.node_tree is not None and \
                node.node_tree.name.startswith(GROUP_NAME) and node.get("polar_follow_scene", True):
            for name, value in zip(("Angle", "Extinction", "Retarder Angle", "Retardance"), values):
                node.inputs[name].default_value = value
            count += 1
    return count


def add_to_compositor(scene):
    """Make the scene's compositor show the Virtual Polariser output of the active view layer.

    Creates the compositor tree if there is none (Render Layers → Virtual Polariser → Group Output
    and Viewer), or adds the group node next to an existing tree.  Returns the group node.
    """
    tree = getattr(scene, "compositing_node_group", None)
    if tree is None:
        tree = bpy.data.node_groups.new(f"{scene.name} Compositing", "CompositorNodeTree")
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        scene.compositing_node_group = tree
    layers = next((n for n in tree.nodes if n.bl_idname == "CompositorNodeRLayers"), None)
    if layers is None:
        layers = tree.nodes.new("CompositorNodeRLayers")
        layers.location = (-400, 0)
    node = tree.nodes.new("CompositorNodeGroup")
    node.node_tree = ensure_group()
    node.name = node.label = GROUP_NAME
    node.location = (0, 0)
    for s in ("S0", "S1", "S2", "S3"):
        if s in layers.outputs:
            tree.links.new(layers.outputs[s], node.inputs[s])
    out = next((n for n in tree.nodes if n.bl_idname == "NodeGroupOutput"), None)
    if out is None:
        out = tree.nodes.new("NodeGroupOutput")
        out.location = (300, 0)
    if out.inputs and not out.inputs[0].is_linked:
        tree.links.new(node.outputs["Image"], out.inputs[0])
    viewer = tree.nodes.new("CompositorNodeViewer")
    viewer.location = (300, -200)
    tree.links.new(node.outputs["Image"], viewer.inputs[0])
    sync_group_nodes(scene)
    return node
