"""A weighted sum of ABCS Mueller values in one compiled loop (engine.materials.mix's incoherent mixture).

``chain_sum_loop`` is engine.materials.mix's sums of scaled values per element (abcs_sum_numpy, and one ABCS value
plus depolarisers as _plus_depolariser adds them), the same arithmetic in the same order: each block of each term
times its factors in order ((b·f₁)·f₂)·… (a ScaledValue's deferred factors, then the term's weight), the running
sums 0 + t₁ + t₂ + … (Python's ``sum`` of the scaled arrays), without the scaled copies and the sums' temporaries.
"""

from __future__ import annotations

from . import jit, jit_inner


@jit_inner
def _chain_run(out, a, g0, g1, g2, g3, nf, add):
    """out[k] (+)= a[k]·g0[k]·g1[k]·… (the first ``nf`` factor rows, multiplied in order) over the row: one output
    per loop, so that it vectorises."""
    N = out.shape[0]
    if nf == 1:
        if add:
            for k in range(N):
                out[k] = out[k] + a[k] * g0[k]
        else:
            for k in range(N):
                out[k] = a[k] * g0[k]
    elif nf == 2:
        if add:
            for k in range(N):
                out[k] = out[k] + a[k] * g0[k] * g1[k]
        else:
            for k in range(N):
                out[k] = a[k] * g0[k] * g1[k]
    elif nf == 3:
        if add:
            for k in range(N):
                out[k] = out[k] + a[k] * g0[k] * g1[k] * g2[k]
        else:
            for k in range(N):
                out[k] = a[k] * g0[k] * g1[k] * g2[k]
    else:
        if add:
            for k in range(N):
                out[k] = out[k] + a[k] * g0[k] * g1[k] * g2[k] * g3[k]
        else:
            for k in range(N):
                out[k] = a[k] * g0[k] * g1[k] * g2[k] * g3[k]


@jit
def _chain_sum_loop(As, Bs, Cs, Ss, Ds, has_depol, factors, n_factors, n_pol, summed, A, B, C, S, D, dep):
    """Σ of K terms, each block times its factors in order ((b·f₁)·f₂)·… (factors[i]: 4 (1 or L, N) arrays, of which
    the first n_factors[i] are read, a row of one for every wavelength); terms 0 … n_pol − 1 ABCS values (Ds[i]
    their depolarised share where has_depol[i]), the rest depolarising values (As[i] only), summed in order into
    ``dep`` (t + t′ + …).  ``summed``: A..S and D arrive zero and each ABCS term is added (0 + t₁ + t₂ + …, Python's
    sum), else the one ABCS term is written.  The caller adds ``dep`` to D (engine.materials.mix: abcs_sum_numpy,
    _plus_depolariser)."""
    L = A.shape[0]
    K = len(As)
    for i in range(K):
        f0, f1, f2, f3 = factors[i]
        nf = n_factors[i]
        Ai, Bi, Ci, Si, Di = As[i], Bs[i], Cs[i], Ss[i], Ds[i]
        for q in range(L):
            g0 = f0[q if f0.shape[0] > 1 else 0]
            g1 = f1[q if f1.shape[0] > 1 else 0]
            g2 = f2[q if f2.shape[0] > 1 else 0]
            g3 = f3[q if f3.shape[0] > 1 else 0]
            if i >= n_pol:
                _chain_run(dep[q], Ai[q], g0, g1, g2, g3, nf, i > n_pol)
                continue
            _chain_run(A[q], Ai[q], g0, g1, g2, g3, nf, summed)
            _chain_run(B[q], Bi[q], g0, g1, g2, g3, nf, summed)
            _chain_run(C[q], Ci[q], g0, g1, g2, g3, nf, summed)
            _chain_run(S[q], Si[q], g0, g1, g2, g3, nf, summed)
            if has_depol[i]:
                _chain_run(D[q], Di[q], g0, g1, g2, g3, nf, summed)


#: (As, Bs, Cs, Ss, Ds: tuples of K (L, N) float64 arrays (dummies where unused), has_depol (K,) bool, factors:
#: a tuple of K tuples of 4 (1 or L, N) float64 arrays, n_factors (K,) int64: how many of them a term has, n_pol,
#: summed, out A, B, C, S, D, dep (L, N)); None without Numba.
chain_sum_loop = _chain_sum_loop
