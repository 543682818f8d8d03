"""The Lambert every shader conversion falls back to (an unsupported shader, a missing Base, a material
without nodes), and the spectrum of a constant colour."""

from ...engine.materials.catalogue import MODELS
from ...engine.spectral import ConstantSpectrum, RGBReflectanceSpectrum, RGBUnboundedSpectrum

DEFAULT_ALBEDO = 0.8


def rgb_spectrum(rgb, kind="reflectance"):
    if max(rgb) == min(rgb):
        return ConstantSpectrum(rgb[0])
    return RGBReflectanceSpectrum(rgb) if kind == "reflectance" else RGBUnboundedSpectrum(rgb)


def lambert(albedo, mat, node=None):
    """The ``lambert`` model of a constant (a number, [r, g, b] or a Spectrum) or a colour texture."""
    if isinstance(albedo, (int, float)):
        albedo = ConstantSpectrum(float(albedo))
    elif isinstance(albedo, (list, tuple)):
        albedo = rgb_spectrum(list(albedo))
    decl = MODELS["lambert"]
    where = f"material {mat!r}" + (f".{node.name}" if node is not None else "")
    return decl.build(decl.values({"albedo": albedo}, where))
