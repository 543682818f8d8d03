"""A plane-parallel vector adding–doubling solver for Rayleigh slabs: the tests' polarised multiple-scattering
reference (issue 37).  Written for the tests from Hansen & Travis 1974 (§3.3–3.4: the reflection and transmission
functions, the doubling equations with the direct beam kept apart) and de Haan, Bosma & Hovenier 1987 (each
Fourier component of the azimuth doubled on its own); not engine code, and sharing none with it.

Problem: a homogeneous slab of optical thickness τ and single-scattering albedo ω over a black surface (nothing
below), Rayleigh scattering with depolarisation factor δ (Hansen & Travis eq. 2.15), lit from above by an
unpolarised collimated beam of irradiance E (on a plane ⟂ the beam) with zenith angle θ0.  Answer: the reflected
(above, going up) or diffusely transmitted (below, going down) Stokes radiance (I, Q, U, V) in direction
(θ, φ), per steradian, φ the azimuth of the outgoing propagation vector relative to the beam's.

Frames (the project's conventions, ../shared/docs/physics.md §0): a direction k at azimuth φ carries the Stokes
frame x = e_φ = (−sin φ, cos φ, 0) (horizontal, ⟂ the meridian plane), y = k × x.  That is exactly Polar's camera
frame for a camera looking along −k with up = +z, so the solver's Stokes vectors compare with Polar's images
directly.  Q > 0: E horizontal (the opposite sign of Hansen & Travis's Q = I_l − I_r).

Method: with the kernels R(μ, μ0, Δφ), T(μ, μ0, Δφ) of Hansen & Travis (I = μ0 (E/π) R·s for a beam of
irradiance E and Stokes vector s), each azimuthal Fourier mode m (complex, e^{imΔφ}) composes as
(A∘B)_m(μ, μ0) = 2 ∫₀¹ A_m(μ, μ') B_m(μ', μ0) μ' dμ' (Gauss–Legendre nodes; the beam's and the views' cosines are
extra nodes of weight 0).  A layer of thickness τ/2ⁿ starts as exact single scattering and is doubled n times
with the adding equations for a layer under itself, tracking the four operators R, T (light from above) and
R*, T* (light from below).  The phase matrix in meridian frames is rotated from the scattering-plane matrix
geometrically (vectors, no angle formulas) and its Fourier modes taken by a half-step offset DFT (so no pair of
nodes is ever exactly forward or backward); Rayleigh has modes |m| ≤ 2 only (checked).
"""

from __future__ import annotations

import numpy as np

MODES = 2                       # Rayleigh's meridian-frame phase matrix has azimuthal modes |m| ≤ 2
AZIMUTHS = 16                   # DFT points (exact for |m| < 8)


def rayleigh_matrix(mu: np.ndarray, delta: float) -> np.ndarray:
    """Rayleigh's phase matrix (..., 4, 4) at cos Θ = mu, normalised ∫ P00 dΩ/4π = 1, in the scattering-plane
    frames x = s = unit(k_i × k_o) on both sides (Q > 0: E ⟂ the scattering plane).  From the dipole's amplitude
    matrix diag(1, cos Θ) and Hansen & Travis 1974 eq. 2.15 for the depolarisation δ."""
    share = (1.0 - delta) / (1.0 + 0.5 * delta)                  # Δ
    circ = (1.0 - 2.0 * delta) / (1.0 - delta) if delta < 1.0 else 0.0   # Δ'
    mu = np.asarray(mu, dtype=np.float64)
    P = np.zeros(mu.shape + (4, 4))
    P[..., 0, 0] = 0.75 * share * (1 + mu * mu) + (1.0 - share)
    P[..., 0, 1] = P[..., 1, 0] = 0.75 * share * (1 - mu * mu)
    P[..., 1, 1] = 0.75 * share * (1 + mu * mu)
    P[..., 2, 2] = 1.5 * share * mu
    P[..., 3, 3] = 1.5 * share * circ * mu
    return P


def direction(mu: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Unit propagation vectors (..., 3) with k_z = mu (signed) and azimuth phi."""
    s = np.sqrt(np.maximum(0.0, 1.0 - mu * mu))
    return np.stack(np.broadcast_arrays(s * np.cos(phi), s * np.sin(phi), mu), axis=-1)


def rotator(k: np.ndarray, x_from: np.ndarray, x_to: np.ndarray) -> np.ndarray:
    """The Mueller matrix (..., 4, 4) re-expressing a Stokes vector on beam k from frame x_from to x_to
    (conventions §0: cos φ = x·x′, sin φ = y·x′, y = k × x)."""
    c = np.sum(x_from * x_to, axis=-1)
    s = np.sum(np.cross(k, x_from) * x_to, axis=-1)
    c2, s2 = c * c - s * s, 2.0 * c * s
    R = np.zeros(c.shape + (4, 4))
    R[..., 0, 0] = R[..., 3, 3] = 1.0
    R[..., 1, 1] = R[..., 2, 2] = c2
    R[..., 1, 2], R[..., 2, 1] = s2, -s2
    return R


def meridian_phase_modes(mu_out: np.ndarray, mu_in: np.ndarray, delta: float) -> np.ndarray:
    """Fourier modes Z_m (MODES + 1, n_out, n_in, 4, 4), complex, of the phase matrix in meridian frames:
    Z(μ_out, μ_in, Δφ) = Σ_m Z_m e^{imΔφ} (m from −MODES to MODES, Z_{−m} = conj Z_m), with signed cosines
    (k_z) of the outgoing and incoming propagation vectors and Δφ = φ_out − φ_in."""
    dphi = (np.arange(AZIMUTHS) + 0.5) * (2.0 * np.pi / AZIMUTHS)
    ki = direction(mu_in[None, :, None], np.zeros((1, 1, 1)))                  # (1, n_in, 1, 3)
    ko = direction(mu_out[:, None, None], dphi[None, None, :])                 # (n_out, 1, K, 3)
    ki, ko = np.broadcast_arrays(ki, ko)
    ex_i = np.broadcast_to(np.array([0.0, 1.0, 0.0]), ki.shape)               # e_φ at φ = 0
    ex_o = np.stack(np.broadcast_arrays(-np.sin(dphi), np.cos(dphi), 0.0 * dphi), axis=-1)[None, None]
    ex_o = np.broadcast_to(ex_o, ko.shape)
    s = np.cross(ki, ko)
    s /= np.linalg.norm(s, axis=-1, keepdims=True)
    Z = rotator(ko, s, ex_o) @ rayleigh_matrix(np.sum(ki * ko, axis=-1), delta) @ rotator(ki, ex_i, s)
    phases = np.exp(-1j * np.arange(AZIMUTHS // 2)[:, None] * dphi[None, :]) / AZIMUTHS
    modes = np.einsum("mk,oikab->moiab", phases, Z)
    leak = np.abs(modes[MODES + 1:]).max()
    assert leak < 1e-12 * np.abs(modes[0]).max(), f"phase matrix has Fourier modes beyond {MODES}: {leak}"
    return modes[:MODES + 1]


def _block(modes: np.ndarray) -> np.ndarray:
    """(M, n_out, n_in, 4, 4) → (M, 4·n_out, 4·n_in) with index node·4 + Stokes component."""
    M, no, ni = modes.shape[:3]
    return modes.transpose(0, 1, 3, 2, 4).reshape(M, 4 * no, 4 * ni)


class Slab:
    """The reflection and diffuse transmission of a Rayleigh slab (see the module docstring).

    ``extra_mu``: the cosines (0, 1] at which answers are wanted (the beam's and the views'), added as nodes of
    weight 0; ``nodes``: Gauss–Legendre nodes per hemisphere; the starting layer is τ/2ⁿ ≤ ``start``."""

    def __init__(self, tau: float, omega: float, delta: float = 0.0, extra_mu=(), nodes: int = 24,
                 start: float = 1e-9):
        x, w = np.polynomial.legendre.leggauss(nodes)
        mu = np.concatenate([0.5 * (x + 1.0), np.asarray(extra_mu, dtype=np.float64)])
        wt = np.concatenate([0.5 * w, np.zeros(len(extra_mu))])
        self.mu, self.tau, self.omega, self.delta = mu, float(tau), float(omega), float(delta)
        n = len(mu)
        self.C = np.repeat(2.0 * wt * mu, 4)                                  # the composition's weights
        mu4 = np.repeat(mu, 4)
        doublings = max(0, int(np.ceil(np.log2(max(tau, start) / start))))
        t0 = tau / 2.0 ** doublings
        # single scattering of the thin layer: Z for (out, in) = (up, down), (down, down), (down, up), (up, up)
        Zr = _block(meridian_phase_modes(mu, -mu, delta))
        Zt = _block(meridian_phase_modes(-mu, -mu, delta))
        Zrs = _block(meridian_phase_modes(-mu, mu, delta))
        Zts = _block(meridian_phase_modes(mu, mu, delta))
        mo, mi = mu4[:, None], mu4[None, :]
        fr = omega / (4.0 * (mo + mi)) * -np.expm1(-t0 * (1.0 / mo + 1.0 / mi))
        same = np.isclose(mo, mi, rtol=0, atol=1e-12)
        diff = np.where(same, 1.0, mo - mi)
        ft = np.where(same, omega * t0 / (4.0 * mi * mi) * np.exp(-t0 / mi),
                      omega / (4.0 * diff) * (np.exp(-t0 / mo) - np.exp(-t0 / mi)))
        R, T, Rs, Ts = fr * Zr, ft * Zt, fr * Zrs, ft * Zts
        thick = t0
        for _ in range(doublings):
            R, T, Rs, Ts = self._double(R, T, Rs, Ts, mu4, thick)
            thick *= 2.0
        self.R, self.T, self.Rs, self.Ts = R, T, Rs, Ts
        self.n = n

    def _double(self, R, T, Rs, Ts, mu4, t):
        """A layer (R, T, R*, T*) of thickness t under itself (Hansen & Travis eqs. 3.9–3.13, per Fourier mode;
        the direct beam e^{−t/μ} kept apart).  Light from below sees the same equations with the roles of
        (R, T) and (R*, T*) exchanged."""
        e = np.exp(-t / mu4)
        return self._from_one_side(R, T, Rs, Ts, e) + self._from_one_side(Rs, Ts, R, T, e)

    def _from_one_side(self, R, T, Rs, Ts, e):
        """(R, T) of two identical layers for light entering the first: Q = R* ∘ R, S = Σ Qⁿ, D and U the
        diffuse down- and upwelling at the interface."""
        C = self.C
        Q = Rs * C[None, None, :] @ R
        S = Q @ np.linalg.inv(np.eye(len(e)) - C[:, None] * Q)
        D = T + (S * C) @ T + S * e[None, None, :]
        U = (R * C) @ D + R * e[None, None, :]
        return R + e[:, None] * U + (Ts * C) @ U, e[:, None] * D + (T * C) @ D + T * e[None, None, :]

    def _node(self, mu: float) -> int:
        i = np.flatnonzero(np.abs(self.mu - mu) < 1e-12)
        if not len(i):
            raise ValueError(f"mu = {mu} is not a node; pass it in extra_mu")
        return int(i[-1])

    def _kernel(self, op: np.ndarray, mu: float, mu0: float, phi: float) -> np.ndarray:
        i, j = self._node(mu), self._node(mu0)
        blocks = op[:, 4 * i:4 * i + 4, 4 * j:4 * j + 4]
        m = np.arange(len(blocks))[:, None, None]
        return np.real(blocks[0] + 2.0 * np.sum((blocks * np.exp(1j * m * phi))[1:], axis=0))

    def reflected(self, mu: float, mu0: float, phi: float, irradiance: float = 1.0) -> np.ndarray:
        """Stokes radiance (4,) going up from the top at cos θ = mu, azimuth phi (radians) from the beam's."""
        return mu0 * irradiance / np.pi * self._kernel(self.R, mu, mu0, phi)[:, 0]

    def transmitted(self, mu: float, mu0: float, phi: float, irradiance: float = 1.0) -> np.ndarray:
        """Diffuse Stokes radiance (4,) going down from the bottom at cos θ = mu (> 0, measured from nadir)."""
        return mu0 * irradiance / np.pi * self._kernel(self.T, mu, mu0, phi)[:, 0]

    def fluxes(self, mu0: float, irradiance: float = 1.0) -> tuple[float, float]:
        """Reflected and diffusely transmitted irradiance (on the horizontal plane) for the beam at mu0:
        2π ∫ I μ dμ over the Gauss nodes (mode 0 only contributes)."""
        j = self._node(mu0)
        w = self.C[::4] / 2.0                                                 # w_i μ_i
        up = np.real(self.R[0, 0::4, 4 * j]) * mu0 * irradiance / np.pi
        down = np.real(self.T[0, 0::4, 4 * j]) * mu0 * irradiance / np.pi
        return float(2 * np.pi * np.sum(w * up)), float(2 * np.pi * np.sum(w * down))
