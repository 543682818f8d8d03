"""A weighted sum of ABCS Mueller values in one compiled loop (engine.materials.mix's incoherent mixture).

``abcs_sum_loop`` is engine.materials.mix.abcs_sum_numpy's block sum per element, the same arithmetic in the
same order: for each of A, B, C, S the running sum 0 + a₁·w₁ + a₂·w₂ + … over the values (Python's ``sum`` of
the scaled arrays), without the scaled copies and the sums' temporaries.
"""

from __future__ import annotations

from . import jit


@jit
def _abcs_sum_loop(As, Bs, Cs, Ss, scales, A, B, C, S):
    L, N = A.shape
    K = len(As)
    for q in range(L):
        for k in range(N):
            a = 0.0
            b = 0.0
            c = 0.0
            s = 0.0
            for i in range(K):
                w = scales[i][k]
                a = a + As[i][q, k] * w
                b = b + Bs[i][q, k] * w
                c = c + Cs[i][q, k] * w
                s = s + Ss[i][q, k] * w
            A[q, k] = a
            B[q, k] = b
            C[q, k] = c
            S[q, k] = s


#: (As, Bs, Cs, Ss: tuples of K (L, N) float64 arrays, scales: a tuple of K (N,) arrays, out A, B, C, S (L, N));
#: None without Numba.
abcs_sum_loop = _abcs_sum_loop
