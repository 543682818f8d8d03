"""The polariser previews of the user guide: a lake under the polarised sky, an LCD screen behind
polarised sunglasses, a car windscreen in daylight — each rendered once and seen through an ideal linear
polariser at 0°, 45°, 90° and 135° (from image right towards image up) — and hills in Rayleigh haze and murky
water (participating media, issue 37) at 0° and 90°.

    python examples/polariser_previews.py [--spp 256] [--out docs/images] [--scenes media_haze,media_underwater]

Runs ``python -m engine render`` on examples/<name>.json and ``python -m engine polariser --sweep …`` on each
result; writes <name>.png into --out.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# name: (polariser sweep, exposure added to --exposure)
SCENES = {"daylight_water": ("0:135:45", 0.0), "lcd_sunglasses": ("0:135:45", 0.0), "windscreen": ("0:135:45", 0.0),
          "media_haze": ("0:90:90", 1.0), "media_underwater": ("0:90:90", 0.0)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--out", default=os.path.join(REPO, "docs", "images"))
    p.add_argument("--exposure", type=float, default=0.0)
    p.add_argument("--scenes", default=",".join(SCENES), help="comma-separated names of examples/<name>.json")
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for name in a.scenes.split(","):
            sweep, exposure = SCENES[name]
            exr = os.path.join(tmp, f"{name}.exr")
            subprocess.run([sys.executable, "-m", "engine", "render", os.path.join(REPO, "examples", f"{name}.json"),
                            "-o", exr, "--spp", str(a.spp), "--no-previews", "-q"], check=True, cwd=REPO)
            png = os.path.join(a.out, f"{name}.png")
            subprocess.run([sys.executable, "-m", "engine", "polariser", exr, "--sweep", sweep, "--exposure",
                            str(a.exposure + exposure), "-o", png], check=True, cwd=REPO)
    return 0


if __name__ == "__main__":
    sys.exit(main())
