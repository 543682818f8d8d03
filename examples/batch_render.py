"""Render a .blend file with Polar from the command line, without Blender's UI.

    python examples/batch_render.py FILE.blend [--frames 1-10 | --frame 3] [--output DIR]
                                    [--samples N] [--seed S] [--polarisation auto|full|linear|off]
                                    [--scheduler tcp://HOST:8786 [--distribute-frames]]

Uses the ``bpy`` module (pip install bpy==5.0.1, or any Blender the README's table lists) and
Polar from this checkout (or, with ``--installed``, the extension installed in Blender's user
folder).  Writes one multilayer EXR per frame (``DIR/<name>_0001.exr`` …) with the view layer's
passes: Combined, S0, S1, S2, S3 (colour) and DoP, DoLP, AoLP, DoCP (value).  A render error
(missing camera, bad material input, …) is printed and the exit status is 1; finished frames are kept.

With ``--scheduler`` every frame's samples are traced on the Dask cluster (the image equals a local
render); with ``--distribute-frames`` as well, whole frames are farmed out instead: each frame runs
this script on a worker (the workers need bpy, this checkout and the .blend at the same paths, e.g.
on a shared file system).
"""

import argparse
import atexit
import importlib.util
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def enable_polar(installed: bool):
    """Enable Polar (the installed extension, or this checkout) and return its package module.

    It is disabled again when the process exits: Blender 4.5 hangs at exit with an add-on still
    registered that its add-on manager did not load."""
    import bpy  # noqa: F401 — sets up Blender's module paths
    for name in ("polar_render", "bl_ext.user_default.polar_render"):
        if name in sys.modules:
            return sys.modules[name]
    if installed:
        import addon_utils
        addon_utils.enable("bl_ext.user_default.polar_render", default_set=True)
        atexit.register(addon_utils.disable, "bl_ext.user_default.polar_render", default_set=False)
        return sys.modules["bl_ext.user_default.polar_render"]
    spec = importlib.util.spec_from_file_location("polar_render", os.path.join(ROOT, "__init__.py"),
                                                  submodule_search_locations=[ROOT])
    module = importlib.util.module_from_spec(spec)
    sys.modules["polar_render"] = module
    spec.loader.exec_module(module)
    module.register()
    atexit.register(module.unregister)
    return module


def _render_one_frame(script, blend, frame, output, extra):
    """Run on a Dask worker: this script for one frame, in its own process (bpy state stays clean)."""
    import subprocess
    proc = subprocess.run([sys.executable, script, blend, "--frame", str(frame), "--output", output, *extra],
                          capture_output=True, text=True)
    return frame, proc.returncode, proc.stdout.strip().splitlines()[-1:] or proc.stderr.strip().splitlines()[-1:]


def distribute_frames(args):
    """Frame-level distribution: one task per frame on the Dask cluster; returns the exit status."""
    from distributed import Client, as_completed
    frames = parse_frames(args.frames) if args.frames else [args.frame or 1]
    extra = []
    for name in ("samples", "seed", "polarisation"):
        if getattr(args, name) is not None:
            extra += [f"--{name}", str(getattr(args, name))]
    client = Client(args.scheduler)
    try:
        futures = [client.submit(_render_one_frame, os.path.abspath(__file__), os.path.abspath(args.blend), f,
                                 os.path.abspath(args.output), extra, pure=False) for f in frames]
        status = 0
        for future in as_completed(futures):
            frame, code, last = future.result()
            if code != 0:
                print(f"error: frame {frame}: {' '.join(last)}", file=sys.stderr)
                status = 1
            else:
                print(*last)
        return status
    finally:
        client.close()


def parse_frames(text):
    if "-" in text:
        a, b = text.split("-", 1)
        return list(range(int(a), int(b) + 1))
    return [int(text)]


def main(argv=None):
    ap = argparse.ArgumentParser(description="Render a .blend with Polar (bpy module)")
    ap.add_argument("blend")
    ap.add_argument("--frames", help="frame range A-B (default: the file's current frame)")
    ap.add_argument("--frame", type=int)
    ap.add_argument("--output", default="out/batch", help="output folder")
    ap.add_argument("--samples", type=int)
    ap.add_argument("--seed", type=int)
    ap.add_argument("--polarisation", choices=("auto", "full", "linear", "off"))
    ap.add_argument("--installed", action="store_true", help="use the installed extension")
    ap.add_argument("--scheduler", help="Dask scheduler address: trace every frame's samples on the cluster")
    ap.add_argument("--distribute-frames", action="store_true", help="with --scheduler: one frame per worker task")
    args = ap.parse_args(argv)
    if not os.path.exists(args.blend):
        print(f"error: {args.blend} does not exist", file=sys.stderr)
        return 2

    if args.scheduler and args.distribute_frames:
        return distribute_frames(args)
    polar = enable_polar(args.installed)     # register before opening the file, so its engine setting resolves
    if args.scheduler:
        from importlib import import_module
        pkg = "bl_ext.user_default.polar_render" if args.installed else "polar_render"
        import_module(pkg + ".polar_addon.render_engine").CONTROL.scheduler = args.scheduler
    import bpy
    bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend))
    scene = bpy.context.scene
    scene.render.engine = "POLAR"
    if args.samples is not None:
        scene.polar.samples = args.samples
    if args.seed is not None:
        scene.polar.seed = args.seed
    if args.polarisation:
        scene.polar.polarisation = args.polarisation.upper()
    polar.polar_addon.compat.set_multilayer_exr(scene.render.image_settings)
    frames = parse_frames(args.frames) if args.frames else [args.frame or scene.frame_current]
    os.makedirs(args.output, exist_ok=True)
    stem = os.path.splitext(os.path.basename(args.blend))[0]
    for frame in frames:
        scene.frame_set(frame)
        path = os.path.join(os.path.abspath(args.output), f"{stem}_{frame:04d}.exr")
        scene.render.filepath = path
        try:
            bpy.ops.render.render(write_still=True)
        except RuntimeError as e:
            print(f"error: frame {frame}: {e}", file=sys.stderr)
            return 1
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
