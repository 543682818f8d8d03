"""Blender-version differences, in one place: every other module of the add-on calls these helpers
instead of testing ``bpy.app.version`` itself.

Supported: Blender 4.5 LTS (Python 3.11) to 5.3 (Python 3.13), ``polar_addon.packaging.BLENDER_PYTHONS``.
Differences are detected by presence (an RNA property, a node type) rather than by version number,
so a later release that keeps an API keeps working.  What differs:

* Node trees of materials and worlds: before 5.0 a new material or world has none until
  ``use_nodes`` is set, and one with ``use_nodes`` off renders its plain colour (Cycles' rule);
  from 5.0 every material and world has its tree and ``use_nodes`` is deprecated.
* The compositor: 5.0 made it a node group assigned to ``Scene.compositing_node_group`` whose Group
  Output is the final image; before, ``Scene.node_tree`` (after ``Scene.use_nodes``) with a
  Composite node.
* Multilayer EXR output: 5.0 sets ``ImageFormatSettings.media_type``; before, a file format of its own.
* Features newer Blenders add are read by presence here (``getattr`` with the older behaviour as the
  default, ``node.inputs.get``), and callers warn once where one a scene uses is not simulated: so
  far 5.1's Normal Map convention (OpenGL or DirectX), :func:`normal_map_convention`.
* The ``openvdb`` module inside Blender's own site-packages (Volume objects): :func:`openvdb_module`,
  :func:`volume_file`.
"""

import bpy

#: (major, minor, patch) of the running Blender.
VERSION = tuple(bpy.app.version)


def _has_property(rna_type, name: str) -> bool:
    return name in rna_type.bl_rna.properties


#: Blender 5.0 on: the compositor is a node group on the scene.
COMPOSITOR_IS_GROUP = _has_property(bpy.types.Scene, "compositing_node_group")
#: Blender 5.0 on: image output settings choose between image, multilayer image and video.
HAS_MEDIA_TYPE = _has_property(bpy.types.ImageFormatSettings, "media_type")
#: Blender 5.0 on: every material and world renders its node tree (``use_nodes`` is deprecated, and
#: reading it warns; 5.0 converts older files' node-less materials on load).  A version test, as the
#: property is still present.
TREES_ALWAYS_USED = VERSION >= (5, 0, 0)


# ----------------------------------------------------------------------------- shader node trees

def node_tree_in_use(block):
    """The node tree a material or world renders with, or None where it renders its plain colour
    (no tree, or ``use_nodes`` off before Blender 5.0)."""
    tree = getattr(block, "node_tree", None)
    if tree is None or TREES_ALWAYS_USED:
        return tree
    return tree if block.use_nodes else None


def ensure_node_tree(block):
    """The node tree of a material or world, switching nodes on first where Blender needs it (before
    5.0 a new material or world has none: Blender then adds Principled BSDF / Background and output)."""
    if node_tree_in_use(block) is None and hasattr(block, "use_nodes"):
        block.use_nodes = True
    return block.node_tree


# ----------------------------------------------------------------------------- compositor

def compositor_tree(scene, create: bool = False):
    """The scene's compositor node tree, or None (``create``: make and assign one if missing).

    A new tree comes with what its Blender needs to show a result: an ``Image`` output socket
    (5.0 on) or a Composite node (before 5.0, which Blender adds with Render Layers)."""
    if COMPOSITOR_IS_GROUP:
        tree = scene.compositing_node_group
        if tree is None and create:
            tree = bpy.data.node_groups.new(f"{scene.name} Compositing", "CompositorNodeTree")
            tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
            scene.compositing_node_group = tree
        return tree
    if not scene.use_nodes:
        if not create:
            return None
        scene.use_nodes = True
    return scene.node_tree


def compositor_output(tree):
    """The node whose first input is the compositor's final image: Group Output (5.0 on) or
    Composite (before), created if missing."""
    kind = "NodeGroupOutput" if COMPOSITOR_IS_GROUP else "CompositorNodeComposite"
    node = next((n for n in tree.nodes if n.bl_idname == kind), None)
    return node if node is not None else tree.nodes.new(kind)


# ----------------------------------------------------------------------------- output files

def set_multilayer_exr(image_settings, depth: str = "32"):
    """Write every pass into one multilayer OpenEXR file (float ``depth`` "16" or "32")."""
    if HAS_MEDIA_TYPE:
        image_settings.media_type = "MULTI_LAYER_IMAGE"
    else:
        image_settings.file_format = "OPEN_EXR_MULTILAYER"
    image_settings.color_depth = depth


# ----------------------------------------------------------------------------- features by presence

def normal_map_convention(node) -> str:
    """A Normal Map node's tangent-space convention, "opengl" or "directx" (Blender 5.1 added the
    choice; before, every normal map is OpenGL's)."""
    return "directx" if getattr(node, "convention", "OPENGL") == "DIRECTX" else "opengl"


# ----------------------------------------------------------------------------- OpenVDB (Volume objects)

_OPENVDB = []


def openvdb_module():
    """The ``openvdb`` Python module that ships inside Blender (4.5–5.3: in Blender's own site-packages,
    ``<resource LOCAL>/python/lib/pythonX.Y/site-packages``, which the ``bpy`` wheel does not put on sys.path),
    or None where it is missing."""
    if _OPENVDB:
        return _OPENVDB[0]
    import importlib
    import os
    import sys
    module = None
    try:
        module = importlib.import_module("openvdb")
    except ImportError:
        version = f"python{sys.version_info.major}.{sys.version_info.minor}"
        folder = os.path.join(bpy.utils.resource_path("LOCAL"), "python", "lib", version, "site-packages")
        if os.path.isdir(folder) and folder not in sys.path:
            sys.path.append(folder)
            try:
                module = importlib.import_module("openvdb")
            except ImportError:
                module = None
    _OPENVDB.append(module)
    return module


def volume_file(obj):
    """The absolute path of the OpenVDB file a Volume object's grids come from at the current frame (a sequence's
    frame file), or None where they are not read from a file that exists (generated by geometry nodes or Mesh to
    Volume, a simulation cache held in memory)."""
    import os
    data = getattr(obj, "data", None)
    grids = getattr(data, "grids", None)
    path = (getattr(grids, "frame_filepath", "") or getattr(data, "filepath", "")) if data is not None else ""
    if not path:
        return None
    original = getattr(getattr(obj, "original", obj), "data", data)
    path = bpy.path.abspath(path, library=getattr(original, "library", None))
    return path if os.path.isfile(path) else None


# ----------------------------------------------------------------------------- OpenImageDenoise

#: File names of Blender's OpenImageDenoise library (Linux, Windows, macOS), the one its compositor's Denoise node
#: and Cycles use (OIDN 2.3 in Blender 4.5–5.0, 2.5 in 5.3).
OIDN_NAMES = ("libOpenImageDenoise.so.2", "OpenImageDenoise.dll", "libOpenImageDenoise.2.dylib")


def _oidn_folders():
    """Folders that may hold Blender's libraries: ``lib`` beside or above the binary (Blender; macOS
    ``Contents/Resources/lib``) and above the ``bpy`` module's scripts (the bpy wheel's ``bpy/lib``)."""
    import os
    starts = [os.path.dirname(bpy.app.binary_path or "")]
    starts.append(os.path.dirname(os.path.abspath(bpy.__file__)))
    folders = []
    for start in starts:
        folder = start
        for _ in range(6):
            if not folder:
                break
            folders += [folder, os.path.join(folder, "lib"), os.path.join(folder, "Resources", "lib"),
                        os.path.join(folder, "blender.shared")]
            parent = os.path.dirname(folder)
            if parent == folder:
                break
            folder = parent
    return folders


_OIDN = []


def oidn_library():
    """Blender's own OpenImageDenoise as a ``ctypes.CDLL``, or None where it is not found.  Blender links it at
    start-up, so loading it by name returns the copy already in the process; else it is looked for in
    Blender's library folders."""
    if _OIDN:
        return _OIDN[0]
    import ctypes
    import os
    lib = None
    for name in OIDN_NAMES:
        candidates = [name] + [os.path.join(folder, name) for folder in _oidn_folders()]
        for path in candidates:
            if path != name and not os.path.isfile(path):
                continue
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            if hasattr(lib, "oidnNewDevice"):
                break
            lib = None
        if lib is not None:
            break
    _OIDN.append(lib)
    return lib
