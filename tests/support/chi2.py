"""Pearson chi-square goodness-of-fit test of a sampler against the density it claims (shared by every
sampler test).

Method (as Mitsuba 3's chi2 test, written afresh):

1. Draw N samples and histogram them over a grid of cells of the parameter domain; directions use
   (cos θ, φ) cells, which have equal solid angle (dω = dcos θ dφ, so the Jacobian is 1).
2. Integrate the claimed pdf over every cell with composite Gauss–Legendre quadrature (2·``sub``
   panels of ``order`` nodes per cell and axis); N times that is the cell's expected count. The
   same with ``sub`` panels must agree to within a shift of 1 in the statistic (else the test fails
   asking for finer quadrature), so quadrature error cannot pass or fail a sampler.
3. Add one cell, "elsewhere", for the samples the grid does not cover (invalid samples, Dirac
   lobes): its expected count is N (1 − ∫ pdf over the grid), so the pdf's total mass is tested too.
4. Sort the cells by expected count and merge the smallest, in order, until every merged cell
   expects at least ``min_expected`` (5) samples, where Pearson's statistic is close to χ².
5. Statistic Σ (O − E)²/E, dof = cells − 1, p-value = χ² survival function, computed here as the
   regularised upper incomplete gamma function Q(dof/2, x/2) (series or continued fraction, as in
   Numerical Recipes §6.2; scipy is not a dependency).
6. Reject when p < the Šidák-corrected level 1 − (1 − α)^(1/test_count), so that a family of
   ``test_count`` tests (e.g. the parametrised cases of one sampler) fails a correct sampler with
   probability α in all; α defaults to 0.01 as in Mitsuba.

Samples outside the domain, or in a cell whose expected count is 0, fail the test outright.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: Family-wise significance level (probability that a correct sampler fails one of its family's tests).
ALPHA = 0.01
#: Smallest expected count of a cell after merging (Pearson's statistic is ~χ² above it).
MIN_EXPECTED = 5.0
#: Largest shift of Pearson's statistic allowed from quadrature error (its spread is √(2 dof) ≥ √2).
QUADRATURE_SHIFT = 1.0
#: Samples this far outside the domain (in its own units) are clamped into the edge cells; beyond, they fail.
DOMAIN_SLACK = 1e-9


# --- the chi-square distribution ------------------------------------------------------------------------


def chi2_sf(x: float, dof: int) -> float:
    """P(χ²_dof ≥ x): the regularised upper incomplete gamma function Q(dof/2, x/2)."""
    if dof <= 0:
        raise ValueError(f"dof must be ≥ 1, got {dof}")
    a, y = 0.5 * dof, 0.5 * float(x)
    if not math.isfinite(y):
        return 0.0 if y > 0 else 1.0
    if y <= 0.0:
        return 1.0
    log_prefactor = -y + a * math.log(y) - math.lgamma(a)  # log(e^{−y} y^a / Γ(a))
    if y < a + 1.0:
        # Series P(a, y) = e^{−y} y^a / Γ(a) · Σ_n y^n / (a (a+1) … (a+n)); converges fast for y < a + 1.
        term = total = 1.0 / a
        k = a
        for _ in range(100_000):
            k += 1.0
            term *= y / k
            total += term
            if term < total * 1e-17:
                break
        return max(0.0, 1.0 - total * math.exp(log_prefactor))
    # Continued fraction for Q(a, y) (modified Lentz); converges fast for y ≥ a + 1, where the series
    # would lose Q to cancellation in 1 − P.
    tiny = 1e-300
    b = y + 1.0 - a
    c = 1.0 / tiny
    d = 1.0 / b
    h = d
    for i in range(1, 100_000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = tiny if abs(d) < tiny else d
        c = b + an / c
        c = tiny if abs(c) < tiny else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-16:
            break
    return math.exp(log_prefactor) * h


def sidak_level(alpha: float, test_count: int) -> float:
    """Per-test level such that ``test_count`` independent tests at it fail with probability ``alpha`` in all."""
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")
    if test_count < 1:
        raise ValueError(f"test_count must be ≥ 1, got {test_count}")
    return 1.0 - (1.0 - alpha) ** (1.0 / test_count)


# --- Pearson's test with merged cells -----------------------------------------------------------------


@dataclass(frozen=True)
class ChiSquareResult:
    """Outcome of Pearson's test: statistic, degrees of freedom, p-value and how cells were merged."""

    statistic: float
    dof: int
    p_value: float
    cells: int            # cells with a non-zero expected count, before merging
    merged_into: int      # cells after merging (dof + 1)
    total: float          # number of samples (= total expected count)

    def rejected(self, alpha: float = ALPHA, test_count: int = 1) -> bool:
        return not self.p_value >= sidak_level(alpha, test_count)

    def __str__(self):
        return (f"χ² = {self.statistic:.2f}, dof = {self.dof}, p = {self.p_value:.3g} "
                f"({self.cells} cells merged into {self.merged_into}, {self.total:.0f} samples)")


def pearson(observed, expected, min_expected: float = MIN_EXPECTED) -> ChiSquareResult:
    """Pearson's test of observed counts against expected counts over a partition of the whole domain.

    The two totals must agree (include an "elsewhere" cell); cells expected to be empty must be empty.
    Cells are merged smallest-first until each expects at least ``min_expected`` samples.
    """
    obs = np.asarray(observed, dtype=np.float64).ravel()
    exp = np.asarray(expected, dtype=np.float64).ravel()
    if obs.shape != exp.shape:
        raise ValueError(f"observed and expected differ in size: {obs.size} vs {exp.size}")
    if not (np.all(np.isfinite(exp)) and np.all(exp >= 0)):
        raise AssertionError("expected counts must be finite and ≥ 0 (is the pdf negative or NaN somewhere?)")
    if not (np.all(np.isfinite(obs)) and np.all(obs >= 0)):
        raise ValueError("observed counts must be finite and ≥ 0")
    total = obs.sum()
    if abs(total - exp.sum()) > 1e-6 * max(total, 1.0):
        raise ValueError(f"observed and expected totals differ ({total} vs {exp.sum()}): the cells must "
                         f"partition the whole domain")
    impossible = (exp == 0) & (obs > 0)
    if np.any(impossible):
        raise AssertionError(f"{obs[impossible].sum():.0f} samples in {impossible.sum()} cells of zero probability")
    keep = exp > 0
    obs, exp = obs[keep], exp[keep]
    order = np.argsort(exp, kind="stable")
    obs, exp = obs[order], exp[order]
    # Greedy merge in ascending order: a group closes once it expects min_expected; a remainder too
    # small to close joins the last closed group.
    group_o, group_e = [], []
    acc_o = acc_e = 0.0
    for o, e in zip(obs, exp):
        acc_o += o
        acc_e += e
        if acc_e >= min_expected:
            group_o.append(acc_o)
            group_e.append(acc_e)
            acc_o = acc_e = 0.0
    if acc_e > 0:
        if not group_e:
            raise AssertionError(f"only {acc_e:.2f} samples expected in all: too few samples for the test")
        group_o[-1] += acc_o
        group_e[-1] += acc_e
    go, ge = np.array(group_o), np.array(group_e)
    dof = go.size - 1
    if dof < 1:
        raise AssertionError("fewer than two cells after merging: too few samples or cells for the test")
    statistic = float(np.sum((go - ge) ** 2 / ge))
    return ChiSquareResult(statistic, dof, chi2_sf(statistic, dof), int(keep.sum()), int(go.size), float(total))


def assert_accepted(result: ChiSquareResult, alpha: float = ALPHA, test_count: int = 1, what: str = "samples"):
    """Fail (AssertionError) when the test rejects the hypothesis that the samples follow the pdf."""
    level = sidak_level(alpha, test_count)
    assert not result.rejected(alpha, test_count), (
        f"{what} do not follow the pdf: {result}; rejected at level {level:.3g} "
        f"(family α = {alpha}, {test_count} tests)")


# --- quadrature -----------------------------------------------------------------------------------------


def _cell_nodes(edges: np.ndarray, order: int, sub: int):
    """Composite Gauss–Legendre nodes and weights over every cell of ``edges``: arrays (cells, sub·order)."""
    if order < 1 or sub < 1:
        raise ValueError(f"quadrature order and sub must be ≥ 1, got {order}, {sub}")
    x, w = np.polynomial.legendre.leggauss(order)
    t = (np.arange(sub)[:, None] + 0.5 * (x[None, :] + 1.0)).ravel() / sub       # in [0, 1], (sub·order,)
    wt = np.tile(0.5 * w / sub, sub)                                             # sums to 1
    lo, width = edges[:-1, None], np.diff(edges)[:, None]
    return lo + width * t[None, :], width * wt[None, :]


def interval_cell_mass(pdf: Callable[[np.ndarray], np.ndarray], edges, order: int = 4, sub: int = 1) -> np.ndarray:
    """∫ pdf(x) dx over every interval of ``edges`` (1-D densities; ``pdf`` maps (M,) to (M,))."""
    edges = np.asarray(edges, dtype=np.float64)
    nodes, weights = _cell_nodes(edges, order, sub)
    values = np.asarray(pdf(nodes.ravel()), dtype=np.float64).reshape(nodes.shape)
    return np.sum(values * weights, axis=1)


def hemisphere_cell_mass(pdf: Callable[[np.ndarray], np.ndarray], n_cos: int, n_phi: int, order: int = 6,
                         sub: int = 1, cos_range=(0.0, 1.0)) -> np.ndarray:
    """∫ pdf(ω) dω over the (cos θ, φ) cells, (n_cos, n_phi); pdf is per steradian and maps unit vectors
    (3, M) in the local frame (normal +z, φ from +x towards +y, φ ∈ [0, 2π)) to (M,)."""
    ce, cw = _cell_nodes(np.linspace(cos_range[0], cos_range[1], n_cos + 1), order, sub)
    pe, pw = _cell_nodes(np.linspace(0.0, 2.0 * math.pi, n_phi + 1), order, sub)
    C = ce[:, :, None, None]
    P = pe[None, None, :, :]
    C, P = np.broadcast_arrays(C, P)                                             # (n_cos, q, n_phi, q)
    s = np.sqrt(np.maximum(1.0 - C * C, 0.0))
    wi = np.stack((s * np.cos(P), s * np.sin(P), C)).reshape(3, -1)
    values = np.asarray(pdf(wi), dtype=np.float64).reshape(C.shape)
    return np.einsum("iajb,ia,jb->ij", values, cw, pw)


# --- histograms ------------------------------------------------------------------------------------------


def _check_inside(x: np.ndarray, lo: float, hi: float, what: str):
    slack = DOMAIN_SLACK * (hi - lo)
    outside = ~((x >= lo - slack) & (x <= hi + slack))   # NaN counts as outside
    if np.any(outside):
        raise AssertionError(f"{outside.sum()} samples with {what} outside [{lo}, {hi}], e.g. {x[outside][:3]}")


def direction_histogram(wi, n_cos: int, n_phi: int, cos_range=(0.0, 1.0)) -> np.ndarray:
    """Counts of unit vectors (3, M) over the (cos θ, φ) cells of :func:`hemisphere_cell_mass`."""
    wi = np.asarray(wi, dtype=np.float64)
    lo, hi = cos_range
    _check_inside(wi[2], lo, hi, "cos θ")
    ic = np.clip(((wi[2] - lo) * (n_cos / (hi - lo))).astype(np.int64), 0, n_cos - 1)
    phi = np.mod(np.arctan2(wi[1], wi[0]), 2.0 * math.pi)
    ip = np.minimum((phi * (n_phi / (2.0 * math.pi))).astype(np.int64), n_phi - 1)
    return np.bincount(ic * n_phi + ip, minlength=n_cos * n_phi).astype(np.float64).reshape(n_cos, n_phi)


# --- whole tests -----------------------------------------------------------------------------------------


def _converged_mass(integrate: Callable[[int, int], np.ndarray], n: int, order: int, sub: int) -> np.ndarray:
    """Cell masses ``integrate(order, 2·sub)``, checked against ``integrate(order, sub)``: the difference
    (an estimate of the coarser rule's error) may shift Pearson's statistic by at most QUADRATURE_SHIFT."""
    coarse, fine = integrate(order, sub), integrate(order, 2 * sub)
    expected, error = n * fine, n * (coarse - fine)
    significant = expected > 0
    shift = float(np.sum(error[significant] ** 2 / expected[significant]))
    if not shift <= QUADRATURE_SHIFT:
        raise AssertionError(f"quadrature too coarse for the pdf (order {order}, sub {sub} vs {2 * sub} shifts "
                             f"χ² by {shift:.3g}): raise order or sub")
    return fine


def _with_elsewhere(counts: np.ndarray, mass: np.ndarray, n: int, mass_tolerance: float):
    """Append the "elsewhere" cell (samples off the grid; expected n·(1 − Σ mass))."""
    total_mass = float(mass.sum())
    if total_mass > 1.0 + mass_tolerance:
        raise AssertionError(f"the pdf integrates to {total_mass:.9g} > 1 over the grid")
    observed = np.append(counts.ravel(), n - counts.sum())
    # A mass within the tolerance above 1 is quadrature error: scale it to 1 so the totals agree.
    expected = np.append(n * mass.ravel() / max(total_mass, 1.0), n * max(1.0 - total_mass, 0.0))
    return observed, expected


def direction_sampler_test(wi, on_grid, pdf, *, n_cos: int, n_phi: int, order: int = 6, sub: int = 1,
                           cos_range=(0.0, 1.0), mass_tolerance: float = 1e-6) -> ChiSquareResult:
    """Test directions wi (3, N) drawn by a sampler against its claimed ``pdf`` (per steradian, see
    :func:`hemisphere_cell_mass`). ``on_grid`` (N,) marks the samples the pdf describes (valid,
    non-Dirac); the others fill the "elsewhere" cell, expected N (1 − ∫ pdf). ``mass_tolerance``:
    how far above 1 the quadrature of the pdf may come before the pdf is declared unnormalised."""
    wi = np.asarray(wi, dtype=np.float64)
    on_grid = np.broadcast_to(np.asarray(on_grid, dtype=bool), wi.shape[1:])
    counts = direction_histogram(wi[:, on_grid], n_cos, n_phi, cos_range)
    mass = _converged_mass(lambda o, s: hemisphere_cell_mass(pdf, n_cos, n_phi, o, s, cos_range), wi.shape[1],
                           order, sub)
    return pearson(*_with_elsewhere(counts, mass, wi.shape[1], mass_tolerance))


def interval_sampler_test(x, pdf, edges, *, order: int = 4, sub: int = 1,
                          mass_tolerance: float = 1e-6) -> ChiSquareResult:
    """Test 1-D samples x (N,) against their claimed density ``pdf`` over the intervals of ``edges``."""
    x = np.asarray(x, dtype=np.float64).ravel()
    edges = np.asarray(edges, dtype=np.float64)
    n_cells = edges.size - 1
    _check_inside(x, edges[0], edges[-1], "x")
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, n_cells - 1)
    counts = np.bincount(idx, minlength=n_cells).astype(np.float64)
    mass = _converged_mass(lambda o, s: interval_cell_mass(pdf, edges, o, s), x.size, order, sub)
    return pearson(*_with_elsewhere(counts, mass, x.size, mass_tolerance))
