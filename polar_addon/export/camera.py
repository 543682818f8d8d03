"""Blender camera → engine Camera, using ``Camera.view_frame`` (sensor fit, shift, ortho scale and
pixel aspect already applied) so that the framing is exactly Blender's."""

import numpy as np

from ...engine.scene.description import Camera
from ...engine.errors import SceneError


def export_camera(scene, camera_object, width: int, height: int, warnings: list) -> Camera:
    if camera_object is None:
        raise SceneError("scene.camera", "the scene has no active camera: add one and make it active "
                                         "(Scene properties ▸ Camera)")
    if camera_object.type != "CAMERA":
        raise SceneError("scene.camera", f"the active camera {camera_object.name!r} is not a camera object")
    data = camera_object.data
    M = np.array(camera_object.matrix_world, dtype=np.float64)
    origin = M[:3, 3]
    # Columns of the rotation: camera looks along −Z with +Y up; remove scale.
    x_axis = M[:3, 0] / np.linalg.norm(M[:3, 0])
    y_axis = M[:3, 1] / np.linalg.norm(M[:3, 1])
    z_axis = M[:3, 2] / np.linalg.norm(M[:3, 2])
    forward = -z_axis
    frame = np.array([tuple(v) for v in data.view_frame(scene=scene)])   # TR, BR, BL, TL in camera space
    x_min, x_max = frame[:, 0].min(), frame[:, 0].max()
    y_min, y_max = frame[:, 1].min(), frame[:, 1].max()
    cam = Camera(origin=origin, target=origin + forward, up=y_axis, width=width, height=height)
    if data.type == "PANO":
        warnings.append(f"camera {camera_object.name!r}: panoramic cameras are not supported; "
                        "rendering as perspective")
    if data.type == "ORTHO":
        cam.projection = "orthographic"
        cam.ortho_width = float(x_max - x_min)
        half_x, half_y = (x_max - x_min) / 2, (y_max - y_min) / 2
        cx, cy = (x_max + x_min) / 2, (y_max + y_min) / 2
    else:
        depth = -frame[0, 2]
        half_x, half_y = (x_max - x_min) / 2 / depth, (y_max - y_min) / 2 / depth
        cx, cy = (x_max + x_min) / 2 / depth, (y_max + y_min) / 2 / depth
        cam.fov_deg = float(np.degrees(2 * np.arctan(half_x)))
    cam.fov_axis = "x"
    if abs(half_y / half_x - height / width) > 1e-3 * height / width:
        warnings.append("non-square pixels (pixel aspect ≠ 1) are rendered square")
    # The engine's shift is in units of the larger image side: offset = 2·shift·side/W·t_x.
    side = max(width, height)
    cam.shift = (float(cx / (2 * half_x) * width / side), float(cy / (2 * half_y) * height / side))
    # The engine's basis must match Blender's (right = x_axis): up = y_axis, forward = −z.
    if np.dot(np.cross(forward, y_axis), x_axis) < 0.999:
        warnings.append(f"camera {camera_object.name!r} has a skewed or mirrored transform")
    cam.clip_start = float(data.clip_start)
    cam.clip_end = float(data.clip_end)
    return cam


def border_window(render, width: int, height: int):
    """Pixel window (x0, y0, x1, y1), row 0 at the top, of a border render, or None."""
    if not render.use_border:
        return None
    x0 = int(render.border_min_x * width)
    x1 = int(render.border_max_x * width)
    y0_bottom = int(render.border_min_y * height)
    y1_bottom = int(render.border_max_y * height)
    if x1 <= x0 or y1_bottom <= y0_bottom:
        return None
    return x0, height - y1_bottom, x1, height - y0_bottom
