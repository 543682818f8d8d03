"""World → constant environment light (colour × strength).

Supported: a Background node (or Emission) plugged into the World Output, with unlinked Color and
Strength.  Anything else (sky textures, HDRIs, mixes) falls back to the Background node's own
colour and strength if there is one, otherwise to the world's viewport colour, with a warning.
"""

from ...engine.scene.description import EnvironmentLight
from ...engine.spectral import RGBIlluminantSpectrum


def export_world(world, warnings: list):
    if world is None:
        return None
    colour, strength = [float(c) for c in world.color], 1.0
    tree = world.node_tree
    output = tree.get_output_node("ALL") if tree is not None else None
    link = output.inputs["Surface"].links[0] if output is not None and output.inputs["Surface"].is_linked else None
    node = link.from_node if link is not None else None
    if node is not None and node.bl_idname in ("ShaderNodeBackground", "ShaderNodeEmission"):
        c, s = node.inputs["Color"], node.inputs["Strength"]
        colour = [float(x) for x in c.default_value[:3]]
        strength = float(s.default_value)
        if c.is_linked or s.is_linked:
            what = (c.links[0].from_node if c.is_linked else s.links[0].from_node).bl_idname
            warnings.append(f"world {world.name!r}: {what} feeding the background is not supported; "
                            "using the Background node's own colour and strength")
    elif node is not None:
        warnings.append(f"world {world.name!r}: {node.bl_idname} is not supported; using the world's "
                        "viewport colour")
    elif tree is not None and output is not None:
        return None   # nothing plugged in: black world
    if strength <= 0 or max(colour) <= 0:
        return None
    return EnvironmentLight(RGBIlluminantSpectrum(colour, strength))
