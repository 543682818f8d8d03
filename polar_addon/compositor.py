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
import numpy as np

from . import compat

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
    tree = compat.compositor_tree(scene)
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


def _compositor_with_render_layers(scene):
    """(the scene's compositor node tree, its Render Layers node), creating either if missing."""
    tree = compat.compositor_tree(scene, create=True)
    layers = next((n for n in tree.nodes if n.bl_idname == "CompositorNodeRLayers"), None)
    if layers is None:
        layers = tree.nodes.new("CompositorNodeRLayers")
        layers.location = (-400, 0)
    return tree, layers


def _show(tree, socket):
    """Make ``socket`` the compositor's final image unless the user already shows something there:
    the output is free, or fed by Render Layers' Image through reroutes only (the tree Blender makes
    before 5.0)."""
    out = compat.compositor_output(tree)
    if not out.inputs:
        return
    links = out.inputs[0].links
    while links and links[0].from_node.bl_idname == "NodeReroute":
        links = links[0].from_node.inputs[0].links
    if not links or (links[0].from_node.bl_idname == "CompositorNodeRLayers"
                     and links[0].from_socket.identifier == "Image"):
        tree.links.new(socket, out.inputs[0])


def add_to_compositor(scene):
    """Make the scene's compositor show the Virtual Polariser output of the active view layer.

    Creates the compositor tree if there is none (Render Layers → Virtual Polariser → the final
    output and a Viewer), or adds the group node next to an existing tree.  Returns the group node.
    """
    tree, layers = _compositor_with_render_layers(scene)
    node = tree.nodes.new("CompositorNodeGroup")
    node.node_tree = ensure_group()
    node.name = node.label = GROUP_NAME
    node.location = (0, 0)
    for s in ("S0", "S1", "S2", "S3"):
        if s in layers.outputs:
            tree.links.new(layers.outputs[s], node.inputs[s])
    _show(tree, node.outputs["Image"])
    viewer = tree.nodes.new("CompositorNodeViewer")
    viewer.location = (300, -200)
    tree.links.new(node.outputs["Image"], viewer.inputs[0])
    sync_group_nodes(scene)
    return node


# ----------------------------------------------------------------------------- denoising

DENOISE_GROUP_NAME = "Polar Denoise"
DENOISE_GROUP_VERSION = 1


def _vector_op(g, operation, a, b=None, scale=None):
    """A ShaderNodeVectorMath node (per colour channel for colour sockets); constants as 3-tuples."""
    node = g.nodes.new("ShaderNodeVectorMath")
    node.operation = operation
    node.location = (g.x, -300)
    g.x += 20
    for value, socket in ((a, node.inputs[0]), (b, node.inputs[1])):
        if value is None:
            continue
        if isinstance(value, tuple):
            socket.default_value = value
        else:
            g.links.new(value, socket)
    if scale is not None:
        g._link(scale, node.inputs["Scale"])
    return node.outputs[0]


def ensure_denoise_group(denoiser="CompositorNodeDenoise"):
    """The "Polar Denoise" group: denoise a Stokes image with Blender's Denoise node (OIDN).

    S1…S3 are signed, the denoiser wants non-negative images: it denoises the six analyser images
    (S0 ± S_k)/2, k = 1, 2, 3 (what ideal linear polarisers at 0°/90°, 45°/135° and right/left
    circular analysers transmit), each with the same Albedo and Normal guides, and recombines
    them: S0 = mean of the three sums, S_k = difference of the pair.  The independent denoising
    of each pair can leave |S| = √(S1² + S2² + S3²) above S0 (DoP > 1): with "Clamp DoP" = 1 the
    group scales S1…S3 down to |S| = S0 where that happens (per colour channel); 0 leaves them.
    ``denoiser``: the node type of the six denoisers (tests use a pass-through to check the
    arithmetic).
    """
    name = f"{DENOISE_GROUP_NAME} v{DENOISE_GROUP_VERSION}"
    if denoiser != "CompositorNodeDenoise":
        name += f" ({denoiser})"
    group = bpy.data.node_groups.get(name)
    if group is not None:
        return group
    group = bpy.data.node_groups.new(name, "CompositorNodeTree")
    iface = group.interface
    for s in ("S0", "S1", "S2", "S3"):
        iface.new_socket(s, in_out="INPUT", socket_type="NodeSocketColor")
    iface.new_socket("Albedo", in_out="INPUT", socket_type="NodeSocketColor")
    iface.new_socket("Normal", in_out="INPUT", socket_type="NodeSocketVector")
    clamp = iface.new_socket("Clamp DoP", in_out="INPUT", socket_type="NodeSocketFloat")
    clamp.default_value, clamp.min_value, clamp.max_value = 1.0, 0.0, 1.0
    clamp.description = "1: scale S1…S3 so that DoP ≤ 1 per colour channel after denoising; 0: leave them"
    for s in ("S0", "S1", "S2", "S3"):
        iface.new_socket(s, in_out="OUTPUT", socket_type="NodeSocketColor")
    g = _Graph(group)
    gin = group.nodes.new("NodeGroupInput")
    gout = group.nodes.new("NodeGroupOutput")
    o = gin.outputs

    def denoised(image):
        if denoiser != "CompositorNodeDenoise":
            return image                           # pass-through: the recombination alone
        node = group.nodes.new(denoiser)
        node.location = (g.x, -600)
        g.x += 20
        group.links.new(image, node.inputs["Image"])
        group.links.new(o["Albedo"], node.inputs["Albedo"])
        group.links.new(o["Normal"], node.inputs["Normal"])
        node.inputs["HDR"].default_value = True    # radiance, not display values
        return node.outputs["Image"]

    pairs = []
    for k in (1, 2, 3):
        plus = _vector_op(g, "SCALE", _vector_op(g, "ADD", o["S0"], o[f"S{k}"]), scale=0.5)
        minus = _vector_op(g, "SCALE", _vector_op(g, "SUBTRACT", o["S0"], o[f"S{k}"]), scale=0.5)
        pairs.append((denoised(plus), denoised(minus)))
    sums = [_vector_op(g, "ADD", p, m) for p, m in pairs]
    s0 = _vector_op(g, "SCALE", _vector_op(g, "ADD", _vector_op(g, "ADD", sums[0], sums[1]), sums[2]),
                    scale=1.0 / 3.0)
    sk = [_vector_op(g, "SUBTRACT", p, m) for p, m in pairs]
    # |S| per colour channel and the factor min(S0/|S|, 1) (safe divide: 0 where |S| = 0, where S_k = 0)
    sq = [_vector_op(g, "MULTIPLY", s, s) for s in sk]
    length = _vector_op(g, "POWER", _vector_op(g, "ADD", _vector_op(g, "ADD", sq[0], sq[1]), sq[2]),
                        (0.5, 0.5, 0.5))
    limit = _vector_op(g, "MAXIMUM", _vector_op(g, "MINIMUM", _vector_op(g, "DIVIDE", s0, length), (1.0, 1.0, 1.0)),
                       (0.0, 0.0, 0.0))
    # factor = 1 + clamp·(limit − 1): 1 without the clamp
    factor = _vector_op(g, "ADD", _vector_op(g, "SCALE", _vector_op(g, "SUBTRACT", limit, (1.0, 1.0, 1.0)),
                                             scale=o["Clamp DoP"]), (1.0, 1.0, 1.0))
    group.links.new(s0, gout.inputs["S0"])
    for k, s in zip((1, 2, 3), sk):
        group.links.new(_vector_op(g, "MULTIPLY", s, factor), gout.inputs[f"S{k}"])
    return group


def add_denoise_to_compositor(scene, denoiser="CompositorNodeDenoise"):
    """Add the Polar Denoise group to the scene's compositor, fed by the Render Layers node's S0…S3 and
    Denoising Albedo / Normal passes (turn them on in the View Layer properties); its S0 goes to the
    compositor's output if nothing else does.  Returns the node."""
    tree, layers = _compositor_with_render_layers(scene)
    node = tree.nodes.new("CompositorNodeGroup")
    node.node_tree = ensure_denoise_group(denoiser)
    node.name = node.label = DENOISE_GROUP_NAME
    node.location = (0, -300)
    for src, dst in (("S0", "S0"), ("S1", "S1"), ("S2", "S2"), ("S3", "S3"),
                     ("Denoising Albedo", "Albedo"), ("Denoising Normal", "Normal")):
        if src in layers.outputs:
            tree.links.new(layers.outputs[src], node.inputs[dst])
    _show(tree, node.outputs["S0"])            # the denoised intensity is the image shown
    return node


# ----------------------------------------------------------------------------- the Denoise switch

#: Render ▸ Performance ▸ Compositor ▸ Denoise quality (final) → OIDN's quality (oidn.h: FAST 4, BALANCED 5, HIGH 6)
OIDN_QUALITY = {"FAST": 4, "BALANCED": 5, "HIGH": 6}
_OIDN_CPU, _OIDN_FLOAT3 = 1, 3


class DenoiseUnavailable(RuntimeError):
    """Blender's OpenImageDenoise cannot be used here (not found, or it reported an error)."""


def _oidn_api(lib):
    """The OIDN C functions the Denoise switch calls, with their ctypes signatures (oidn.h, OIDN 2)."""
    import ctypes
    vp, cp, sz = ctypes.c_void_p, ctypes.c_char_p, ctypes.c_size_t
    for name, res, args in (("oidnNewDevice", vp, [ctypes.c_int]), ("oidnCommitDevice", None, [vp]),
                            ("oidnSetDeviceBool", None, [vp, cp, ctypes.c_bool]),
                            ("oidnGetDeviceError", ctypes.c_int, [vp, ctypes.POINTER(cp)]),
                            ("oidnReleaseDevice", None, [vp]), ("oidnNewFilter", vp, [vp, cp]),
                            ("oidnSetSharedFilterImage", None, [vp, cp, vp, ctypes.c_int, sz, sz, sz, sz, sz]),
                            ("oidnSetFilterBool", None, [vp, cp, ctypes.c_bool]),
                            ("oidnSetFilterInt", None, [vp, cp, ctypes.c_int]),
                            ("oidnCommitFilter", None, [vp]), ("oidnExecuteFilter", None, [vp]),
                            ("oidnReleaseFilter", None, [vp])):
        f = getattr(lib, name)
        f.restype, f.argtypes = res, args
    return lib


def _oidn_run(lib, images, output, quality, settings, affinity=None):
    """One OIDN "RT" filter on a new CPU device: ``images`` {name: (H, W, C) float32 C-contiguous} read as Float3
    with the pixel stride of their C channels, the result written into ``output`` (which may be one of them),
    ``settings`` {name: bool} the filter's flags (hdr, cleanAux)."""
    import ctypes
    device = lib.oidnNewDevice(_OIDN_CPU)
    if not device:
        raise DenoiseUnavailable("OpenImageDenoise could not create a CPU device")
    try:
        if affinity is not None:
            lib.oidnSetDeviceBool(device, b"setAffinity", affinity)
        lib.oidnCommitDevice(device)
        filt = lib.oidnNewFilter(device, b"RT")
        try:
            height, width = output.shape[:2]
            for name, image in list(images.items()) + [("output", output)]:
                assert image.dtype == np.float32 and image.flags.c_contiguous and image.shape[:2] == (height, width)
                stride = 4 * image.shape[2]
                lib.oidnSetSharedFilterImage(filt, name.encode(), image.ctypes.data, _OIDN_FLOAT3, width, height, 0,
                                             stride, stride * width)
            for name, value in settings.items():
                lib.oidnSetFilterBool(filt, name.encode(), value)
            lib.oidnSetFilterInt(filt, b"quality", quality)
            lib.oidnCommitFilter(filt)
            lib.oidnExecuteFilter(filt)
        finally:
            lib.oidnReleaseFilter(filt)
        message = ctypes.c_char_p()
        if lib.oidnGetDeviceError(device, ctypes.byref(message)) != 0:
            raise DenoiseUnavailable(f"OpenImageDenoise: {(message.value or b'error').decode(errors='replace')}")
    finally:
        lib.oidnReleaseDevice(device)


def _rgba(image):
    """(H, W, 3) → (H, W, 4) float32 with alpha 1: a colour as the compositor holds it (4 floats a pixel)."""
    out = np.ones(image.shape[:2] + (4,), np.float32)
    out[..., :3] = image
    return out


def denoise_stokes(stokes_rgb, albedo=None, normal=None, quality="HIGH", clamp_dop=True, lib=None):
    """The Polar Denoise group's computation on a Stokes image, with Blender's OpenImageDenoise called directly:
    its S0…S3 outputs (4, H, W, 3) float32 for the Stokes image ``stokes_rgb`` (4, H, W, 3) and the guides
    ``albedo``, ``normal`` (H, W, 3) (None: without guides), all in Blender's row order (row 0 at the bottom, as
    the compositor holds render passes: the network is not symmetric under a flip).

    As the group's nodes do, in float32: the analyser images (S0 ± S_k)·½ are each denoised by an OIDN "RT"
    filter on a CPU device (the Denoise node's defaults: HDR, prefilter Accurate — the albedo and the normal
    denoised once beforehand, each alone, and given as clean auxiliary images —, the quality ``quality``: the
    node's Follow Scene → Render ▸ Performance ▸ Compositor ▸ Denoise final quality), then S0 = (Σ sums)·⅓,
    S_k = difference of each pair, scaled per colour channel by max(min(S0/|S|, 1), 0) where ``clamp_dop``
    (the group's Clamp DoP = 1).  Raises DenoiseUnavailable where the library is missing or fails."""
    lib = lib if lib is not None else compat.oidn_library()
    if lib is None:
        raise DenoiseUnavailable("Blender's OpenImageDenoise library was not found")
    lib = _oidn_api(lib)
    q = OIDN_QUALITY.get(quality, OIDN_QUALITY["HIGH"])
    s = np.asarray(stokes_rgb, np.float32)
    guides = {}
    if albedo is not None and normal is not None:
        guides["albedo"] = _rgba(np.asarray(albedo, np.float32))
        guides["normal"] = np.ascontiguousarray(normal, np.float32)
        for name, image in guides.items():          # Prefilter Accurate: each guide denoised alone, in place
            _oidn_run(lib, {name: image}, image, q, {})
    half = np.float32(0.5)
    pairs = []
    for k in (1, 2, 3):
        pair = []
        for analyser in ((s[0] + s[k]) * half, (s[0] - s[k]) * half):
            out = np.empty(analyser.shape[:2] + (4,), np.float32)
            _oidn_run(lib, {"color": _rgba(analyser), **guides}, out, q, {"hdr": True, "cleanAux": True},
                      affinity=False)
            pair.append(out[..., :3])
        pairs.append(pair)
    sums = [p + m for p, m in pairs]
    result = np.empty(s.shape, np.float32)
    result[0] = ((sums[0] + sums[1]) + sums[2]) * np.float32(1.0 / 3.0)
    sk = [p - m for p, m in pairs]
    length = np.power((sk[0] * sk[0] + sk[1] * sk[1]) + sk[2] * sk[2], np.float32(0.5))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(length != 0, result[0] / np.where(length != 0, length, np.float32(1.0)), np.float32(0.0))
    limit = np.maximum(np.minimum(ratio, np.float32(1.0)), np.float32(0.0))
    factor = (limit - np.float32(1.0)) * np.float32(1.0 if clamp_dop else 0.0) + np.float32(1.0)
    for k in (1, 2, 3):
        result[k] = sk[k - 1] * factor
    return result
