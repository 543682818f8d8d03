"""Fresnel and Lambert against NIST SCATMECH (shared/oracles), through the `mueller` entry point."""

import json
import subprocess
import sys

import numpy as np
import pytest

from engine.materials.catalogue import make_model
from engine.materials.evaluate import mueller_at
from engine.polarisation.fresnel import fresnel_amplitudes
from tests.conftest import REPO, shared_path


def _records(name):
    with open(shared_path("oracles", name)) as fh:
        return json.load(fh)["records"]


FRESNEL = _records("scatmech_fresnel.json")
LAMBERT = _records("scatmech_lambert.json")


@pytest.mark.parametrize("rec", FRESNEL, ids=lambda r: f"{r['material']}-{r['theta_i_deg']:.6g}-{r['case']}")
def test_fresnel_matches_scatmech(rec):
    model = make_model("fresnel", {"n": rec["n"], "k": rec["k"]})
    out = mueller_at(model, rec["theta_i_deg"], rec["theta_r_deg"], rec["phi_r_deg"], 550.0, "sp")
    assert np.max(np.abs(np.array(out["brdf"]))) == 0.0
    np.testing.assert_allclose(np.array(out["delta"]), np.array(rec["M"]), rtol=0, atol=1e-9)


@pytest.mark.parametrize("rec", FRESNEL[::7], ids=lambda r: f"{r['material']}-{r['theta_i_deg']:.6g}")
def test_fresnel_amplitudes_match_scatmech(rec):
    cos_t = np.cos(np.radians(rec["theta_i_deg"])) if rec["theta_i_deg"] != 90 else 0.0
    r_s, r_p = fresnel_amplitudes(cos_t, rec["n"] + 1j * rec["k"])
    assert abs(r_s - complex(*rec["rs"])) < 1e-9
    assert abs(r_p - complex(*rec["rp"])) < 1e-9


@pytest.mark.parametrize("rec", LAMBERT, ids=lambda r: f"{r['theta_i_deg']}-{r['theta_r_deg']}-{r['phi_r_deg']}")
def test_lambert_matches_scatmech(rec):
    model = make_model("lambert", {"albedo": rec["reflectance"]})
    out = mueller_at(model, rec["theta_i_deg"], rec["theta_r_deg"], rec["phi_r_deg"], 550.0, "sp")
    assert out["delta"] is None
    np.testing.assert_allclose(np.array(out["brdf"]), np.array(rec["M"]), rtol=0, atol=1e-12)


@pytest.mark.subprocess
def test_mueller_cli_prints_json_matching_the_oracle():
    rec = next(r for r in FRESNEL if r["material"] == "gold_like" and r["theta_i_deg"] == 45.0)
    proc = subprocess.run([sys.executable, "-m", "engine", "mueller", "--model", "fresnel", "--param", "n=0.47",
                           "--param", "k=2.4", "--theta-i", "45", "--theta-o", "45", "--phi-o", "0",
                           "--wavelength-nm", "550", "--basis", "scattering"],
                          cwd=REPO, capture_output=True, text=True, check=True)
    out = json.loads(proc.stdout)
    assert out["basis"] == "scattering"
    np.testing.assert_allclose(np.array(out["delta"]), np.array(rec["M"]), atol=1e-9)
    assert np.array(out["brdf"]).shape == (4, 4)


@pytest.mark.subprocess
def test_mueller_cli_rejects_bad_parameter_with_field_name():
    proc = subprocess.run([sys.executable, "-m", "engine", "mueller", "--model", "fresnel", "--param", "n=0.47",
                           "--param", "k=-2", "--theta-i", "45", "--theta-o", "45"],
                          cwd=REPO, capture_output=True, text=True)
    assert proc.returncode == 2
    assert "param.k" in proc.stderr and "[0" in proc.stderr
    assert "Traceback" not in proc.stderr
