"""Mueller matrices: construction, Jones conversion and physical checks.

Layout: a Mueller matrix batch is (4, 4, ...) (row, column, batch...), Stokes
vectors are (4, ...), matching the structure-of-arrays layout of the engine.
S_out = M · S_in.  Conventions of docs/physics.md §0 (S3 = 2 Im(E_x E_y*)).
"""

from __future__ import annotations

import numpy as np

# Pauli-type basis matched to S_i = Tr(σ_i E E†) for the Stokes definition of §0:
# σ3 = [[0, i], [−i, 0]] gives Tr(σ3 C) = 2 Im(E_x E_y*).
_SIGMA = np.array([
    [[1, 0], [0, 1]],
    [[1, 0], [0, -1]],
    [[0, 1], [1, 0]],
    [[0, 1j], [-1j, 0]],
], dtype=np.complex128)


def mueller_from_jones(J: np.ndarray) -> np.ndarray:
    """Mueller matrix of a Jones matrix J (2, 2, ...): M_ij = ½ Tr(σ_i J σ_j J†)."""
    J = np.asarray(J, dtype=np.complex128)
    Jh = np.conj(np.swapaxes(J, 0, 1))
    # ½ Tr(σ_i J σ_j J†) = ½ Σ σ_i[a,b] J[b,c] σ_j[c,d] J†[d,a]
    M = 0.5 * np.einsum("iab,bc...,jcd,da...->ij...", _SIGMA, J, _SIGMA, Jh)
    return M.real.copy()


def stokes_from_jones_vector(E: np.ndarray) -> np.ndarray:
    """Stokes vector (4, ...) of a Jones vector E = (E_x, E_y) (2, ...)."""
    ex, ey = E[0], E[1]
    return np.stack((abs(ex) ** 2 + abs(ey) ** 2, abs(ex) ** 2 - abs(ey) ** 2,
                     2 * (ex * np.conj(ey)).real, 2 * (ex * np.conj(ey)).imag))


def abcs_matrix(A, B, C, S) -> np.ndarray:
    """The block form [[A,B,0,0],[B,A,0,0],[0,0,C,S],[0,0,−S,C]] (Fresnel, diattenuators)."""
    A, B, C, S = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (A, B, C, S)))
    M = np.zeros((4, 4) + A.shape)
    M[0, 0] = M[1, 1] = A
    M[0, 1] = M[1, 0] = B
    M[2, 2] = M[3, 3] = C
    M[2, 3] = S
    M[3, 2] = -S
    return M


def depolariser(a) -> np.ndarray:
    """Ideal depolariser a·diag(1, 0, 0, 0)."""
    a = np.asarray(a, dtype=np.float64)
    M = np.zeros((4, 4) + a.shape)
    M[0, 0] = a
    return M


def linear_polariser(angle_rad, transmittance=1.0) -> np.ndarray:
    """Ideal linear polariser with transmission axis at angle θ from the frame's x axis."""
    c = np.cos(2 * np.asarray(angle_rad, dtype=np.float64))
    s = np.sin(2 * np.asarray(angle_rad, dtype=np.float64))
    t = 0.5 * np.asarray(transmittance, dtype=np.float64)
    row = np.stack((np.ones_like(c), c, s, np.zeros_like(c)))
    return t * row[:, None] * row[None, :]


def apply(M: np.ndarray, S: np.ndarray) -> np.ndarray:
    """M · S for batches: (4, 4, ...) × (4, ...) → (4, ...)."""
    return np.einsum("ij...,j...->i...", M, S)


def compose(M2: np.ndarray, M1: np.ndarray) -> np.ndarray:
    """M2 · M1 (M1 acts first) for batches."""
    return np.einsum("ij...,jk...->ik...", M2, M1)


def coherency_matrix(M: np.ndarray) -> np.ndarray:
    """Cloude coherency matrix H = ¼ Σ_ij M_ij (σ_i ⊗ σ_j*) (4, 4, ...) complex Hermitian.

    M is physically realisable (a convex sum of non-depolarising elements) iff
    H is positive semidefinite.
    """
    M = np.asarray(M, dtype=np.float64)
    basis = np.einsum("iab,jcd->ijacbd", _SIGMA, np.conj(_SIGMA)).reshape(4, 4, 4, 4)
    return 0.25 * np.einsum("ij...,ijab->ab...", M, basis)


def realisability_report(M: np.ndarray, tol: float = 1e-9) -> dict:
    """Checks of docs/physics.md §4 on a batch (4, 4, ...); returns {check: bool array}.

    - ``m00_nonnegative``: M00 ≥ −tol
    - ``row_col_bounded``: |M0j|, |Mj0| ≤ M00 (1 + tol) + tol
    - ``coherency_psd``: smallest eigenvalue of the Cloude coherency matrix ≥ −tol·(M00 + 1)
    Each entry is a boolean array over the batch shape.
    """
    M = np.asarray(M, dtype=np.float64)
    m00 = M[0, 0]
    bound = m00 * (1 + tol) + tol
    rows = np.all(np.abs(M[0, 1:]) <= bound, axis=0)
    cols = np.all(np.abs(M[1:, 0]) <= bound, axis=0)
    H = coherency_matrix(M)
    Hb = np.moveaxis(H, (0, 1), (-2, -1))
    eig = np.linalg.eigvalsh(Hb)[..., 0]
    return {
        "m00_nonnegative": m00 >= -tol,
        "row_col_bounded": rows & cols,
        "coherency_psd": eig >= -tol * (np.abs(m00) + 1.0),
    }


def is_realisable(M: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """True where every check of :func:`realisability_report` passes."""
    rep = realisability_report(M, tol)
    out = None
    for v in rep.values():
        out = v if out is None else out & v
    return out


def depolarisation_index_sq_excess(M: np.ndarray) -> np.ndarray:
    """tr(MᵀM) − 4 M00²: zero for a non-depolarising (pure) Mueller matrix."""
    M = np.asarray(M, dtype=np.float64)
    return np.einsum("ij...,ij...->...", M, M) - 4 * M[0, 0] ** 2
