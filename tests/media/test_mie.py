"""Lorenz–Mie (engine/media/mie_series.py, mie.py) against published numbers and analytic limits.

- Bohren & Huffman's appendix example (m = 1.55, x = 2π·0.525/0.6328) and Wiscombe's MIEV0 test cases
  (NCAR/TN-140, 1979/1996; the values as miepython's tests quote them): Q_ext, Q_sca, Q_back, g, and the
  amplitudes S1, S2 of case 14 (MIEV0 uses e^{+iωt}, m = n − iκ: its amplitudes are the complex
  conjugates of Bohren & Huffman's, which Polar follows);
- the tables: ∫ of the tabulated S11 equals π x² Q_sca of the series (the angle grid resolves the lobes);
- size parameter → 0: the normalised matrix is Rayleigh's (δ = 0);
- a large absorbing sphere (gold-like η = 0.47 + 2.4i, x ≈ 228): away from the forward diffraction lobe the
  light is reflected off the sphere, so the normalised matrix at Θ is the Fresnel reflection matrix at
  incidence (π − Θ)/2 — in particular the sign of its retardance element S, docs/physics.md §0;
- λ interpolation between tables; refused parameters; the mueller command.
"""

import json
import math

import numpy as np
import pytest

from engine import cli
from engine.errors import SceneError
from engine.media.catalogue import make_phase, phase_matrices_at
from engine.media.mie import sphere_table
from engine.media.mie_series import amplitudes, mie_coefficients
from engine.polarisation.fresnel import fresnel_reflection_abcs_numpy

#: (m (Polar's sign: Im ≥ 0), x, Q_ext or None, Q_sca, Q_back or None, g)
PUBLISHED = [
    (1.55, 2 * math.pi * 0.525 / 0.6328, 3.10543, 3.10543, 2.92534, 0.63314),          # Bohren & Huffman
    (1.55 + 0.1j, 2 * math.pi * 0.525 / 0.6328, 2.86165188243, 1.66424911991, 0.20599534080, 0.80128972639),
    (0.75, 0.099, None, 0.000007, None, 0.001448),                                    # MIEV0 case 5
    (0.75, 10.0, None, 2.232265, None, 0.896473),                                     # 7
    (0.75, 1000.0, None, 1.997908, None, 0.844944),                                   # 8
    (1.33 + 1e-5j, 1.0, None, 0.093923, None, 0.184517),                              # 9
    (1.33 + 1e-5j, 100.0, None, 2.096594, None, 0.868959),                            # 10
    (1.5 + 1j, 0.055, 0.101491, 0.000011, None, 0.000491),                            # 12
    (1.5 + 1j, 1.0, None, 0.6634538, None, 0.192136),                                 # 14
    (1.5 + 1j, 100.0, 2.097502, 1.283697, None, 0.850252),                            # 15
    (10 + 10j, 1.0, None, 2.049405, None, -0.110664),                                 # 17
    (10 + 10j, 100.0, None, 1.836785, None, 0.556215),                                # 18
]


@pytest.mark.parametrize("m, x, q_ext, q_sca, q_back, g", PUBLISHED)
def test_efficiencies_published(m, x, q_ext, q_sca, q_back, g):
    """Within half a unit of the last published digit (B&H print 5 decimals, MIEV0 6)."""
    c = mie_coefficients(m, x)
    tol = 5e-6 if x == PUBLISHED[0][1] else 6e-7
    assert c.q_sca == pytest.approx(q_sca, abs=tol)
    assert c.g == pytest.approx(g, abs=tol)
    if q_ext is not None:
        assert c.q_ext == pytest.approx(q_ext, abs=tol)
    if q_back is not None:
        assert c.q_back == pytest.approx(q_back, abs=tol)


def test_amplitudes_published():
    """MIEV0 case 14 (m = 1.5 − 1i in its convention, x = 1) at Θ = 0, 30, …, 180°."""
    s1_pub = [0.584080 + 0.190515j, 0.565702 + 0.187200j, 0.517525 + 0.178443j, 0.456340 + 0.167167j,
              0.400212 + 0.156643j, 0.362157 + 0.149391j, 0.348844 + 0.146829j]
    s2_pub = [0.584080 + 0.190515j, 0.500161 + 0.145611j, 0.287964 + 0.041054j, 0.0362285 - 0.0618265j,
              -0.174875 - 0.122959j, -0.305682 - 0.143846j, -0.348844 - 0.146829j]
    s1, s2 = amplitudes(mie_coefficients(1.5 + 1j, 1.0), np.cos(np.radians(np.arange(0, 181, 30))))
    np.testing.assert_allclose(s1, np.conj(s1_pub), atol=1.5e-6)
    np.testing.assert_allclose(s2, np.conj(s2_pub), atol=1.5e-6)


@pytest.mark.parametrize("m, x", [(1.55, 5.213), (1.33, 100.0), (1.5 + 1j, 1.0), (1.33, 0.01), (1.33 + 0.01j, 30.0)])
def test_table_integrates_to_q_sca(m, x):
    """2π ∫ S11 dμ of the table (its trapezoid sum) = π x² Q_sca of the series: the grid resolves the lobes."""
    assert sphere_table(m, x).norm == pytest.approx(math.pi * x * x * mie_coefficients(m, x).q_sca, rel=5e-4)


def test_small_spheres_are_rayleigh():
    """x ≈ 0.0057 (radius 0.5 nm at 550 nm): the normalised matrix is Rayleigh's (δ = 0) to 1e-4 of its peak
    (the size correction is O(x²))."""
    mie, rayleigh = make_phase("mie", {"radius": "0.0005", "n": "1.5"}), make_phase("rayleigh", {})
    mu = np.linspace(-1, 1, 41)
    np.testing.assert_allclose(mie.matrix(mu, 550.0), rayleigh.matrix(mu), atol=1e-4 * 3 / (8 * np.pi))


def test_large_absorbing_sphere_reflects_as_fresnel():
    """Gold-like sphere, radius 20 µm (x ≈ 228 at 550 nm): outside the diffraction lobe the normalised matrix
    is the Fresnel reflection matrix at incidence (π − Θ)/2 (B/A, C/A, S/A to 0.012; measured ≤ 0.009)."""
    eta = 0.47 + 2.4j
    phase = make_phase("mie", {"radius": "20", "n": "0.47", "k": "2.4"})
    angles = [60.0, 90.0, 120.0, 150.0]
    M = np.array(phase_matrices_at(phase, angles, 550.0)["mueller"])
    for theta, m in zip(angles, M):
        cos_i = np.array(math.cos(math.radians((180 - theta) / 2)))
        A, B, C, S = (float(v) for v in fresnel_reflection_abcs_numpy(cos_i, np.array(eta)))
        got = np.array([m[0, 1], m[2, 2], m[2, 3]]) / m[0, 0]
        np.testing.assert_allclose(got, [B / A, C / A, S / A], atol=0.012, err_msg=f"Θ = {theta}")
        assert m[1, 1] == m[0, 0] and m[3, 3] == m[2, 2] and m[3, 2] == -m[2, 3]


def test_wavelength_interpolation_and_sampling_blend():
    """Between two tables the elements are the linear blend; at a table wavelength exactly that table."""
    phase = make_phase("mie", {"radius": "0.4", "n": "1.5"})
    mu = np.linspace(-1, 1, 7)
    a, b, mid = phase.matrix(mu, 550.0), phase.matrix(mu, 555.0), phase.matrix(mu, 551.0)
    np.testing.assert_allclose(mid, 0.8 * a + 0.2 * b, rtol=1e-12, atol=1e-18)
    j = 38
    assert phase._bracket(np.array([550.0]))[0][0] == j and phase._bracket(np.array([550.0]))[1][0] == 0.0
    assert set(phase._tables) <= {j, j + 1}


def test_refused_parameters():
    with pytest.raises(SceneError, match="param.radius: must be a finite number in"):
        make_phase("mie", {"radius": "0"})
    with pytest.raises(SceneError, match="mie.n: equals the medium's index"):
        make_phase("mie", {"n": "1.33", "medium_n": "1.33"})


def test_mueller_command_prints_phase_matrices(capsys):
    """`mueller --model mie --scattering-angle …` prints the phase matrices (1/sr, scattering-plane frames)."""
    status = cli.main(["mueller", "--model", "mie", "--param", "radius=0.5", "--param", "k=0.01",
                       "--scattering-angle", "0", "--scattering-angle", "90", "--wavelength-nm", "600"])
    out = json.loads(capsys.readouterr().out)
    assert status == 0 and out["basis"] == "scattering" and out["scattering_angles_deg"] == [0.0, 90.0]
    expected = make_phase("mie", {"radius": "0.5", "k": "0.01"}).matrix(np.array([1.0, 0.0]), 600.0)
    np.testing.assert_allclose(out["mueller"], expected, rtol=1e-12)
    assert out["pdf"] == pytest.approx(expected[:, 0, 0].tolist())


@pytest.mark.parametrize("args, field", [
    (["--model", "rayleigh"], "--scattering-angle"),
    (["--model", "rayleigh", "--scattering-angle", "181"], "--scattering-angle"),
    (["--model", "rayleigh", "--scattering-angle", "nan"], "--scattering-angle"),
    (["--model", "rayleigh", "--scattering-angle", "9", "--theta-i", "3"], "--theta-i"),
    (["--model", "rayleigh", "--scattering-angle", "9", "--basis", "sp"], "--basis"),
    (["--model", "draine", "--scattering-angle", "9", "--param", "alpha=-1"], "param.alpha"),
    (["--model", "fresnel", "--param", "n=1.5", "--theta-i", "3", "--theta-o", "3", "--scattering-angle", "9"],
     "--scattering-angle"),
    (["--model", "fresnel", "--param", "n=1.5", "--theta-i", "3"], "--theta-o"),
])
def test_mueller_command_refuses_with_one_line(args, field, capsys):
    status = cli.main(["mueller", *args])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert status == 2 and len(lines) == 1 and lines[0].startswith(f"error: {field}: "), err
