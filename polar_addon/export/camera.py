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
    if data.type == "PANO" and getattr(data, "panorama_type", "") == "EQUIRECTANGULAR":
        return _equirectangular(scene, camera_object, cam, warnings)
    if data.type == "PANO":
        warnings.append(f"camera {camera_object.name!r}: {getattr(data, 'panorama_type', 'panoramic').lower()} "
                        "panoramic cameras are not supported; rendering as perspective")
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
    _lens_and_film(scene, camera_object, cam, warnings)
    return cam


def _equirectangular(scene, camera_object, cam, warnings):
    """Cycles' equirectangular panorama: longitude (right positive, 0 = forward) and latitude ranges."""
    data = camera_object.data
    cam.projection = "equirectangular"
    cam.longitude_deg = (float(np.degrees(data.longitude_min)), float(np.degrees(data.longitude_max)))
    cam.latitude_deg = (float(np.degrees(data.latitude_min)), float(np.degrees(data.latitude_max)))
    if not (cam.longitude_deg[1] > cam.longitude_deg[0] and cam.latitude_deg[1] > cam.latitude_deg[0]):
        raise SceneError(f"camera {camera_object.name!r}", "the panorama's longitude and latitude ranges must "
                                                           "have max > min")
    if data.shift_x != 0 or data.shift_y != 0:
        warnings.append(f"camera {camera_object.name!r}: lens shift of a panoramic camera is ignored")
    cam.clip_start = float(data.clip_start)
    cam.clip_end = float(data.clip_end)
    _lens_and_film(scene, camera_object, cam, warnings)
    return cam


def aperture_radius(data) -> float:
    """Cycles' aperture radius in scene units: lens_mm·1e-3 / (2·f-stop) (perspective and panoramic,
    whatever the unit scale), 1/(2·f-stop) for orthographic cameras; 0 without depth of field."""
    if not data.dof.use_dof:
        return 0.0
    fstop = max(float(data.dof.aperture_fstop), 1e-5)
    if data.type == "ORTHO":
        return 1.0 / (2.0 * fstop)
    return float(data.lens) * 1e-3 / (2.0 * fstop)


def focus_distance(camera_object) -> float:
    """Depth of the focus plane: the focus object's depth along the view axis, else Focus Distance."""
    data = camera_object.data
    target = data.dof.focus_object
    if target is not None:
        M = np.array(camera_object.matrix_world, dtype=np.float64)
        z_axis = M[:3, 2] / np.linalg.norm(M[:3, 2])
        T = np.array(target.matrix_world, dtype=np.float64)
        return max(abs(float(np.dot(z_axis, M[:3, 3] - T[:3, 3]))), 1e-5)
    return max(float(data.dof.focus_distance), 1e-5)


def _lens_and_film(scene, camera_object, cam, warnings):
    data = camera_object.data
    cam.aperture_radius = aperture_radius(data)
    if cam.aperture_radius > 0:
        cam.focus_distance = focus_distance(camera_object)
        blades = int(data.dof.aperture_blades)
        cam.aperture_blades = blades if blades >= 3 else 0
        cam.aperture_rotation_deg = float(np.degrees(data.dof.aperture_rotation))
        cam.aperture_ratio = float(data.dof.aperture_ratio)
    cam.film_transparent = bool(scene.render.film_transparent)
    if scene.render.film_transparent and getattr(scene.render, "film_transparent_glass", False):
        warnings.append("Film ▸ Transparent Glass is not supported: glass stays opaque in alpha")
    if scene.render.use_motion_blur:
        warnings.append("motion blur is not simulated: the image shows the scene at the current frame")


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
