"""The light tree's light choice on the real assets: per light, the share of next-event samples Polar's tree gives it
at the camera's first hits, against the share Cycles' tree formulas give at the same points.

    python tests/bench/tree_choice.py [--assets TextureTransform,Sunglasses] [--lighting lamps] [--res 48]

Runs in the bpy module.  Builds each case as tests/support/asset_parity does (the glTF imported, framed, lit), exports
it to Polar, casts a ray through each pixel centre (Blender's ray cast: the point and the face normal, turned
towards the camera) and prints, per light, the mean pick probability over the hit points (the expected fraction of
next-event samples; a mesh light's triangles summed) of Polar's tree, and — where the scene's lights are the lamps
lighting's sun and area light with no emissive mesh — of an independent NumPy model of Cycles' choice there (its
tree's root: the area light against the distant leaf, kernel/light/tree.h's importance with the parameters of
kernel/light/{area, distant}.h and scene/light_tree.cpp's energies; a constant world is not in Cycles' tree,
scene/light.cpp test_enabled_lights).  Not a test: the numbers go to docs/benchmarks/light-tree.md.
"""

from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)


def first_hits(scene, width, height):
    """(p (3, M), side normal (3, M)) of the camera rays through the pixel centres that hit something."""
    import bpy
    from mathutils import Vector
    cam = scene.camera
    depsgraph = bpy.context.evaluated_depsgraph_get()
    frame_pts = [Vector(v) for v in cam.data.view_frame(scene=scene)]
    xs, ys, z = [v.x for v in frame_pts], [v.y for v in frame_pts], frame_pts[0].z
    M = cam.matrix_world
    origin = M.translation
    ps, ns = [], []
    for i in range(height):
        y = max(ys) - (i + 0.5) / height * (max(ys) - min(ys))
        for j in range(width):
            x = min(xs) + (j + 0.5) / width * (max(xs) - min(xs))
            d = (M.to_3x3() @ Vector((x, y, z))).normalized()
            hit, loc, normal, *_ = scene.ray_cast(depsgraph, origin, d)
            if hit:
                n = np.array(tuple(normal))
                ps.append(tuple(loc))
                ns.append(n if np.dot(n, tuple(d)) < 0 else -n)
    return np.array(ps, float).T, np.array(ns, float).T


def _sin(c):
    return np.sqrt(np.maximum(1.0 - c * c, 0.0))


def cycles_importance(N, ptc, cos_u, axis, theta_o, theta_e, d_max, d_min, energy):
    """kernel/light/tree.h light_tree_importance (a surface, no transmission), vectorised: (I⁺, I⁻) (M,)."""
    sin_u = _sin(cos_u)
    cos_i = (ptc * N).sum(0)
    sin_i = _sin(cos_i)
    cmin_inc = np.where(cos_i >= cos_u, 1.0, cos_i * cos_u + sin_i * sin_u)
    cmax_inc = np.maximum(cos_i * cos_u - sin_i * sin_u, 0.0)
    cos_t = np.clip(-(axis * ptc).sum(0), -1, 1)
    sin_t = _sin(cos_t)
    c_tmu = cos_t * cos_u + sin_t * sin_u
    co, so = math.cos(theta_o), math.sin(theta_o)
    inside = (cos_t >= cos_u) | (c_tmu >= co)
    edge = (theta_o + theta_e > math.pi) | (c_tmu > math.cos(theta_o + theta_e))
    cmin_out = np.where(inside, 1.0, c_tmu * co + _sin(c_tmu) * so)
    ok = (inside | edge) & (cmin_inc >= 0)
    i_max = np.where(ok, np.abs(cmin_inc * energy * cmin_out / d_min ** 2), 0.0)
    c_tpu = cos_t * cos_u - sin_t * sin_u
    lower = ~((theta_e - theta_o < 0) | (cos_t < 0) | (cos_u < 0) | (c_tpu < math.cos(theta_e - theta_o)))
    cmax_out = c_tpu * co - _sin(c_tpu) * so
    i_min = np.where(ok & lower, np.abs(cmax_inc * energy * cmax_out / d_max ** 2), 0.0)
    return i_max, i_min


def cycles_area(p, N, lamp):
    """(I⁺, I⁻) of a Blender area light (square or rectangle; kernel/light/area.h area_light_tree_parameters)."""
    import bpy
    obj = bpy.data.objects[lamp]
    M = np.array(obj.matrix_world)
    centre, R = M[:3, 3], M[:3, :3]
    su = obj.data.size
    sv = obj.data.size_y if obj.data.shape in ("RECTANGLE", "ELLIPSE") else su
    eu, ev = R @ np.array([su, 0, 0]), R @ np.array([0, sv, 0])
    axis = -R[:, 2] / np.linalg.norm(R[:, 2])               # a Blender area light emits along its local −Z
    v = centre[:, None] - p
    d = np.linalg.norm(v, axis=0)
    ptc = v / d
    cos_u, d_max = np.full(d.shape, np.inf), d.copy()
    for a, b in ((-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5)):
        w = (centre + a * eu + b * ev)[:, None] - p
        dc = np.linalg.norm(w, axis=0)
        cos_u = np.minimum(cos_u, ((w / dc) * ptc).sum(0))
        d_max = np.maximum(d_max, dc)
    front = (axis[:, None] * ptc).sum(0) < 0
    above = (N * v).sum(0) + np.abs(N.T @ eu) + np.abs(N.T @ ev) > 0
    # energy: radiance × area, the S/π of Blender ≥ 4.0's L = S/(π A) (light_tree.cpp's 0.25 × Cycles' strength)
    strength = np.array(obj.data.color) * obj.data.energy / math.pi
    i_max, i_min = cycles_importance(N, ptc, cos_u, axis[:, None], 0.0, 0.5 * obj.data.spread, d_max, d,
                                     strength.mean())
    vis = front & above
    return np.where(vis, i_max, 0.0), np.where(vis, i_min, 0.0)


def cycles_sun(p, N, lamp):
    """(I⁺, I⁻) of a sun as one emitter (kernel/light/distant.h distant_light_tree_parameters)."""
    import bpy
    obj = bpy.data.objects[lamp]
    R = np.array(obj.matrix_world)[:3, :3]
    travel = -R[:, 2] / np.linalg.norm(R[:, 2])
    half = 0.5 * obj.data.angle
    cos_u = np.full(p.shape[1], math.cos(half))
    ptc = np.repeat(-travel[:, None], p.shape[1], axis=1)
    energy = float(np.mean(np.array(obj.data.color) * obj.data.energy))
    return cycles_importance(N, ptc, cos_u, travel[:, None], 0.0, half, 1.0 / cos_u, np.ones_like(cos_u), energy)


def cycles_shares(p, N):
    """{light name: mean pick probability} of Cycles' tree with the lamps lighting (area light, sun; constant world
    not in the tree): root(left = the area light, right = the distant leaf of the sun alone)."""
    a_max, a_min = cycles_area(p, N, "Area")
    s_max, s_min = cycles_sun(p, N, "Sun")
    t_max, t_min = a_max + s_max, a_min + s_min
    ok = t_max > 0
    p_max = a_max / np.where(ok, t_max, 1.0)
    p_min = np.where(t_min > 0, a_min / np.where(t_min > 0, t_min, 1.0),
                     0.5 * ((a_max > 0) + (s_max == 0)))
    left = np.where(ok, 0.5 * (p_max + p_min), 0.0)
    return {"Area": float(left.mean()), "Sun": float(np.where(ok, 1 - left, 0).mean()),
            "(none)": float((~ok).mean())}


def polar_shares(renderer, p, N, K=64):
    """{light: the fraction of next-event samples Polar's tree gives it over the points} (K stratified numbers per
    point through ``choose``; "(none)": no light can reach the point)."""
    lights = renderer.lights
    tree = lights.light_tree()
    M = p.shape[1]
    u = np.tile((np.arange(K) + 0.5) / K, M)
    light, _, _, _ = tree.choose(u, np.repeat(p, K, axis=1), np.repeat(N, K, axis=1))
    out = {f"{li}:{type(lt).__name__}": float((light == li).mean()) for li, lt in enumerate(lights.lights)}
    out["(none)"] = float((light < 0).mean())
    power, _, _ = lights.choose(u, np.repeat(p, K, axis=1), np.repeat(N, K, axis=1))
    by_power = {f"{li}:{type(lt).__name__}": float((power == li).mean()) for li, lt in enumerate(lights.lights)}
    return out, by_power


def main(argv=None):
    ap_ = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap_.add_argument("--assets", default="")
    ap_.add_argument("--lighting", default="lamps")
    ap_.add_argument("--res", type=int, default=48)
    args = ap_.parse_args(argv)
    from tests.support import asset_parity as ap
    names = args.assets.split(",") if args.assets else list(ap.CATALOGUE)
    for name in names:
        for lighting in args.lighting.split(","):
            asset = ap.CATALOGUE[name]
            w = args.res
            h = max(8, round(args.res * asset.size[1] / asset.size[0]))
            scene = ap.build(asset, lighting, w, h)
            p, N = first_hits(scene, w, h)
            ap.cycles_settings(scene, 16, 8, light_tree=True)
            renderer, settings, _ = ap.export_polar(scene, 16, 8)
            shares, by_power = polar_shares(renderer, p, N)
            print(f"{name} {lighting}: {p.shape[1]} points; Polar's tree: "
                  + ", ".join(f"{k} {v:.3f}" for k, v in shares.items()))
            print(f"    Polar's {renderer.lights.selection!r} selection: "
                  + ", ".join(f"{k} {v:.3f}" for k, v in by_power.items()))
            has_mesh = len(renderer.lights.lights) > 3
            if lighting == "lamps" and not has_mesh:
                c = cycles_shares(p, N)
                print("    Cycles' tree (model): " + ", ".join(f"{k} {v:.3f}" for k, v in c.items()))
            sys.stdout.flush()


if __name__ == "__main__":
    main()
