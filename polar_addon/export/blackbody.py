"""Cycles' blackbody colour and intensity of Principled Volume (kernel/svm/math_util.h
svm_math_blackbody_color_rec709 with kernel/tables.h blackbody_table_*, and svm_node_principled_volume):

- colour(T): linear Rec. 709 RGB of a blackbody at T kelvin, Cycles' piecewise fit (a/T + b·T + c for R and G,
  a cubic in T for B) on 800–12000 K, its end values outside; negative components (outside the Rec. 709 gamut)
  are clamped to 0 here (an emission grid holds values ≥ 0);
- emission(T, intensity, tint) = tint · σ/π·10⁻⁶ · mix(1, T⁴, intensity) · colour(T) (Stefan–Boltzmann with
  σ = 5.670373·10⁻⁸), 0 where T ≤ 0 — Cycles' volume emission per unit length.
Vectorised over T (any shape); results (…, 3).
"""

from __future__ import annotations

import numpy as np

_R = np.array([[1.61919106e+03, -2.05010916e-03, 5.02995757e+00], [2.48845471e+03, -1.11330907e-03, 3.22621544e+00],
               [3.34143193e+03, -4.86551192e-04, 1.76486769e+00], [4.09461742e+03, -1.27446582e-04, 7.25731635e-01],
               [4.67028036e+03, 2.91258199e-05, 1.26703442e-01], [4.59509185e+03, 2.87495649e-05, 1.50345020e-01],
               [3.78717450e+03, 9.35907826e-06, 3.99075871e-01]])
_G = np.array([[-4.88999748e+02, 6.04330754e-04, -7.55807526e-02], [-7.55994277e+02, 3.16730098e-04, 4.78306139e-01],
               [-1.02363977e+03, 1.20223470e-04, 9.36662319e-01], [-1.26571316e+03, 4.87340896e-06, 1.27054498e+00],
               [-1.42529332e+03, -4.01150431e-05, 1.43972784e+00], [-1.17554822e+03, -2.16378048e-05, 1.30408023e+00],
               [-5.00799571e+02, -4.59832026e-06, 1.09098763e+00]])
_B = np.array([[5.96945309e-11, -4.85742887e-08, -9.70622247e-05, -4.07936148e-03],
               [2.40430366e-11, 5.55021075e-08, -1.98503712e-04, 2.89312858e-02],
               [-1.40949732e-11, 1.89878968e-07, -3.56632824e-04, 9.10767778e-02],
               [-3.61460868e-11, 2.84822009e-07, -4.93211319e-04, 1.56723440e-01],
               [-1.97075738e-11, 1.75359352e-07, -2.50542825e-04, -2.22783266e-02],
               [-1.61997957e-13, -1.64216008e-08, 3.86216271e-04, -7.38077418e-01],
               [6.72650283e-13, -2.73078809e-08, 4.24098264e-04, -7.52335691e-01]])
_EDGES = np.array([965.0, 1167.0, 1449.0, 1902.0, 3315.0, 6365.0])
_HOT = np.array([0.8262954810464208, 0.9945080501520986, 1.566307710274283])
_COLD = np.array([5.413294490189271, -0.20319390035873933, -0.0822535242887164])
#: Cycles' σ/π·10⁻⁶ (Stefan–Boltzmann, per steradian, scaled to Blender's units)
SIGMA = 5.670373e-8 * 1e-6 / np.pi


def colour(T) -> np.ndarray:
    """Cycles' blackbody colour (…, 3) (linear Rec. 709, clamped ≥ 0) at temperatures T [K] (any shape)."""
    t = np.asarray(T, np.float64)
    i = np.searchsorted(_EDGES, t, side="right")
    ts = np.maximum(t, 1.0)
    r, g, b = _R[i], _G[i], _B[i]
    fit = np.stack((r[..., 0] / ts + r[..., 1] * ts + r[..., 2], g[..., 0] / ts + g[..., 1] * ts + g[..., 2],
                    ((b[..., 0] * ts + b[..., 1]) * ts + b[..., 2]) * ts + b[..., 3]), axis=-1)
    fit = np.where((t >= 12000.0)[..., None], _HOT, np.where((t < 800.0)[..., None], _COLD, fit))
    return np.maximum(fit, 0.0)


def emission(T, intensity: float, tint) -> np.ndarray:
    """Principled Volume's blackbody emission (…, 3) per unit length at temperatures T [K] (see the docstring)."""
    t = np.maximum(np.asarray(T, np.float64), 0.0)
    power = SIGMA * (1.0 + intensity * (t ** 4 - 1.0))
    return np.where((t > 0)[..., None], np.asarray(tint, np.float64) * power[..., None] * colour(t), 0.0)
