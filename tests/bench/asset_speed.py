"""Polar against Cycles on the real-asset suite: noise × time of S0 at equal samples, per asset.

    python tests/bench/asset_speed.py [--assets BoomBox,UnlitTest] [--lighting lamps,hdri] [--spp 16]
                                      [--seeds 32] [--res 96] [--json] [--light-tree off|on]
                                      [--figure docs/images/assets.png [--figure-lighting hdri]]

Runs each case of tests/blender/test_real_assets.py (tests/support/asset_parity.run_case: the glTF
imported by Blender, framed, lit, rendered by Cycles with the parity settings and by Polar through the
extension's exporter, both at ``--spp`` samples with ``--seeds`` seeds) and prints one line per case,
the two renderers side by side.  ``--light-tree on`` renders both with Cycles' Light Tree on (Cycles' default, and
what issue 36's race against Cycles asks for; Polar reads the switch as F12 does: its "on"); the default ``off`` is
the parity settings (issue 33's benchmark).  The renderers take turns seed by seed (asset_parity.render_alternated:
Cycles then Polar for seed 0, Polar then Cycles for seed 1, …), so the two renders of a seed share the load of
this shared 2-core VM: one side's seconds move ±15–30 % between identical runs, the ratio of a seed's pair much
less.  ``--extra N`` adds N timing-only pairs (seeds re-rendered, images not kept) when few seeds give few pairs;
``--sequential`` times as before 2026-12-07 (all Cycles renders, then all Polar renders; means, no spread).

* seconds per render, warm, on both sides: the median over seeds 1, 2, … (the first seed's renders left out:
  Cycles syncs the scene there, 0.9 s against 0.03–0.1 s for a later render of these small images; Polar's
  first render after the export is left out alike); Cycles' render call includes its EXR write. The
  one-time costs are printed beside them (Cycles: the first render's excess over a warm one, scene sync;
  Polar: the export through the extension plus its first render's excess). The ratio races warm renders:
  what an animation or a re-render pays per frame;
* σ² = mean over the asset's pixels of the per-pixel variance of the S0 luminance between the seeds (32 by
  default since 2026-12-08: with 16, SpecGlossEmission lamps' σ² ratio read 1.30 in one run and 0.90 with 32);
* the share of σ² in the top 1 % of pixels (Cycles / Polar) and the ratio Polar ÷ Cycles of σ² over the other
  99 %: a share near 1 means a few fireflies carry σ², and a few seeds' ratio is then luck (a warning line
  says so; Sunglasses under lamps read 13.5× with seeds 0–3 and 0.6× with 16, docs/benchmarks.md);
* **var × time ratio** = (σ²_Polar ÷ σ²_Cycles) · median over the warm pairs of t_Polar ÷ t_Cycles: how much
  longer Polar needs for Cycles' noise (< 1: Polar is more efficient);
* **IQR** (new 2026-12-07): the interquartile range of that ratio over the warm pairs (σ² ratio × each pair's
  time ratio), the spread of the time measurement; the σ² ratio is the seeds' and has no spread here (its luck is
  the top-1 % columns').  Between two runs of one tree each side's seconds moved ±18–23 %, the ratio ±5–10 %
  (medians; docs/benchmarks/real-assets.md).  The IQR is the pairs' spread within the run, not a bound between
  runs: a change of background load slows Cycles' two threads more than Polar's, and on a loaded machine every
  ratio falls (compare runs at similar load averages).  ``--json`` adds "var_time_iqr", "var_time_range"
  (min–max over the pairs) and "pairs";
* the parity numbers of the case (blocks passing the rule, luminance ratio Polar ÷ Cycles);
* the load average before and after (the machine may be shared: the ratios race the two renderers in one run).

``--selections power,cycles`` races Polar's light choices (Scene.light_selection) on each case instead: one Cycles
render per seed, the scene exported once, and Polar rendered with each choice in turn, seed by seed (the load
falls on each alike); one line per choice, then the var × time ratio of each later choice ÷ the first.

A case whose scene Polar refuses prints the reason.  ``--figure PATH`` also writes, per asset, a PNG of
Cycles | Polar S0 | Polar DoLP under ``--figure-lighting`` into a folder beside PATH and stacks them
into PATH (the documentation figure docs/images/assets.png).  Runs in the bpy module; not part of the
test command.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)


#: above this share of σ² in the top 1 % of pixels (either renderer) the line warns that σ² is fireflies' luck
FIREFLY_SHARE = 0.5


def warm(times):
    """(mean seconds of the renders after the first, the first one's excess over that mean)."""
    rest = times[1:] or times
    mean = sum(rest) / len(rest)
    return mean, max(times[0] - mean, 0.0)


def run_selections(name, lighting, selections, spp, seeds, width=None, height=None, bounces=8):
    """{selection: CaseReport} of one asset case: Cycles once, Polar with each Scene.light_selection of
    ``selections``, the choices alternating seed by seed (tests/support/asset_parity.run_case's steps)."""
    import dataclasses
    import time

    import numpy as np

    from tests.support import asset_parity as ap
    from polar_render.engine.render.renderer import Renderer
    asset = ap.CATALOGUE[name]
    width, height = width or asset.size[0], height or asset.size[1]
    scene = ap.build(asset, lighting, width, height)
    hit = ap.coverage(scene, width, height)
    times_c = []
    with tempfile.TemporaryDirectory() as tmp:
        cyc = ap.render_cycles(scene, spp, seeds, bounces, tmp, times_c)
    t = time.perf_counter()
    renderer, settings, warnings = ap.export_polar(scene, spp, bounces)
    export = time.perf_counter() - t
    renderers = {s: Renderer(dataclasses.replace(renderer.scene, light_selection=s)) for s in selections}
    images, times = {s: [] for s in selections}, {s: [] for s in selections}
    for seed in range(seeds):
        for s in (selections if seed % 2 == 0 else selections[::-1]):     # each choice first on every other seed
            t = time.perf_counter()
            images[s].append(renderers[s].render(dataclasses.replace(settings, seed=seed)).stokes())
            times[s].append(time.perf_counter() - t)
    reports = {}
    for s in selections:
        r = reports[s] = ap.CaseReport(asset.name, lighting, spp, seeds, width, height, warnings=list(warnings))
        r.seconds = {"cycles_each": times_c, "polar_each": times[s], "export": export}
        ap.compare(cyc, np.array(images[s])[:, 0], hit, r)
    return reports


def main(argv=None):
    from tests.support import asset_parity as ap
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--assets", default=",".join(ap.CATALOGUE))
    p.add_argument("--lighting", default=",".join(ap.LIGHTINGS))
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--seeds", type=int, default=32,
                   help="renders per renderer (σ² between them); fewer make σ² ratios the fireflies' luck")
    p.add_argument("--res", type=int, default=0, help="square resolution (0: each asset's own, 96 × 96 mostly)")
    p.add_argument("--json", action="store_true", help="also print the reports as JSON lines")
    p.add_argument("--figure", default="", help="write the Cycles | Polar S0 | Polar DoLP figure to this PNG")
    p.add_argument("--figure-lighting", default="hdri", choices=ap.LIGHTINGS)
    p.add_argument("--extra", type=int, default=0, help="timing-only render pairs beyond the seeds' (alternated)")
    p.add_argument("--sequential", action="store_true",
                   help="time all Cycles renders, then all Polar ones (the timing before 2026-12-07; no spread)")
    p.add_argument("--light-tree", default="off", choices=("off", "on"),
                   help="Cycles' Light Tree (Polar reads the switch as F12 does): off = the parity settings "
                        "(issue 33's benchmark), on = Cycles' default (issue 36's race against Cycles)")
    p.add_argument("--selections", default="", help="Polar's light choices to race, e.g. power,cycles "
                                                     "(Scene.light_selection; default: the exporter's)")
    a = p.parse_args(argv)

    import bpy  # noqa: F401  (the bpy module must be importable)
    from tests.blender_support import load_addon
    load_addon()
    names = [n for n in a.assets.split(",") if n]
    lightings = [x for x in a.lighting.split(",") if x]
    panels = tempfile.mkdtemp(prefix="asset_panels_") if a.figure else None
    print(f"load average {' / '.join(f'{v:.2f}' for v in os.getloadavg())} ({os.cpu_count()} cores); "
          f"Cycles' Light Tree {a.light_tree}", flush=True)
    print(f"{'asset':20s} {'light':5s} | {'Cycles s':>8s} {'σ²':>9s} {'sync s':>7s} | {'Polar s':>8s} {'σ²':>9s} "
          f"{'setup s':>7s} | {'var×time P÷C':>12s} {'IQR':>11s} | parity")
    for name in names:
        for lighting in lightings:
            out = panels if (panels and lighting == a.figure_lighting) else None
            res = (a.res, a.res) if a.res else (None, None)
            if a.selections:
                selections = a.selections.split(",")
                reports = run_selections(name, lighting, selections, a.spp, a.seeds, *res)
                for s in selections:
                    line(f"{name[:20 - len(s) - 1]} {s}", lighting, reports[s], a.json)
                first = var_time(reports[selections[0]])
                print(f"{'':26s}  var × time " + ", ".join(f"{s} ÷ {selections[0]} {var_time(reports[s]) / first:.2f}"
                                                           for s in selections[1:]), flush=True)
                continue
            r = ap.run_case(name, lighting, spp=a.spp, seeds=a.seeds, width=res[0], height=res[1], out_dir=out,
                            alternate=not a.sequential, extra=a.extra, light_tree=a.light_tree == "on")
            if r.error:
                print(f"{name:20s} {lighting:5s} | Polar refused the scene: {r.error}")
                continue
            line(name, lighting, r, a.json)
    print(f"load average {' / '.join(f'{v:.2f}' for v in os.getloadavg())} at the end", flush=True)
    if a.figure:
        done = [n for n in names if os.path.exists(os.path.join(panels, f"{n}_{a.figure_lighting}.png"))]
        print(ap.figure(panels, a.figure, done, a.figure_lighting))


def seconds(r):
    """(warm Cycles s, Cycles sync s, warm Polar s, Polar first-render excess s, timing or None) of a CaseReport:
    medians and asset_parity.timing of the pairs when the renders alternated, else warm's means."""
    tc, sync = warm(r.seconds["cycles_each"])
    tp, first = warm(r.seconds["polar_each"])
    if not r.seconds.get("alternated"):
        return tc, sync, tp, first, None
    from tests.support import asset_parity as ap
    t = ap.timing(r.seconds["cycles_each"], r.seconds["polar_each"])
    each_c, each_p = r.seconds["cycles_each"], r.seconds["polar_each"]
    return t["cycles"], max(each_c[0] - t["cycles"], 0.0), t["polar"], max(each_p[0] - t["polar"], 0.0), t


def var_time(r):
    """(σ²_Polar · t_Polar) ÷ (σ²_Cycles · t_Cycles) of a CaseReport, warm seconds (the pairs' median time ratio
    when the renders alternated)."""
    tc, _, tp, _, t = seconds(r)
    vc, vp = r.noise["cycles"], r.noise["polar"]
    if vc * tc <= 0:
        return float("inf")
    return vp / vc * t["ratio"] if t else (vp * tp) / (vc * tc)


def line(name, lighting, r, as_json=False):
    """Print one case's line (and its JSON with ``as_json``)."""
    tc, sync, tp, first, t = seconds(r)
    setup = r.seconds["export"] + first
    vc, vp = r.noise["cycles"], r.noise["polar"]
    ratio = var_time(r)
    k = vp / vc if vc > 0 else float("inf")
    iqr = f"{k * t['q1']:5.2f}–{k * t['q3']:5.2f}" if t else f"{'–':>11s}"
    (sc, rc), (sp, rp) = r.tails["cycles"], r.tails["polar"]
    print(f"{name:20s} {lighting:5s} | {tc:8.3f} {vc:9.2e} {sync:7.2f} | {tp:8.3f} {vp:9.2e} {setup:7.2f} "
          f"| {ratio:12.2f} {iqr:>11s} | {r.passed}/{r.blocks} blocks, Y {r.luminance_ratio:.3f} "
          f"| top 1 %: {sc:.2f} / {sp:.2f} of σ², rest P÷C {rp / rc if rc > 0 else float('inf'):.2f}",
          flush=True)
    if max(sc, sp) > FIREFLY_SHARE:
        print(f"{'':26s}  σ² is mostly fireflies ({max(sc, sp):.0%} in the top 1 % of pixels): with "
              f"{r.seeds} seeds its ratio is luck; rerun with more --seeds", flush=True)
    if as_json:
        spread = {"var_time_iqr": [k * t["q1"], k * t["q3"]], "var_time_range": [k * t["lo"], k * t["hi"]],
                  "pairs": t["n"]} if t else {}
        print(json.dumps({"asset": name, "lighting": lighting, "spp": r.spp, "seeds": r.seeds,
                          "cycles_s": tc, "polar_s": tp,
                          "cycles_sync_s": sync, "polar_setup_s": setup, "cycles_var": vc, "polar_var": vp,
                          "var_time_ratio": ratio, **spread, "top1_share": [sc, sp], "rest_var": [rc, rp],
                          "blocks": r.blocks, "passed": r.passed,
                          "luminance_ratio": r.luminance_ratio, "warnings": r.warnings}))


if __name__ == "__main__":
    main()
