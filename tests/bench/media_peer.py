"""Participating media against Mitsuba 3: S0 per block, and the time to equal S0 error (issue 37).

    python tests/bench/media_peer.py [--scenes media_hg_box,media_grid] [--spp 64] [--seeds 4] [--res 64]
                                     [--timing-spp 32] [--out DIR] [--mitsuba-python /work/peerenv/bin/python]

The scenes are tests/bench/scenes/<name>.json (Polar's scene format: a box of homogeneous Henyey–Greenstein
fog, and a density grid of HG smoke, both without a surface, on Lambert floor and wall under a sun and a
sky).  This script converts them to Mitsuba 3 scene dictionaries itself (the shared peer harness has no media):
the fog box becomes a `cube` with a `null` BSDF and an `interior` medium — `homogeneous` (σ_t = density,
the same albedo, `hg` phase) or `heterogeneous` with a `gridvolume` made from the same array (Polar's grid has
its nodes on the bounds' corners, Mitsuba's texels their centres at (i + ½)/N of its unit cube, so the grid's
unit cube is the bounds grown by half a cell on every side; inside the bounds both interpolate the same
nodes trilinearly) — and renders them with Mitsuba's `volpath` (in `llvm_ad_spectral_polarized` under the
`stokes` integrator: its polarised variants treat phase functions as depolarising, and HG is scalar anyway)
in a second interpreter (``--mitsuba-python``, whose environment has Mitsuba; it runs this same file with
``--mitsuba-side``, which imports only numpy, mitsuba and ../shared/peers/render_peer.py).

Output: per scene, S0 (luminance and each of R, G, B) compared with ../shared/peers/compare.py's 8×8-block
z-scores (σ from the ``seeds`` renders on both sides, its variance floor): the share of blocks within 4σ (issue
37 asks ≥ 99 %).  Then, on each scene, the time to equal S0 error: each renderer's wall time per render
(warm: kernels compiled, the first render discarded) times the variance of one render's luminance (mean over
pixels of the across-seed variance), for Polar with Auto transport (scalar here) and full Stokes (its default
sobol sampler) and for Mitsuba's `llvm_ad_rgb` volpath (its fastest) and `llvm_ad_spectral_polarized`, each with
its samplers (``--mitsuba-samplers``); the last column is each row's time to equal error relative to the first
row's (Mitsuba llvm_ad_rgb, independent).  Not part of the test command (needs Mitsuba and minutes).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
SHARED = os.environ.get("POLAR_SHARED", os.path.join(os.path.dirname(REPO), "shared"))
PEERS = os.path.join(SHARED, "peers")
SCENES = os.path.join(HERE, "scenes")
BLOCK, Z_LIMIT = 8, 4.0
MITSUBA_VARIANTS = ("llvm_ad_spectral_polarized", "llvm_ad_rgb")


def load_shared(name: str):
    spec = importlib.util.spec_from_file_location(f"peers_{name}", os.path.join(PEERS, f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def with_resolution(scene: dict, res: int) -> dict:
    return {**scene, "camera": {**scene["camera"], "width": res, "height": res}}


# ----------------------------------------------------------------------------- the Mitsuba side (peer env)


def aabb(obj: dict) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(obj["vertices"], dtype=np.float64)
    return v.min(axis=0), v.max(axis=0)


def mitsuba_medium(mi, interior: dict, obj: dict) -> dict:
    """Polar's interior (albedo + density form, HG phase, optional grid) as a Mitsuba medium."""
    phase = interior["phase"]
    if phase["type"] != "henyey_greenstein" or "scattering" in interior:
        raise ValueError("only {albedo, density} interiors with a henyey_greenstein phase are converted")
    medium = {"albedo": float(interior["albedo"]), "phase": {"type": "hg", "g": float(phase["g"])}}
    if "grid" not in interior:
        return {"type": "homogeneous", "sigma_t": float(interior["density"]), **medium}
    values = np.asarray(interior["grid"]["values"], dtype=np.float32)          # [x][y][z] nodes
    lo, hi = (np.asarray(b, dtype=np.float64) for b in interior["grid"]["bounds"])
    cell = (hi - lo) / (np.array(values.shape) - 1)
    lo_b, hi_b = aabb(obj)
    if not (np.allclose(lo_b, lo) and np.allclose(hi_b, hi)):
        raise ValueError("the grid's bounds must be its bounding box's (outside, Mitsuba clamps where Polar is 0)")
    to_world = mi.ScalarTransform4f().translate((lo - 0.5 * cell).tolist()) @ \
        mi.ScalarTransform4f().scale((cell * np.array(values.shape)).tolist())
    grid = mi.VolumeGrid(np.ascontiguousarray(values.transpose(2, 1, 0)[..., None]))
    return {"type": "heterogeneous", "scale": float(interior["density"]),
            "sigma_t": {"type": "gridvolume", "grid": grid, "raw": True, "to_world": to_world}, **medium}


def mitsuba_scene(mi, peer, scene: dict, variant: str, spp: int, seed: int, sampler: str = "independent") -> dict:
    """The subset of Polar's scene format these scenes use, as a Mitsuba scene dictionary."""
    cam, settings = scene["camera"], scene["render"]
    nested = {"type": "volpath", "max_depth": int(settings["max_depth"]), "rr_depth": int(settings["rr_depth"])}
    d = {"type": "scene",
         "integrator": {"type": "stokes", "nested": nested} if "polarized" in variant else nested,
         "sensor": {"type": "perspective", "fov": float(cam["fov_deg"]), "fov_axis": "x",
                    "near_clip": 1e-3, "far_clip": 1e5,
                    "to_world": mi.ScalarTransform4f().look_at(origin=cam["origin"], target=cam["target"],
                                                               up=cam["up"]),
                    "film": {"type": "hdrfilm", "width": int(cam["width"]), "height": int(cam["height"]),
                             "rfilter": {"type": "box"}, "pixel_format": "rgb", "component_format": "float32"},
                    "sampler": {"type": sampler, "sample_count": int(spp), "seed": int(seed)}}}
    for i, light in enumerate(scene["lights"]):
        if light["type"] == "directional":
            d[f"light{i}"] = {"type": "directional", "direction": light["direction"],
                              "irradiance": float(light["irradiance"])}
        elif light["type"] == "environment":
            d[f"light{i}"] = {"type": "constant", "radiance": float(light["radiance"])}
        else:
            raise ValueError(f"light type {light['type']!r} is not converted")
    for i, obj in enumerate(scene["objects"]):
        material = scene["materials"][obj["material"]]
        if obj.get("alpha") == 0.0 and "interior" in material:
            lo, hi = aabb(obj)
            d[f"obj{i}"] = {"type": "cube", "bsdf": {"type": "null"},
                            "to_world": mi.ScalarTransform4f().translate(((lo + hi) / 2).tolist())
                            @ mi.ScalarTransform4f().scale(((hi - lo) / 2).tolist()),
                            "interior": mitsuba_medium(mi, material["interior"], obj)}
        elif obj["shape"] == "quad" and material["type"] == "lambert":
            d[f"obj{i}"] = {"type": "rectangle", "to_world": peer._quad_to_world(mi, obj),
                            "bsdf": {"type": "diffuse", "reflectance": float(material["albedo"])}}
        else:
            raise ValueError(f"object {i} is not converted")
    return d


def mitsuba_side(job_file: str) -> None:
    """Render one scene with Mitsuba: ``seeds`` renders at ``spp`` after a discarded warm-up; saves the
    Stokes arrays [4 | 1, H, W, 3] as .npy and the wall times as .json next to them."""
    with open(job_file) as f:
        job = json.load(f)
    peer = load_shared("render_peer")
    peer.setup_llvm_env()
    mi, variant = peer.set_variant(job["variant"])
    scene = job["scene"]
    times, files = [], []
    peer.render(mi, mi.load_dict(mitsuba_scene(mi, peer, scene, variant, 4, 999)), 4, 999)    # JIT warm-up
    for seed in range(job["seeds"]):
        loaded = mi.load_dict(mitsuba_scene(mi, peer, scene, variant, job["spp"], seed, job["sampler"]))
        img, seconds = peer.render(mi, loaded, job["spp"], seed)
        path = f"{job['prefix']}__seed{seed}.npy"
        np.save(path, peer.stokes_array(np, img, variant))
        times.append(seconds)
        files.append(path)
    with open(f"{job['prefix']}.json", "w") as f:
        json.dump({"variant": variant, "times": times, "files": files}, f)


# ----------------------------------------------------------------------------- the Polar side


def run_mitsuba(python: str, scene: dict, variant: str, spp: int, seeds: int, prefix: str,
                sampler: str = "independent") -> dict:
    job = f"{prefix}.job.json"
    with open(job, "w") as f:
        json.dump({"scene": scene, "variant": variant, "spp": spp, "seeds": seeds, "prefix": prefix,
                   "sampler": sampler}, f)
    subprocess.run([python, os.path.abspath(__file__), "--mitsuba-side", job], check=True)
    with open(f"{prefix}.json") as f:
        return json.load(f)


def run_polar(scene: dict, spp: int, seeds: int, prefix: str, polarisation: str = "auto") -> dict:
    sys.path.insert(0, REPO)
    from engine.render.renderer import Renderer
    from engine.scene.loader import parse_scene
    data = {**scene, "render": {**scene["render"], "spp": spp, "polarisation": polarisation}}
    Renderer(parse_scene({**data, "render": {**data["render"], "spp": 4, "seed": 999}})).render()   # warm-up
    times, files, transport = [], [], None
    for seed in range(seeds):
        renderer = Renderer(parse_scene({**data, "render": {**data["render"], "seed": seed}}))
        t0 = time.perf_counter()
        result = renderer.render()
        times.append(time.perf_counter() - t0)
        transport = result.stats["transport"]
        path = f"{prefix}__seed{seed}.npy"
        np.save(path, result.stokes().astype(np.float32))
        files.append(path)
    return {"times": times, "files": files, "transport": transport}


def luminance_variance(files: list[str], compare) -> float:
    """Mean over pixels of the across-render variance of one render's S0 luminance."""
    imgs = np.stack([compare.channel(compare.load(f), "Y")[0] for f in files])
    return float(imgs.var(axis=0, ddof=1).mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mitsuba-side", help=argparse.SUPPRESS)
    ap.add_argument("--scenes", default="media_hg_box,media_grid")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--timing-spp", type=int, default=32)
    ap.add_argument("--timing-scenes", default="media_hg_box")
    ap.add_argument("--mitsuba-samplers", default="independent,stratified,multijitter,ldsampler",
                    help="Mitsuba samplers timed (spp a power of 4 suits them all)")
    ap.add_argument("--out", default=os.path.join(REPO, "out", "media_peer"))
    ap.add_argument("--mitsuba-python", default="/work/peerenv/bin/python")
    args = ap.parse_args()
    if args.mitsuba_side:
        mitsuba_side(args.mitsuba_side)
        return
    sys.path.insert(0, REPO)
    from tests.bench.peer_compare import compare_sides
    compare = load_shared("compare")
    os.makedirs(args.out, exist_ok=True)
    print(f"machine load before: {os.getloadavg()}")
    print(f"{'scene':14s} {'channel':7s} {'Polar S0':>9s} {'Mitsuba S0':>10s} {'rms z':>6s} {'max|z|':>7s} "
          f"{'within 4σ':>9s}")
    for name in filter(None, args.scenes.split(",")):
        with open(os.path.join(SCENES, f"{name}.json")) as f:
            scene = with_resolution(json.load(f), args.res)
        prefix = os.path.join(args.out, f"{name}__{args.res}__{args.spp}spp")
        ours = run_polar(scene, args.spp, args.seeds, prefix + "__polar")
        theirs = run_mitsuba(args.mitsuba_python, scene, MITSUBA_VARIANTS[0], args.spp, args.seeds,
                             prefix + "__mitsuba")
        for ch in ("Y", "R", "G", "B"):
            s0 = compare_sides(ours["files"], theirs["files"], ch, args.spp * args.seeds,
                               args.spp * args.seeds, compare)["S0"]
            print(f"{name:14s} {ch:7s} {s0[0]:9.5f} {s0[1]:10.5f} {s0[2]:6.2f} {s0[3]:7.2f} {100 * s0[4]:8.1f}%")
    print(f"\ntime to equal S0 error ({args.timing_spp} spp, {args.seeds} seeds, {args.res}², warm)")
    print(f"{'scene':14s} {'renderer':44s} {'s/render':>9s} {'var(Y)':>10s} {'s × var':>10s} {'× first':>8s}")
    for name in filter(None, args.timing_scenes.split(",")):
        with open(os.path.join(SCENES, f"{name}.json")) as f:
            scene = with_resolution(json.load(f), args.res)
        prefix = os.path.join(args.out, f"{name}__{args.res}__{args.timing_spp}spp__timing")
        rows = {}
        for variant in reversed(MITSUBA_VARIANTS):
            for sampler in args.mitsuba_samplers.split(","):
                r = run_mitsuba(args.mitsuba_python, scene, variant, args.timing_spp, args.seeds,
                                f"{prefix}__{variant}__{sampler}", sampler)
                rows[f"Mitsuba {variant} {sampler}"] = r
        for transport in ("auto", "full"):
            r = run_polar(scene, args.timing_spp, args.seeds, f"{prefix}__polar_{transport}", transport)
            rows[f"Polar {transport} ({r['transport']})"] = r
        base = None
        for label, r in rows.items():
            t, v = float(np.median(r["times"])), luminance_variance(r["files"], compare)
            base = base or t * v
            print(f"{name:14s} {label:44s} {t:9.3f} {v:10.3e} {t * v:10.3e} {t * v / base:8.2f}")
    print(f"machine load after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
