"""Command line: ``python -m engine render …`` and ``python -m engine mueller …``.

User mistakes (bad scene files, parameters out of range) end with a one-line
message naming the field and exit status 2, never a traceback.  Ctrl-C during
a render stops after the current batch and writes the finished samples.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time

import numpy as np

from .errors import SceneError


class ProgressBar:
    """A one-line progress bar on stderr (only redrawn when it changes visibly)."""

    def __init__(self, label: str, stream=sys.stderr, width: int = 30):
        self.label, self.stream, self.width = label, stream, width
        self.t0 = time.perf_counter()
        self._last = None

    def __call__(self, fraction: float, stats: dict) -> None:
        filled = int(round(fraction * self.width))
        elapsed = time.perf_counter() - self.t0
        eta = elapsed * (1 - fraction) / fraction if fraction > 0 else 0.0
        rate = stats.get("samples", 0) / max(elapsed, 1e-9) / 1e3
        line = (f"\r{self.label} [{'#' * filled}{'.' * (self.width - filled)}] {100 * fraction:5.1f}% "
                f"{elapsed:6.1f}s elapsed, {eta:6.1f}s left, {rate:7.1f} ksamples/s")
        if line != self._last:
            self.stream.write(line)
            self.stream.flush()
            self._last = line

    def close(self):
        if self._last is not None:
            self.stream.write("\n")
            self.stream.flush()


def _render(args) -> int:
    from .output.exr import write_stokes_exr
    from .output.previews import write_previews
    from .render.renderer import Renderer
    from .scene.loader import load_scene, parse_settings

    scene = load_scene(args.scene)
    st = scene.settings
    overrides = {k: v for k, v in (("spp", args.spp), ("seed", args.seed), ("max_depth", args.max_depth),
                                   ("spectral", args.spectral), ("polarisation", args.polarisation),
                                   ("wavelength_nm", args.wavelength_nm), ("simplify", args.simplify),
                                   ("reduce_spectral", args.reduce_spectral)) if v is not None}
    if overrides:
        merged = {**{k: getattr(st, k) for k in ("spp", "max_depth", "rr_depth", "seed", "spectral",
                                                  "wavelength_nm", "polarisation", "batch_rays", "threads",
                                                  "reduce_spectral", "simplify")}, **overrides}
        st = parse_settings(merged, "option")
        scene.settings = st
    out = args.output
    if not out.lower().endswith(".exr"):
        raise SceneError("-o", f"the output must be an .exr file, got {out!r}")
    out_dir = os.path.dirname(os.path.abspath(out))
    try:
        os.makedirs(out_dir, exist_ok=True)
    except OSError as e:
        raise SceneError("-o", f"cannot create the output folder {out_dir!r}: {e.strerror}") from None

    resume_film = None
    if args.resume:
        resume_film, st = _resume_state(args, scene, st)
        scene.settings = st
    renderer = Renderer(scene)
    cam = scene.camera
    print(f"polar: {os.path.basename(args.scene)}: {cam.width}×{cam.height}, {st.spp} spp, "
          f"{len(renderer.compiled.faces)} triangles, {len(renderer.lights)} lights, "
          f"polarisation {st.polarisation}, {st.spectral}"
          f"{'' if st.spectral == 'spectral' else f' at {st.wavelength_nm:g} nm'}", file=sys.stderr)
    stop = {"requested": False}

    def on_interrupt(signum, frame):
        # First Ctrl-C: finish the current batch and write what is done; a second one aborts.
        stop["requested"] = True
        signal.signal(signal.SIGINT, signal.default_int_handler)

    previous = signal.signal(signal.SIGINT, on_interrupt)
    bar = None if args.quiet else ProgressBar("rendering")
    try:
        if args.scheduler:
            if resume_film is not None:
                raise SceneError("--scheduler", "cannot be combined with --resume yet")
            from .render.distributed import render_distributed
            try:
                result = render_distributed(scene, args.scheduler, st, progress=bar,
                                            should_stop=lambda: stop["requested"])
            except OSError as e:
                raise SceneError("--scheduler", f"cannot reach the Dask scheduler at {args.scheduler}: {e}") from None
            except RuntimeError as e:
                raise SceneError("--scheduler", str(e)) from None
        else:
            result = renderer.render(st, progress=bar, should_stop=lambda: stop["requested"], resume=resume_film)
    finally:
        signal.signal(signal.SIGINT, previous)
        if bar is not None:
            bar.close()
    if result.cancelled:
        print(f"polar: interrupted — writing the {result.stats['samples']} finished samples", file=sys.stderr)
    stats = result.stats
    print(f"polar: transport: {stats['transport_reason']}; spectral: {stats['spectral']}; "
          f"kernels: {stats.get('kernels', '?')}", file=sys.stderr)
    for why in stats.get("simplified", []):
        print(f"polar: simplified: {why}", file=sys.stderr)
    film = result.film
    spp_image = film.spp_image()
    meta = {"polar.spp": int(st.spp), "polar.complete": int(not result.cancelled),
            "polar.spp_min": int(spp_image.min()), "polar.spp_max": int(spp_image.max()),
            "polar.seed": int(st.seed), "polar.max_depth": int(st.max_depth), "polar.spectral": st.spectral,
            "polar.polarisation": stats["transport"], "polar.transport_reason": stats["transport_reason"],
            "polar.scene": os.path.basename(args.scene),
            "polar.render_seconds": float(stats["seconds"]), "polar.nonfinite_samples": int(stats["nonfinite"]),
            "polar.kernels": stats.get("kernels", ""), "polar.simplified": "; ".join(stats.get("simplified", []))}
    if st.spectral == "mono":
        meta["polar.wavelength_nm"] = float(st.wavelength_nm)
    extra = {"spp": spp_image.astype("uint32")}
    if args.stderr:
        se = film.stderr_luminance()
        for i in range(4):
            extra[f"S{i}.Y.stderr"] = se[i].astype("float32")
    write_stokes_exr(out, result.stokes(), metadata=meta, extra=extra)
    written = [out]
    if not args.no_previews:
        written += write_previews(os.path.splitext(out)[0], result.stokes(), exposure=args.exposure)
    msamples = stats["samples"] / max(stats["seconds"], 1e-9) / 1e6
    print(f"polar: {stats['samples']} samples in {stats['seconds']:.2f} s ({msamples:.3f} Msamples/s), "
          f"{stats['rays']} rays + {stats['shadow_rays']} shadow rays"
          f"{'; dropped non-finite samples: ' + str(stats['nonfinite']) if stats['nonfinite'] else ''}",
          file=sys.stderr)
    for path in written:
        print(path)
    return 130 if result.cancelled else 0


def _read_polar_exr(path, field):
    """(stokes, channels, header) of a Stokes EXR, or a SceneError naming ``field``."""
    from .output.exr import read_stokes_exr
    if not os.path.exists(path):
        raise SceneError(field, f"{path!r} does not exist")
    try:
        return read_stokes_exr(path)
    except (ValueError, OSError) as e:
        raise SceneError(field, f"{path!r} is not a Polar Stokes EXR: {e}") from None


def _resume_state(args, scene, st):
    """(Film of the finished samples, settings) to continue the render stored in ``args.resume``."""
    import copy

    from .render.film import film_from_stokes

    stokes, channels, header = _read_polar_exr(args.resume, "--resume")
    if "spp" not in channels or "polar.seed" not in header:
        raise SceneError("--resume", f"{args.resume!r} has no per-pixel sample counts (not written by Polar)")
    H, W = stokes.shape[1:3]
    if (W, H) != (scene.camera.width, scene.camera.height):
        raise SceneError("--resume", f"{args.resume!r} is {W}×{H} but the scene renders "
                                     f"{scene.camera.width}×{scene.camera.height}")
    st = copy.copy(st)
    if args.seed is not None and args.seed != header["polar.seed"]:
        raise SceneError("--seed", f"must be the resumed render's seed ({header['polar.seed']}) to continue it")
    st.seed = int(header["polar.seed"])
    if args.spp is None:
        st.spp = int(header["polar.spp"])
    for key in ("polarisation", "spectral"):
        stored = header.get(f"polar.{key}")
        if stored is not None and key == "spectral" and stored != st.spectral:
            raise SceneError("--resume", f"the stored render is {stored!r}, this one {st.spectral!r}")
    spp = channels["spp"].astype(np.int64)
    if spp.max() > st.spp:
        raise SceneError("--spp", f"must be at least the samples already done ({int(spp.max())})")
    stderr = np.stack([channels[f"S{i}.Y.stderr"] for i in range(4)]) if "S0.Y.stderr" in channels else None
    return film_from_stokes(stokes, spp, stderr), st


def _parse_params(pairs):
    params = {}
    for item in pairs or []:
        if "=" not in item:
            raise SceneError("--param", f"must look like NAME=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        params[key.strip()] = value.strip()
    return params


def _mueller(args) -> int:
    from .materials.catalogue import make_model
    from .materials.evaluate import mueller_at

    for name, v, lo, hi in (("--theta-i", args.theta_i, 0, 90), ("--theta-o", args.theta_o, 0, 90),
                            ("--wavelength-nm", args.wavelength_nm, 360, 830)):
        if not (lo <= v <= hi):
            raise SceneError(name, f"must be in [{lo}, {hi}], got {v:g}")
    model = make_model(args.model, _parse_params(args.param))
    result = mueller_at(model, args.theta_i, args.theta_o, args.phi_o, args.wavelength_nm, args.basis)
    result.update(model=args.model, params=_parse_params(args.param),
                  geometry={"theta_i_deg": args.theta_i, "theta_o_deg": args.theta_o, "phi_o_deg": args.phi_o,
                            "wavelength_nm": args.wavelength_nm})
    print(json.dumps(result))
    return 0


def _polariser(args) -> int:
    import numpy as np

    from .output.colormaps import tonemap
    from .output.png import write_png
    from .postprocess.filters import apply_filter, filter_row
    from .postprocess.sheets import contact_sheet

    stokes, _, _ = _read_polar_exr(args.exr, "EXR")
    if not (0.0 <= args.extinction <= 1.0):
        raise SceneError("--extinction", f"must be in [0, 1], got {args.extinction:g}")

    def filtered(angle):
        row = filter_row(args.type, angle, args.extinction, args.retarder_angle, args.retardance)
        return apply_filter(stokes, row)

    out = args.output
    os.makedirs(os.path.dirname(os.path.abspath(out)) or ".", exist_ok=True)
    if args.sweep is not None:
        try:
            start, stop, step = (float(v) for v in args.sweep.split(":"))
        except ValueError:
            raise SceneError("--sweep", f"must look like START:STOP:STEP in degrees, got {args.sweep!r}") from None
        if step <= 0 or stop < start:
            raise SceneError("--sweep", "needs STEP > 0 and STOP ≥ START")
        angles = list(np.arange(start, stop + 1e-9, step))
        tiles = [tonemap(filtered(a), args.exposure) for a in angles]
        write_png(out, contact_sheet(tiles, [f"{a:g}" for a in angles]))
    elif out.lower().endswith(".exr"):
        from .output.exr import write_stokes_exr
        img = filtered(args.angle)
        unpolarised = np.zeros_like(stokes)
        unpolarised[0] = img
        write_stokes_exr(out, unpolarised, metadata={"polar.filter": args.type, "polar.filter_angle_deg": args.angle})
    else:
        write_png(out, tonemap(filtered(args.angle), args.exposure))
    print(out)
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m engine", description="Polar: polarised spectral path tracer")
    sub = ap.add_subparsers(dest="command", required=True)

    r = sub.add_parser("render", help="render a scene file to a Stokes EXR (+ PNG previews)")
    r.add_argument("scene", help="scene JSON (engine format or a shared/peers scene)")
    r.add_argument("-o", "--output", required=True, help="output .exr path")
    r.add_argument("--spp", type=int, help="samples per pixel (default: the scene's)")
    r.add_argument("--seed", type=int, help="random seed (default: the scene's)")
    r.add_argument("--max-depth", type=int, help="maximum path segments (1 = emitters only)")
    r.add_argument("--spectral", choices=("spectral", "mono"), help="4 wavelengths per path or one")
    r.add_argument("--wavelength-nm", type=float, help="wavelength of --spectral mono (nm)")
    r.add_argument("--polarisation", choices=("auto", "full", "linear", "off"),
                   help="auto (default: the cheapest exact transport), full 4×4, linear 3×3 or scalar")
    r.add_argument("--reduce-spectral", choices=("auto", "exact", "off"),
                   help="where no material depends on λ: auto (RGB with exact light colours), exact "
                        "(sampled λ, one Mueller product per path) or off")
    r.add_argument("--simplify", choices=("auto", "off"),
                   help="auto (default): skip layered coats that are index-matched and clear; off: keep all")
    r.add_argument("--exposure", type=float, default=0.0, help="preview exposure in stops")
    r.add_argument("--no-previews", action="store_true", help="write only the EXR")
    r.add_argument("--stderr", action="store_true", help="also write per-pixel standard errors")
    r.add_argument("--resume", metavar="EXR", help="continue the (interrupted) render stored in this EXR")
    r.add_argument("--scheduler", metavar="ADDRESS", help="render on a Dask cluster, e.g. tcp://host:8786 "
                                                          "(same image as a local render)")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=_render)

    from .materials.catalogue import MODEL_PARAMETERS, parameter_help   # the declared models and parameters
    m = sub.add_parser("mueller", help="print one model's Mueller BRDF at one geometry as JSON",
                       epilog=parameter_help(), formatter_class=argparse.RawDescriptionHelpFormatter)
    m.add_argument("--model", required=True, help=" | ".join(MODEL_PARAMETERS))
    m.add_argument("--param", action="append", metavar="NAME=VALUE", help="model parameter (repeatable)")
    m.add_argument("--theta-i", type=float, required=True, help="incidence angle (deg)")
    m.add_argument("--theta-o", type=float, required=True, help="viewing angle (deg)")
    m.add_argument("--phi-o", type=float, default=0.0, help="viewing azimuth (deg), 0 = forward side")
    m.add_argument("--wavelength-nm", type=float, default=550.0, help="wavelength (nm)")
    m.add_argument("--basis", choices=("sp", "scattering"), default="sp", help="Stokes basis of the result")
    m.set_defaults(func=_mueller)

    p = sub.add_parser("polariser", help="what a virtual polarising filter would show, from a rendered EXR")
    p.add_argument("exr", help="a Stokes EXR written by `render`")
    p.add_argument("-o", "--output", required=True, help="output .png (tonemapped) or .exr (linear)")
    p.add_argument("--type", choices=("linear", "circular-right", "circular-left", "retarder"), default="linear")
    p.add_argument("--angle", type=float, default=0.0,
                   help="transmission axis in degrees, from image right towards image up")
    p.add_argument("--extinction", type=float, default=0.0, help="t_min/t_max of the polariser (0 = ideal)")
    p.add_argument("--retarder-angle", type=float, default=45.0, help="fast axis of the retarder (deg)")
    p.add_argument("--retardance", type=float, default=90.0, help="retardance of the retarder (deg)")
    p.add_argument("--sweep", metavar="START:STOP:STEP", help="contact sheet of polariser angles, e.g. 0:180:15")
    p.add_argument("--exposure", type=float, default=0.0, help="PNG exposure in stops")
    p.set_defaults(func=_polariser)
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except SceneError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\ninterrupted", file=sys.stderr)
        return 130
