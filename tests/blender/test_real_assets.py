"""Real-asset parity with Cycles: third-party glTF 2.0 assets (tests/data/assets/SOURCES.md) imported by
Blender's glTF importer and rendered by Cycles and by Polar (the extension's exporter + engine, as F12
does), under lamps and under an HDRI sky.  The rule and the settings are in tests/support/asset_parity.py:
per 16 × 16-pixel block of the asset, Polar's S0 luminance must be Cycles' within 4 σ + 2 % (σ from
4 seeds of each renderer at equal samples), in at least 95 % of the asset's blocks.

Cases the exporter does not render like Cycles yet are marked ``xfail(strict=True)`` with the cause
found by editing the material in both renderers (``run_case(edit=…)``): when the exporter learns the
feature, the case passes, strict xfail turns that into a failure, and the mark is removed.
"""

import os

import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import load_addon  # noqa: E402
from tests.support import asset_parity as ap  # noqa: E402

SPP = 16
SEEDS = 4

#: Why each currently failing case fails, as isolated by editing the material in both renderers (none now:
#: the last two — a steep normal map, and sunglass lenses crossed once — were fixed by following Cycles'
#: mapped-normal rules and its refraction without radiance scaling).
KNOWN: dict[tuple[str, str], str] = {}


def _cases():
    for name in ap.CATALOGUE:
        for lighting in ap.LIGHTINGS:
            reason = KNOWN.get((name, lighting))
            marks = [pytest.mark.xfail(strict=True, reason=reason)] if reason else []
            yield pytest.param(name, lighting, marks=marks, id=f"{name}-{lighting}")


@pytest.fixture(scope="module")
def addon():
    return load_addon()


@pytest.mark.parametrize("name, lighting", list(_cases()))
def test_asset_matches_cycles(addon, name, lighting):
    report = ap.run_case(name, lighting, spp=SPP, seeds=SEEDS)
    print(report.line())
    assert not report.error, report.line()
    assert report.blocks >= 8, f"{name}: only {report.blocks} blocks of the asset to compare (framing)"
    assert report.ok, (f"{report.line()}\nfailing blocks (row, column, Polar ÷ Cycles, tolerance): "
                       f"{[(i, j, round(r, 3), round(t, 3)) for i, j, r, t in report.failing]}\n"
                       f"warnings: {report.warnings}")


def test_sources_list_every_asset_within_the_size_budget():
    with open(os.path.join(ap.ASSETS, "SOURCES.md"), encoding="utf-8") as f:
        sources = f.read()
    total = 0
    for root, _, files in os.walk(ap.ASSETS):
        total += sum(os.path.getsize(os.path.join(root, n)) for n in files)
    assert total <= 25 * 2 ** 20, f"tests/data/assets holds {total / 2 ** 20:.1f} MB (budget 25 MB)"
    for asset in ap.CATALOGUE.values():
        assert os.path.exists(asset.file), asset.file
        assert f"`{asset.path.split('/')[0]}/`" in sources, f"{asset.name} is not in SOURCES.md"
    for lighting in ap.LIGHTINGS:
        assert lighting in sources
