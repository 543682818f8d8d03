"""Engine field paths → where the setting is in Blender's UI, for error messages.

The engine names the offending value by its scene-file path (``camera.width``,
``render.batch_rays``); an artist in Blender knows "Output Properties ▸ Format ▸ Resolution X"
instead.  :func:`ui_message` rewrites a SceneError with these labels.  Every field of the engine's
Camera and RenderSettings that the exporter fills in has an entry (tests check this), including
the few the add-on fixes itself, which say so.
"""

from __future__ import annotations

import re

_FIXED = "fixed by the Polar add-on (not a Blender setting)"

#: Engine ``render.<field>`` → (property of Scene.polar or None, UI path).
RENDER_SETTINGS = {
    "spp": ("samples", "Render Properties ▸ Sampling ▸ Samples: Render (Viewport for the viewport and previews)"),
    "max_depth": ("max_bounces", "Render Properties ▸ Sampling ▸ Max Bounces (+2 segments, as Cycles counts bounces; "
                  "at most Light Paths ▸ Max Bounces ▸ Total)"),
    "rr_depth": (None, _FIXED),
    "seed": ("seed", "Render Properties ▸ Sampling ▸ Seed"),
    "spectral": ("spectral", "Render Properties ▸ Polarisation & Spectrum ▸ Spectral"),
    "wavelength_nm": ("wavelength_nm", "Render Properties ▸ Polarisation & Spectrum ▸ Wavelength"),
    "polarisation": ("polarisation", "Render Properties ▸ Polarisation & Spectrum ▸ Polarisation"),
    "batch_rays": ("batch_rays", "Render Properties ▸ Performance ▸ Batch Size"),
    "threads": ("threads", "Render Properties ▸ Performance ▸ Threads"),
    "parallel": ("parallel", "Render Properties ▸ Performance ▸ Parallel"),
    "reduce_spectral": (None, _FIXED),
    "simplify": ("skip_clear_layers", "Render Properties ▸ Polarisation & Spectrum ▸ Skip Clear Layers"),
    "sampler": ("sampler", "Render Properties ▸ Sampling ▸ Pattern"),
    "halves": ("halves", "Render Properties ▸ Sampling ▸ Even/Odd Samples"),
    "light_tree": (None, "Render Properties ▸ Sampling ▸ Light Tree (Cycles' Sampling ▸ Lights ▸ Light Tree)"),
    "denoise_data": (None, "View Layer Properties ▸ Polarisation Passes ▸ Denoising Data"),
    "max_diffuse_bounces": (None, "Render Properties ▸ Light Paths ▸ Max Bounces ▸ Diffuse"),
    "max_glossy_bounces": (None, "Render Properties ▸ Light Paths ▸ Max Bounces ▸ Glossy"),
    "max_transmission_bounces": (None, "Render Properties ▸ Light Paths ▸ Max Bounces ▸ Transmission"),
    "max_transparent_bounces": (None, "Render Properties ▸ Light Paths ▸ Max Bounces ▸ Transparent"),
    "max_volume_bounces": (None, "Render Properties ▸ Light Paths ▸ Max Bounces ▸ Volume"),
    "clamp_direct": (None, "Render Properties ▸ Light Paths ▸ Clamping ▸ Direct Light"),
    "clamp_indirect": (None, "Render Properties ▸ Light Paths ▸ Clamping ▸ Indirect Light"),
    "caustics_reflective": (None, "Render Properties ▸ Light Paths ▸ Caustics ▸ Reflective"),
    "caustics_refractive": (None, "Render Properties ▸ Light Paths ▸ Caustics ▸ Refractive"),
}

#: Engine ``camera.<field>`` → UI path (of the active camera, or the output format).
CAMERA = {
    "width": "Output Properties ▸ Format ▸ Resolution X (× %)",
    "height": "Output Properties ▸ Format ▸ Resolution Y (× %)",
    "origin": "the active camera's Object Properties ▸ Transform ▸ Location",
    "target": "the active camera's Object Properties ▸ Transform ▸ Rotation",
    "up": "the active camera's Object Properties ▸ Transform ▸ Rotation",
    "fov_deg": "Camera Properties ▸ Lens ▸ Focal Length (and Camera ▸ Sensor Size)",
    "fov_axis": "Camera Properties ▸ Camera ▸ Sensor Fit",
    "projection": "Camera Properties ▸ Lens ▸ Type",
    "ortho_width": "Camera Properties ▸ Lens ▸ Orthographic Scale",
    "shift": "Camera Properties ▸ Lens ▸ Shift X / Y",
    "clip_start": "Camera Properties ▸ Lens ▸ Clip Start",
    "clip_end": "Camera Properties ▸ Lens ▸ Clip End",
    "aperture_radius": "Camera Properties ▸ Depth of Field ▸ Aperture ▸ F-Stop (with Lens ▸ Focal Length)",
    "focus_distance": "Camera Properties ▸ Depth of Field ▸ Focus Distance (or Focus Object)",
    "aperture_blades": "Camera Properties ▸ Depth of Field ▸ Aperture ▸ Blades",
    "aperture_rotation_deg": "Camera Properties ▸ Depth of Field ▸ Aperture ▸ Rotation",
    "aperture_ratio": "Camera Properties ▸ Depth of Field ▸ Aperture ▸ Ratio",
    "longitude_deg": "Camera Properties ▸ Lens ▸ Longitude Min / Max (Panoramic, Equirectangular)",
    "latitude_deg": "Camera Properties ▸ Lens ▸ Latitude Min / Max (Panoramic, Equirectangular)",
    "film_transparent": "Render Properties ▸ Film ▸ Transparent",
}

#: Every engine field path the Blender side can meet → its UI label.
UI_NAMES = {
    **{f"render.{k}": label for k, (_, label) in RENDER_SETTINGS.items()},
    **{f"camera.{k}": label for k, label in CAMERA.items()},
    "scene.camera": "Scene Properties ▸ Scene ▸ Camera",
    "objects": "the visible objects of the view layer (Outliner)",
    "scene": "the visible objects of the view layer (Outliner)",
}

_PATTERN = re.compile(r"(?<![\w.])(" + "|".join(re.escape(k) for k in sorted(UI_NAMES, key=len, reverse=True)
                                                 if "." in k) + r")(?![\w.])")


def ui_label(field: str) -> str | None:
    """The UI label of an engine field path, or None if it is not a Blender setting we know."""
    return UI_NAMES.get(field)


def ui_message(error) -> str:
    """The message of a SceneError (or any exception) with engine field names replaced by UI labels."""
    field = getattr(error, "field", "")
    reason = getattr(error, "reason", None)
    label = UI_NAMES.get(field)
    text = f"{label}: {reason}" if (label and reason is not None) else str(error)
    return _PATTERN.sub(lambda m: f"“{UI_NAMES[m.group(1)]}”", text)
