"""Properties of the polarisation algebra: Fresnel, Jones→Mueller, frames, realisability (docs/physics.md §0, §4)."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.polarisation.frames import (frame_rotation, plane_of_incidence_axis, rotate_mueller_frames,
                                        rotate_stokes_frame, rotation_mueller)
from engine.polarisation.fresnel import (fresnel_amplitudes, fresnel_reflection_abcs, fresnel_reflection_mueller,
                                         fresnel_transmission_abcs, fresnel_transmission_mueller)
from engine.polarisation.mueller import (abcs_matrix, apply, depolarisation_index_sq_excess, is_realisable,
                                         linear_polariser, mueller_from_jones, realisability_report,
                                         stokes_from_jones_vector)
from engine.polarisation.stokes import (angle_of_linear_polarisation, degree_of_circular_polarisation,
                                        degree_of_linear_polarisation, degree_of_polarisation)

# Hard cases mixed into random cosines: normal, grazing, Brewster (glass), near-grazing.
COS_HARD = [1.0, 0.0, math.cos(math.atan(1.5)), math.cos(math.radians(89.99)), 1e-12]
cosines = st.one_of(st.sampled_from(COS_HARD), st.floats(0.0, 1.0))
indices = st.one_of(st.sampled_from([(1.5, 0.0), (1 / 1.5, 0.0), (0.47, 2.4), (1.0, 0.0), (0.2, 50.0)]),
                    st.tuples(st.floats(0.05, 10.0), st.floats(0.0, 50.0)))


def test_physics_md_check_values():
    A, B, C, S = fresnel_reflection_abcs(math.cos(math.radians(45)), 0.47 + 2.4j)
    assert abs(A - 0.761655) < 1e-6 and abs(B - 0.070002) < 1e-6
    assert abs(C + 0.652013) < 1e-6 and abs(S + 0.387424) < 1e-6
    A, B, C, S = fresnel_reflection_abcs(math.cos(math.radians(45)), 1.5)
    assert abs(A + B - 0.092013) < 1e-6 and abs(A - B - 0.008466) < 1e-6
    assert abs(C + 0.027911) < 1e-6 and S == 0.0


@settings(max_examples=300, deadline=None)
@given(cosines, indices)
def test_fresnel_reflection_is_a_pure_realisable_jones_matrix(c, nk):
    eta = nk[0] + 1j * nk[1]
    M = fresnel_reflection_mueller(c, eta)
    assert np.all(np.isfinite(M))
    assert is_realisable(M, tol=1e-9)
    assert abs(depolarisation_index_sq_excess(M)) < 1e-9          # non-depolarising
    r_s, r_p = fresnel_amplitudes(c, eta)
    np.testing.assert_allclose(mueller_from_jones(np.array([[r_s, 0], [0, r_p]])), M, atol=1e-12)
    assert M[0, 0] <= 1.0 + 1e-12


@settings(max_examples=200, deadline=None)
@given(cosines, st.floats(0.05, 5.0))
def test_transmission_is_a_realisable_diattenuator_conserving_energy(c, n):
    Ar, Br, _, _ = fresnel_reflection_abcs(c, n)
    At, Bt, Ct, St = fresnel_transmission_abcs(c, n)
    sin2_t = (1 - c * c) / (n * n)
    if sin2_t < 1:                       # below the critical angle: R + T = 1 per polarisation
        assert abs((Ar + Br) + (At + Bt) - 1) < 1e-12
        assert abs((Ar - Br) + (At - Bt) - 1) < 1e-12
    elif sin2_t > 1:                     # total internal reflection: nothing is transmitted
        assert At == 0 and abs(Ar - 1) < 1e-12
    assert St == 0
    assert is_realisable(fresnel_transmission_mueller(c, n), tol=1e-9)


def test_normal_incidence_is_F_diag_1_1_m1_m1():
    for eta in (1.5, 0.47 + 2.4j, 1 / 1.33):
        M = fresnel_reflection_mueller(1.0, eta)
        F = M[0, 0]
        np.testing.assert_allclose(M, F * np.diag([1, 1, -1, -1]), atol=1e-15)


def test_brewster_reflection_is_fully_s_polarised():
    c = math.cos(math.atan(1.5))
    A, B, C, S = fresnel_reflection_abcs(c, 1.5)
    assert abs(A - B) < 1e-15                       # F_p = 0
    out = apply(abcs_matrix(A, B, C, S), np.array([1.0, 0, 0, 0]))
    assert abs(out[1] / out[0] - 1) < 1e-12         # S1/S0 = +1: along s


def test_total_internal_reflection_retards_and_keeps_energy():
    c = math.cos(math.radians(60))                   # glass → air, beyond the critical angle 41.8°
    A, B, C, S = fresnel_reflection_abcs(c, 1 / 1.5)
    assert abs(A - 1) < 1e-12 and abs(B) < 1e-12
    assert abs(C * C + S * S - 1) < 1e-12 and abs(S) > 0.1   # pure retarder with δ ≠ 0, π


def test_jones_to_mueller_matches_the_stokes_definition():
    rng = np.random.default_rng(1)
    for _ in range(50):
        J = rng.normal(size=(2, 2)) + 1j * rng.normal(size=(2, 2))
        E = rng.normal(size=2) + 1j * rng.normal(size=2)
        np.testing.assert_allclose(apply(mueller_from_jones(J), stokes_from_jones_vector(E)),
                                   stokes_from_jones_vector(J @ E), atol=1e-10)


def test_right_circular_has_positive_s3():
    # E = (1, −i)/√2 with e^{−iωt}: E_x(t) = cos ωt, E_y(t) = −sin ωt = cos(ωt + π/2), so E_y leads E_x by 90°:
    # right-circular in the optics convention, S3 = 2 Im(E_x E_y*) = +1 (docs/physics.md §0).
    S = stokes_from_jones_vector(np.array([1.0, -1j]) / np.sqrt(2))
    np.testing.assert_allclose(S, [1, 0, 0, 1], atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi), cosines, indices)
def test_frame_rotations_transform_like_R_out_M_R_in_T(a_in, a_out, c, nk):
    M = fresnel_reflection_mueller(c, nk[0] + 1j * nk[1])
    k_in = np.array([0.3, -0.2, -0.93])
    k_in /= np.linalg.norm(k_in)
    k_out = np.array([0.5, 0.1, 0.86])
    k_out /= np.linalg.norm(k_out)
    x_in = np.cross(k_in, [0.0, 0.0, 1.0])
    x_in /= np.linalg.norm(x_in)
    x_out = np.cross(k_out, [0.0, 0.0, 1.0])
    x_out /= np.linalg.norm(x_out)

    def rotated(x, k, a):
        return math.cos(a) * x + math.sin(a) * np.cross(k, x)

    x_in2, x_out2 = rotated(x_in, k_in, a_in), rotated(x_out, k_out, a_out)
    M2 = rotate_mueller_frames(M, x_in, x_in2, k_in, x_out, x_out2, k_out)
    S = np.array([1.0, 0.3, -0.4, 0.5])
    # Same physics in either frame pair: rotate input to frame 2, apply M2, rotate back.
    S2_in = rotate_stokes_frame(S, x_in, x_in2, k_in)
    back = rotate_stokes_frame(apply(M2, S2_in), x_out2, x_out, k_out)
    np.testing.assert_allclose(back, apply(M, S), atol=1e-12)
    assert abs(M2[0, 0] - M[0, 0]) < 1e-14                               # M00 is frame-invariant
    dop = lambda m: math.hypot(m[1, 0], m[2, 0], m[3, 0]) / m[0, 0] if m[0, 0] > 0 else 0  # noqa: E731
    assert abs(dop(M2) - dop(M)) < 1e-12


def test_rotation_by_45_degrees_swaps_s1_into_s2():
    k = np.array([0.0, 0.0, 1.0])
    x = np.array([1.0, 0.0, 0.0])
    x45 = np.array([1.0, 1.0, 0.0]) / math.sqrt(2)
    S = rotate_stokes_frame(np.array([1.0, 1.0, 0.0, 0.0]), x, x45, k)   # horizontal light
    np.testing.assert_allclose(S, [1, 0, -1, 0], atol=1e-15)             # is at −45° in the new frame
    c2, s2 = frame_rotation(x, x45, k)
    assert abs(c2) < 1e-15 and abs(s2 - 1) < 1e-15
    np.testing.assert_allclose(rotation_mueller(x, x45, k) @ np.array([1, 1, 0, 0]), [1, 0, -1, 0], atol=1e-15)


def test_plane_of_incidence_axis_handles_normal_incidence():
    n = np.array([[0.0], [0.0], [1.0]])
    s = plane_of_incidence_axis(n, -n)
    assert np.all(np.isfinite(s)) and abs(np.linalg.norm(s) - 1) < 1e-15 and abs(s[2, 0]) < 1e-15


def test_realisability_report_rejects_unphysical_matrices():
    bad = np.diag([1.0, 1.0, 1.0, -1.0])  # mirror of S3 alone (time reversal): not a physical Mueller matrix
    rep = realisability_report(bad)
    assert not rep["coherency_psd"]
    assert not is_realisable(np.array([[1.0, 1.2, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]))
    assert is_realisable(linear_polariser(0.3))


def test_derived_quantities():
    S = np.array([[2.0, 0.0], [1.0, 0.0], [1.0, 0.0], [-1.0, 0.0]])   # (4, N) layout, second pixel dark
    np.testing.assert_allclose(degree_of_polarisation(S), [math.sqrt(3) / 2, 0.0])
    np.testing.assert_allclose(degree_of_linear_polarisation(S), [math.sqrt(2) / 2, 0.0])
    np.testing.assert_allclose(degree_of_circular_polarisation(S), [-0.5, 0.0])
    np.testing.assert_allclose(angle_of_linear_polarisation(S)[0], math.pi / 8)


def test_index_matched_and_subnormal_grazing_cases_stay_finite():
    # Found by hypothesis: a subnormal cosθ overflowed complex division; an index-matched
    # grazing ray was treated as total internal reflection.
    for c in (2.225073858507e-311, 5e-324, 0.0):
        for eta in (1.0, 1.5, 1 / 1.5, 0.47 + 2.4j):
            M = fresnel_reflection_mueller(c, eta)
            assert np.all(np.isfinite(M)) and is_realisable(M)
    At, Bt, Ct, _ = fresnel_transmission_abcs(0.0, 1.0)
    assert At == 1.0 and Bt == 0.0 and Ct == 1.0      # no interface: everything passes
