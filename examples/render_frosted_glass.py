"""Frosted against smooth glass: renders examples/frosted_glass.json twice and writes one PNG montage.

    python examples/render_frosted_glass.py [--spp 64] [--out examples/images/frosted_glass.png]

Row 1 is the smooth glass sphere (the scene with the sphere's material switched to ``smooth_glass``),
row 2 the frosted one (``frosted_glass``: rough dielectric, Beckmann α = 0.2); same camera, floor,
sky and backdrop panels, full polarisation.  Columns: S0 (linear sRGB, tone-mapped by clipping), DoLP (viridis 0 … 1)
and S3/S0 in luminance (blue −S3_SCALE … white 0 … red +S3_SCALE, optics sign convention: red =
right-circular).  Each panel has the engine's legend strip below it; panels are separated by black.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from engine.output import luminance_stokes  # noqa: E402
from engine.output.colormaps import diverging, sequential, tonemap  # noqa: E402
from engine.output.png import write_png  # noqa: E402
from engine.output.previews import legend_bar  # noqa: E402
from engine.render.renderer import Renderer  # noqa: E402
from engine.scene.loader import parse_scene  # noqa: E402

SCENE = os.path.join(HERE, "frosted_glass.json")
MATERIALS = ("smooth_glass", "frosted_glass")   # one montage row each, top to bottom
S3_SCALE = 0.1   # full scale of the S3/S0 panel: circular polarisation here is a few per cent
GAP = 8          # black pixels between panels


def render_stokes(data: dict, material: str, spp: int, seed: int) -> np.ndarray:
    """(4, H, W, 3) linear-sRGB Stokes image of ``data`` with the sphere made of ``material``."""
    d = copy.deepcopy(data)
    for obj in d["objects"]:
        if obj["name"] == "sphere":
            obj["material"] = material
    scene = parse_scene(d, base_dir=HERE, source=SCENE)
    scene.settings = dataclasses.replace(scene.settings, spp=spp, seed=seed, polarisation="full")
    return Renderer(scene).render(scene.settings).stokes()


def panels(stokes: np.ndarray) -> list[np.ndarray]:
    """S0, DoLP and S3/S0 panels (uint8 RGB, legend strip appended) of one Stokes image."""
    y = luminance_stokes(stokes)
    dark = ~(y[0] > 0)
    s0 = np.where(dark, 1.0, y[0])
    dolp = np.where(dark, np.nan, np.hypot(y[1], y[2]) / s0)
    s3 = np.where(dark, np.nan, y[3] / s0)
    t = np.linspace(0.0, 1.0, stokes.shape[2])
    grey = tonemap(np.repeat(t[:, None], 3, axis=1))
    return [np.concatenate([tonemap(stokes[0]), legend_bar(grey)], axis=0),
            np.concatenate([sequential(dolp), legend_bar(sequential(t))], axis=0),
            np.concatenate([diverging(s3 / S3_SCALE), legend_bar(diverging(2.0 * t - 1.0))], axis=0)]


def montage(rows: list[list[np.ndarray]]) -> np.ndarray:
    """Panels on a black background, GAP pixels apart and around."""
    h, w = rows[0][0].shape[:2]
    out = np.zeros((GAP + len(rows) * (h + GAP), GAP + len(rows[0]) * (w + GAP), 3), np.uint8)
    for i, row in enumerate(rows):
        for j, panel in enumerate(row):
            out[GAP + i * (h + GAP):GAP + i * (h + GAP) + h, GAP + j * (w + GAP):GAP + j * (w + GAP) + w] = panel
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=None, help="samples per pixel (default: the scene's)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=os.path.join(HERE, "images", "frosted_glass.png"))
    args = ap.parse_args()
    with open(SCENE, encoding="utf-8") as fh:
        data = json.load(fh)
    spp = args.spp or data["render"]["spp"]
    rows = []
    for material in MATERIALS:
        t0 = time.perf_counter()
        stokes = render_stokes(data, material, spp, args.seed)
        y = luminance_stokes(stokes)
        print(f"{material}: {spp} spp in {time.perf_counter() - t0:.1f} s; mean Y S0 {y[0].mean():.4f}, "
              f"max DoLP {np.nanmax(np.hypot(y[1], y[2]) / np.maximum(y[0], 1e-12)):.3f}, "
              f"max |S3|/S0 {np.nanmax(np.abs(y[3]) / np.maximum(y[0], 1e-12)):.4f}")
        rows.append(panels(stokes))
    write_png(args.out, montage(rows))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
