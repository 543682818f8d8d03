"""Writes sky_sun.exr beside this file: a small procedural equirectangular sky for the real-asset suite.

    python tests/data/assets/environment/make_sky.py

512 × 256 texels, half float, ZIP: a blue zenith fading to a pale horizon, a brown-grey ground
below it, and a sun of 5° diameter at 35° elevation whose irradiance is about 2.5 W/m² (texel
radiance ≈ 420) with a faint glow around it.  Made here (numpy + OpenEXR), no third-party data;
deterministic, so re-running it rewrites the same file.
"""

import os

import numpy as np

W, H = 512, 256
SUN_ELEVATION = np.radians(35.0)
SUN_LONGITUDE = np.radians(-50.0)       # longitude in the map (0 = the map's centre column)
SUN_RADIUS = np.radians(2.5)
SUN_IRRADIANCE = 2.5                    # W/m² from the disc (its radiance × solid angle)


def sky() -> np.ndarray:
    """(H, W, 3) float32 linear radiance; row 0 is the zenith."""
    el = np.pi / 2 - (np.arange(H) + 0.5) / H * np.pi                 # elevation of each row
    lon = ((np.arange(W) + 0.5) / W - 0.5) * 2 * np.pi                 # longitude of each column
    el, lon = np.meshgrid(el, lon, indexing="ij")
    zenith = np.array([0.22, 0.42, 1.0]) * 0.9
    horizon = np.array([0.95, 0.95, 1.0]) * 1.1
    ground = np.array([0.32, 0.28, 0.24]) * 0.45
    t = np.clip(el / (np.pi / 2), 0.0, 1.0)[..., None] ** 0.6
    up = horizon * (1 - t) + zenith * t
    g = np.clip(-el / np.radians(4.0), 0.0, 1.0)[..., None]            # soft horizon line
    rgb = up * (1 - g) + ground * g
    d = np.stack([np.cos(el) * np.cos(lon), np.cos(el) * np.sin(lon), np.sin(el)], axis=-1)
    s = np.array([np.cos(SUN_ELEVATION) * np.cos(SUN_LONGITUDE), np.cos(SUN_ELEVATION) * np.sin(SUN_LONGITUDE),
                  np.sin(SUN_ELEVATION)])
    angle = np.arccos(np.clip(d @ s, -1.0, 1.0))
    radiance = SUN_IRRADIANCE / (np.pi * SUN_RADIUS ** 2)
    disc = np.clip((SUN_RADIUS - angle) / np.radians(0.4) + 0.5, 0.0, 1.0)   # antialiased edge
    glow = 3.0 * np.exp(-(angle / np.radians(8.0)) ** 2)
    rgb = rgb + (disc * radiance + glow)[..., None] * np.array([1.0, 0.95, 0.85])
    return rgb.astype(np.float32)


def main():
    import OpenEXR
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "sky_sun.exr")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, {"RGB": sky().astype(np.float16)}).write(path)
    print(path)


if __name__ == "__main__":
    main()
