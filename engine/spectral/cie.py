"""CIE 1931 colorimetry, D65 and spectral sampling (numpy only).

Units: wavelengths in nm, pdfs in 1/nm. The colour matching functions are the raw CIE tables
(ȳ peaks at 1, ∫ȳ dλ ≈ 106.86 nm); spectral radiance is in units where ``d65_normalised``
(∫ D65n ȳ dλ = 1) is the white of luminance Y = 1, i.e. linear sRGB (1, 1, 1).

Tables are read from ``data/*.csv`` (made once by ``data/generate_tables.py``) and sampled at
1 nm, 360-830 nm; between table points everything is linearly interpolated.
"""

from __future__ import annotations

import functools
import os

import numpy as np

from ..kernels import tables, twin, wavelengths

LAMBDA_MIN = 360.0
LAMBDA_MAX = 830.0
DATA_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data")


def read_csv_table(path: str) -> tuple[list[str], np.ndarray]:
    """Read a '#'-commented CSV with one header line; returns (column names, float64 rows)."""
    with open(path, encoding="utf-8") as f:
        lines = [ln.strip() for ln in f if ln.strip() and not ln.lstrip().startswith("#")]
    names = [c.strip() for c in lines[0].split(",")]
    rows = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]], dtype=np.float64)
    return names, rows.reshape(-1, len(names))


def load_grid_table(name: str, ncols: int) -> np.ndarray:
    """Load a 1 nm 360-830 table; returns (ncols, 471) with the wavelength column checked."""
    _, rows = read_csv_table(os.path.join(DATA_DIR, name))
    grid = np.arange(LAMBDA_MIN, LAMBDA_MAX + 1.0)
    if rows.shape != (grid.size, ncols + 1) or not np.array_equal(rows[:, 0], grid):
        raise RuntimeError(f"{name}: expected 1 nm rows 360-830 nm with {ncols} value columns")
    return np.ascontiguousarray(rows[:, 1:].T)


#: 1 nm wavelength grid 360..830 nm inclusive (471 points) of the embedded tables.
GRID_NM = np.arange(LAMBDA_MIN, LAMBDA_MAX + 1.0)
_CMF = load_grid_table("cie1931_2deg.csv", 3)  # (3, 471)
_D65 = load_grid_table("d65.csv", 1)[0]  # (471,), 100 at 560 nm

#: ∫ ȳ dλ over 360-830 nm [nm] (1 nm rectangle rule, the rule used throughout).
CIE_Y_INTEGRAL = float(_CMF[1].sum())
_D65N = _D65 / float(np.dot(_D65, _CMF[1]))  # ∫ D65n ȳ dλ = 1 (1 nm steps)


def interp_grid(table: np.ndarray, lam_nm, outside: str = "zero") -> np.ndarray:
    """Linearly interpolate rows of a (K, 471) 1 nm table at lam_nm -> (K, *lam.shape).

    ``outside``: "zero" (0 outside [360, 830]) or "clamp" (end values held); engine.kernels.tables.
    """
    return tables.interp_grid(table, lam_nm, LAMBDA_MIN, LAMBDA_MAX, outside == "zero")


def cmf_xyz(lam_nm) -> np.ndarray:
    """CIE 1931 2° x̄, ȳ, z̄ at lam_nm [nm] -> (3, *lam.shape); 0 outside 360-830 nm."""
    return interp_grid(_CMF, lam_nm)


def d65_normalised(lam_nm) -> np.ndarray:
    """D65 spectral radiance scaled so ∫ D65n ȳ dλ = 1 [1/nm]; 0 outside 360-830 nm."""
    return interp_grid(_D65N[None, :], lam_nm)[0]


def _xyz_to_rgb_from_primaries() -> np.ndarray:
    """IEC 61966-2-1 / Rec. 709 primaries with D65 white (x, y) = (0.3127, 0.3290)."""
    prim = np.array([[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]])
    white = np.array([0.3127, 0.3290])

    def xyz(xy):
        return np.array([xy[0] / xy[1], 1.0, (1.0 - xy[0] - xy[1]) / xy[1]])

    p = np.stack([xyz(c) for c in prim], axis=1)
    rgb_to_xyz = p * np.linalg.solve(p, xyz(white))[None, :]
    return rgb_to_xyz


LINEAR_SRGB_TO_XYZ = _xyz_to_rgb_from_primaries()
XYZ_TO_LINEAR_SRGB = np.linalg.inv(LINEAR_SRGB_TO_XYZ)
LINEAR_SRGB_TO_XYZ.setflags(write=False)
XYZ_TO_LINEAR_SRGB.setflags(write=False)
#: Rec. 709 / sRGB luminance weights of linear R, G, B (Y of linear sRGB): the engine's one definition.
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])
LUMINANCE_WEIGHTS.setflags(write=False)


def luminance(rgb) -> np.ndarray:
    """Rec. 709 luminance 0.2126 R + 0.7152 G + 0.0722 B of linear sRGB (last axis = RGB)."""
    return np.asarray(rgb, dtype=np.float64) @ LUMINANCE_WEIGHTS


# --- wavelength sampling (Mitsuba 3's sample_rgb_spectrum) ----------------------------------
_A = 0.0072  # 1/nm
_C = 538.0  # nm
_T0 = np.tanh(_A * (LAMBDA_MIN - _C))
_T1 = np.tanh(_A * (LAMBDA_MAX - _C))
_PDF_NORM = _A / (_T1 - _T0)  # 1/nm; = 0.0039398042... as in Mitsuba 3


def wavelength_pdf(lam_nm) -> np.ndarray:
    """pdf [1/nm] of ``sample_wavelengths``: ∝ sech²(0.0072 (λ − 538)) on [360, 830], else 0."""
    lam = np.asarray(lam_nm, dtype=np.float64)
    pdf = _PDF_NORM / np.cosh(_A * (lam - _C)) ** 2
    return np.where((lam >= LAMBDA_MIN) & (lam <= LAMBDA_MAX), pdf, 0.0)


def sample_wavelengths_numpy(u, count: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Importance-sample ``count`` stratified wavelengths per path from u ∈ [0, 1).

    Wavelength j uses u_j = frac(u + j/count) and inverts the CDF of ``wavelength_pdf``:
    λ = 538 + atanh(T0 + u_j (T1 − T0)) / 0.0072 nm. Returns (lam [nm], pdf [1/nm]), each of
    shape (count, *u.shape).
    """
    u = np.asarray(u, dtype=np.float64)
    offs = (np.arange(count, dtype=np.float64) / count).reshape((count,) + (1,) * u.ndim)
    uj = np.mod(u[None, ...] + offs, 1.0)
    lam = _C + np.arctanh(_T0 + uj * (_T1 - _T0)) / _A
    lam = np.clip(lam, LAMBDA_MIN, LAMBDA_MAX)
    return lam, wavelength_pdf(lam)


def rgb_weights_numpy(lam_nm, pdf) -> np.ndarray:
    """Per-wavelength factors turning radiance samples L(λ_j) of a path into linear sRGB.

    weights[:, j] = XYZ_TO_LINEAR_SRGB @ cmf_xyz(λ_j) / pdf_j / count, so
    RGB ≈ Σ_j weights[:, j] · L(λ_j). lam, pdf: (count, N) -> (3, count, N) [nm].
    Samples with pdf 0 get weight 0.
    """
    lam = np.asarray(lam_nm, dtype=np.float64)
    pdf = np.asarray(pdf, dtype=np.float64)
    count = lam.shape[0]
    rgb = np.tensordot(XYZ_TO_LINEAR_SRGB, cmf_xyz(lam), axes=1)
    inv = np.divide(1.0, pdf * count, out=np.zeros_like(pdf), where=pdf > 0)
    return rgb * inv[None, ...]


def _sample_wavelengths_compiled(u, count: int = 4) -> tuple[np.ndarray, np.ndarray]:
    return wavelengths.sample_tanh(u, count, _T0, _T1 - _T0, _C, _A, LAMBDA_MIN, LAMBDA_MAX, _PDF_NORM)


def _rgb_weights_compiled(lam_nm, pdf) -> np.ndarray:
    lam = np.asarray(lam_nm, dtype=np.float64)
    rgb = np.tensordot(XYZ_TO_LINEAR_SRGB, cmf_xyz(lam), axes=1)     # BLAS, as in the reference
    return wavelengths.weights_over_pdf(rgb, pdf)


#: (λ, pdf) of ``count`` stratified wavelengths per path (sample_wavelengths_numpy); the elementwise
#: steps compiled when available (engine.kernels.wavelengths, same numbers).
sample_wavelengths = twin(wavelengths.sample_tanh and _sample_wavelengths_compiled, sample_wavelengths_numpy)
#: The per-wavelength sRGB factors of a path (rgb_weights_numpy), compiled when available (same numbers).
rgb_weights = twin(wavelengths.weights_over_pdf and _rgb_weights_compiled, rgb_weights_numpy)


def spectrum_to_xyz(values_on_grid, illuminant: bool = False) -> np.ndarray:
    """XYZ = Σ cmf(λ) s(λ) [D65n(λ)] · 1 nm over ``GRID_NM`` (values_on_grid: (..., 471)).

    With illuminant=True, s is a reflectance lit by the unit D65 white (s ≡ 1 gives Y = 1);
    otherwise s is a spectral radiance in the renderer's units.
    """
    s = np.asarray(values_on_grid, dtype=np.float64)
    if illuminant:
        s = s * _D65N
    return s @ _CMF.T


def spectrum_to_linear_srgb(values_on_grid, illuminant: bool = False) -> np.ndarray:
    """Linear sRGB of ``spectrum_to_xyz`` (last axis RGB)."""
    return spectrum_to_xyz(values_on_grid, illuminant) @ XYZ_TO_LINEAR_SRGB.T


#: optical path differences (nm) up to which ``channel_fourier_table`` is tabulated; beyond, a film is incoherent
#: (|S| < 1e-3 there, and the channel averages of its interference terms are taken as 0), as in Cycles (60 µm)
FOURIER_X_MAX = 60000.0


def channel_sensitivity(lam_nm) -> np.ndarray:
    """(3, *lam.shape) the linear-sRGB channels' sensitivities under the unit D65 white, D65n(λ)·(M·cmf(λ))_c
    (unnormalised): how the spectral transport develops light at λ into each channel."""
    lam = np.asarray(lam_nm, np.float64)
    return np.tensordot(XYZ_TO_LINEAR_SRGB, cmf_xyz(lam), axes=1) * d65_normalised(lam)


@functools.lru_cache(maxsize=1)
def channel_fourier_table() -> tuple[float, np.ndarray]:
    """(h nm, S (3, J) complex): S_c(x) = ∫ s_c(λ) e^{2πix/λ} dλ at x = 0, h, …, (J − 1)·h ≈ FOURIER_X_MAX nm, the
    average over linear-sRGB channel c of the phase factor e^{2πix/λ} of an optical path difference x, each
    channel's sensitivity s_c = D65n·(M·cmf)_c normalised to ∫ s_c dλ = 1 (so S_c(0) = 1): the white of the
    spectral transport (``spectrum_to_linear_srgb`` with the D65 illuminant) developed to RGB.  Computed once
    (≈ 0.3 s): the integral over ν = 1/λ on a uniform grid of 1024 intervals (trapezoid rule) by an FFT padded to
    h ≈ 2 nm (docs/physics.md, thin films: accurate to ≈ 1e-5 against 0.05 nm quadrature)."""
    m, h_target = 1024, 2.0
    nu0, nu1 = 1.0 / LAMBDA_MAX, 1.0 / LAMBDA_MIN
    dnu = (nu1 - nu0) / m
    lam = 1.0 / (nu0 + dnu * np.arange(m + 1))
    g = channel_sensitivity(lam) * lam ** 2           # per unit ν
    g[:, 0] *= 0.5
    g[:, -1] *= 0.5
    g /= g.sum(axis=1, keepdims=True)
    n = int(round(1.0 / (dnu * h_target)))
    h = 1.0 / (n * dnu)
    count = int(FOURIER_X_MAX / h) + 2
    padded = np.zeros((3, n), np.complex128)
    padded[:, :m + 1] = g
    S = np.fft.ifft(padded, axis=1)[:, :count] * n          # Σ_m g_m e^{2πi j m / n}
    S *= np.exp(2j * np.pi * h * np.arange(count) * nu0)[None, :]
    S.setflags(write=False)
    return h, S
