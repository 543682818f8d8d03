"""The three polariser previews of the user guide: a lake under the polarised sky, an LCD screen behind
polarised sunglasses, a car windscreen in daylight — each rendered once and seen through an ideal linear
polariser at 0°, 45°, 90° and 135° (from image right towards image up).

    python examples/polariser_previews.py [--spp 256] [--out docs/images]

Runs ``python -m engine render`` on examples/daylight_water.json, lcd_sunglasses.json and windscreen.json
and ``python -m engine polariser --sweep 0:135:45`` on each result; writes <name>.png into --out.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = ("daylight_water", "lcd_sunglasses", "windscreen")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--out", default=os.path.join(REPO, "docs", "images"))
    p.add_argument("--exposure", type=float, default=0.0)
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for name in SCENES:
            exr = os.path.join(tmp, f"{name}.exr")
            subprocess.run([sys.executable, "-m", "engine", "render", os.path.join(REPO, "examples", f"{name}.json"),
                            "-o", exr, "--spp", str(a.spp), "--no-previews", "-q"], check=True, cwd=REPO)
            png = os.path.join(a.out, f"{name}.png")
            subprocess.run([sys.executable, "-m", "engine", "polariser", exr, "--sweep", "0:135:45", "--exposure",
                            str(a.exposure), "-o", png], check=True, cwd=REPO)
    return 0


if __name__ == "__main__":
    sys.exit(main())
