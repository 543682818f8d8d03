"""Spectral rendering support: CIE colorimetry, wavelength sampling, spectral parameters.

Wavelengths are in nm throughout (rendered range 360-830 nm); see ``cie`` for the radiance
units (``d65_normalised`` is the white of luminance 1, linear sRGB (1, 1, 1)).
"""

from .cie import (
    CIE_Y_INTEGRAL,
    GRID_NM,
    LAMBDA_MAX,
    LAMBDA_MIN,
    LINEAR_SRGB_TO_XYZ,
    LUMINANCE_WEIGHTS,
    XYZ_TO_LINEAR_SRGB,
    cmf_xyz,
    d65_normalised,
    luminance,
    rgb_weights,
    sample_wavelengths,
    spectrum_to_linear_srgb,
    spectrum_to_xyz,
    wavelength_pdf,
)
from .ior import NAMED_METALS, named_ior
from .spectrum import (
    ConstantSpectrum,
    RGBIlluminantSpectrum,
    RGBReflectanceSpectrum,
    RGBUnboundedSpectrum,
    Spectrum,
    TabulatedSpectrum,
    RGB_WAVELENGTHS_NM,
    WavelengthLookup,
    rgb_channel_tables,
    as_spectrum,
    basis_rgb,
    parse_spectrum,
)

__all__ = [
    "CIE_Y_INTEGRAL",
    "GRID_NM",
    "LAMBDA_MAX",
    "LAMBDA_MIN",
    "LINEAR_SRGB_TO_XYZ",
    "LUMINANCE_WEIGHTS",
    "XYZ_TO_LINEAR_SRGB",
    "cmf_xyz",
    "d65_normalised",
    "luminance",
    "rgb_weights",
    "sample_wavelengths",
    "spectrum_to_linear_srgb",
    "spectrum_to_xyz",
    "wavelength_pdf",
    "NAMED_METALS",
    "named_ior",
    "ConstantSpectrum",
    "RGBIlluminantSpectrum",
    "RGBReflectanceSpectrum",
    "RGBUnboundedSpectrum",
    "Spectrum",
    "TabulatedSpectrum",
    "RGB_WAVELENGTHS_NM",
    "WavelengthLookup",
    "rgb_channel_tables",
    "as_spectrum",
    "basis_rgb",
    "parse_spectrum",
]
