"""The Lorenz–Mie series for a homogeneous sphere (Bohren & Huffman 1983, appendix A: BHMIE).

Why written here: ``miepython`` (the well-kept library, MIT) pulls in scipy and matplotlib at install
time, which neither the engine nor the Blender extension (bundled wheels) should carry for ~80 lines
of recurrences; tests/media/test_mie.py checks this code against Bohren & Huffman's worked example and
Wiscombe's MIEV0 test cases.

Conventions (docs/physics.md §0): time dependence e^{−iωt}, relative index m = (n + iκ)/n_medium with
κ ≥ 0 (as Bohren & Huffman's BHMIE), size parameter x = 2π r n_medium/λ.  The amplitude functions S1
(field ⟂ the scattering plane) and S2 (field in it) are B&H's; the logarithmic derivative D_n(mx) by
downward recurrence from n_mx = max(n_stop, |mx|) + 10|mx|^{1/3} + 15 (BHMIE's + 15 alone leaves errors of
10⁻⁴ in D_n of weakly absorbing spheres, |mx| ≳ 100: Wiscombe's case m = 1.33 + 10⁻⁵i, x = 100 came out 2·10⁻⁵
off), ψ_n and χ_n upward, n_stop = x + 4x^{1/3} + 2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MieCoefficients:
    """Efficiencies and asymmetry of one sphere, and its series coefficients a_n, b_n (n = 1 … n_stop)."""

    x: float
    m: complex
    a: np.ndarray
    b: np.ndarray
    q_ext: float
    q_sca: float
    q_back: float
    g: float


def n_stop(x: float) -> int:
    """Terms of the series (Wiscombe 1980 / BHMIE)."""
    return int(x + 4.0 * x ** (1.0 / 3.0) + 2.0)


def mie_coefficients(m: complex, x: float) -> MieCoefficients:
    """a_n, b_n and Q_ext, Q_sca, Q_back, g for relative index ``m`` (Im m ≥ 0) and size parameter x > 0."""
    m, x = complex(m), float(x)
    if not (x > 0 and np.isfinite(x)):
        raise ValueError(f"size parameter must be a positive finite number, got {x}")
    ns = n_stop(x)
    y = m * x
    nmx = int(max(ns, abs(y)) + 10.0 * abs(y) ** (1.0 / 3.0)) + 15
    D = np.zeros(nmx + 1, complex)
    for n in range(nmx, 0, -1):
        D[n - 1] = n / y - 1.0 / (D[n] + n / y)
    a = np.empty(ns, complex)
    b = np.empty(ns, complex)
    psi0, psi1 = np.cos(x), np.sin(x)
    chi0, chi1 = -np.sin(x), np.cos(x)
    xi1 = complex(psi1, -chi1)
    for n in range(1, ns + 1):
        psi = (2 * n - 1) * psi1 / x - psi0
        chi = (2 * n - 1) * chi1 / x - chi0
        xi = complex(psi, -chi)
        da = D[n] / m + n / x
        db = m * D[n] + n / x
        a[n - 1] = (da * psi - psi1) / (da * xi - xi1)
        b[n - 1] = (db * psi - psi1) / (db * xi - xi1)
        psi0, psi1, chi0, chi1 = psi1, psi, chi1, chi
        xi1 = complex(psi1, -chi1)
    n = np.arange(1, ns + 1)
    q_ext = 2.0 / x ** 2 * float(np.sum((2 * n + 1) * (a + b).real))
    q_sca = 2.0 / x ** 2 * float(np.sum((2 * n + 1) * (np.abs(a) ** 2 + np.abs(b) ** 2)))
    q_back = float(np.abs(np.sum((2 * n + 1) * (-1.0) ** n * (a - b))) ** 2) / x ** 2
    nn = n[:-1]
    g_sum = (np.sum(nn * (nn + 2) / (nn + 1) * (a[:-1] * np.conj(a[1:]) + b[:-1] * np.conj(b[1:])).real)
             + np.sum((2 * n + 1) / (n * (n + 1)) * (a * np.conj(b)).real))
    g = 4.0 / (x ** 2 * q_sca) * float(g_sum) if q_sca > 0 else 0.0
    return MieCoefficients(x, m, a, b, q_ext, q_sca, q_back, g)


def amplitudes(coef: MieCoefficients, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(S1, S2) complex, shaped like ``mu`` = cos Θ: S = Σ (2n+1)/(n(n+1))·(a_n π_n + b_n τ_n) (S1) and
    (a_n τ_n + b_n π_n) (S2), with the angular functions π_n, τ_n by their upward recurrence."""
    mu = np.asarray(mu, dtype=np.float64)
    s1 = np.zeros(mu.shape, complex)
    s2 = np.zeros(mu.shape, complex)
    pi0 = np.zeros(mu.shape)
    pi1 = np.ones(mu.shape)
    for n in range(1, coef.a.size + 1):
        tau = n * mu * pi1 - (n + 1) * pi0
        f = (2 * n + 1) / (n * (n + 1))
        an, bn = coef.a[n - 1], coef.b[n - 1]
        s1 += f * (an * pi1 + bn * tau)
        s2 += f * (an * tau + bn * pi1)
        pi0, pi1 = pi1, ((2 * n + 1) * mu * pi1 - (n + 1) * pi0) / n
    return s1, s2
