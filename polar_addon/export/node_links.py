"""What feeds a shader node's input socket: the link followed through reroutes (the material export's
graph walks start here: images, the node reader, the shader conversions)."""


def linked_source(socket):
    """(node, output socket) feeding an input socket (through reroutes), or (None, None)."""
    if not socket.is_linked:
        return None, None
    link = socket.links[0]
    node, out = link.from_node, link.from_socket
    while node is not None and node.bl_idname == "NodeReroute":
        if not node.inputs[0].is_linked:
            return None, None
        link = node.inputs[0].links[0]
        node, out = link.from_node, link.from_socket
    return node, out


def follow(socket):
    """The node feeding an input socket (through reroutes), or None."""
    return linked_source(socket)[0]
