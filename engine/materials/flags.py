"""What a material can do: its lobes and capabilities (like Mitsuba 3's BSDFFlags / pbrt-v4's BxDFFlags).

Every BSDF reports ``flags`` (engine.materials.base.BSDF), set per instance where the parameters
matter (a conductor with κ ≡ 0 does not retard, a Lambert with a grey albedo is the same at every
wavelength).  Readers test bits instead of the model's class: the integrator (next-event
estimation only where a non-Dirac lobe exists, one Mueller product per path where nothing depends
on λ), the effect analysis (scalar / linear / full Stokes transport) and the layered-coat
simplification.

Lobes, as in Mitsuba 3 (a lobe is reported if the model has it structurally, even where its weight
happens to be 0 for some directions or wavelengths):

- DIFFUSE_*: scattering into a 2D set of directions with a depolarising (Lambertian-like) lobe,
- GLOSSY_*: scattering into a 2D set of directions otherwise (microfacet lobes),
- DELTA_*: scattering into a discrete set of directions (Dirac lobes: smooth mirrors, refraction),
- NULL: light passes straight through, ω_i = −ω_o (thin filter sheets); counts as transmission
  and as a Dirac lobe (as Mitsuba 3's ``Null``).

Capabilities (docs/physics.md §0 conventions; lights are unpolarised):

- POLARISING: the Mueller matrix can change the state of polarisation (not a pure depolariser),
- RETARDING: it can create a phase difference between s and p, i.e. circular polarisation
  (complex index κ > 0, reachable total internal reflection, retarder sheets),
- WAVELENGTH_DEPENDENT: the Mueller matrix can differ between wavelengths,
- SEPARABLE_DIFFUSE: ``eval`` returns the diffuse lobes as a depolarising MuellerValue or an ABCS
  ``depol`` share, apart from the polarising lobes, so a coat above can treat them apart
  (Weidlich–Wilkie's internal-reflection factor c_ms); models that fold a diffuse term into a
  "general" matrix (HTSG, a layered stack) do not set it,
- BATCHED: the shader serves several materials in one call and reads each point's member from
  ``ShadingPoint.material`` (engine.materials.batching); a property of the shader, not the physics.
"""

from __future__ import annotations

import enum

__all__ = ["BSDFFlags"]


class BSDFFlags(enum.IntFlag):
    """Lobes and capabilities of a material model (see the module docstring)."""

    NONE = 0
    # --- lobes
    NULL = 1 << 0
    DIFFUSE_REFLECTION = 1 << 1
    DIFFUSE_TRANSMISSION = 1 << 2
    GLOSSY_REFLECTION = 1 << 3
    GLOSSY_TRANSMISSION = 1 << 4
    DELTA_REFLECTION = 1 << 5
    DELTA_TRANSMISSION = 1 << 6
    # --- capabilities
    POLARISING = 1 << 8
    RETARDING = 1 << 9
    WAVELENGTH_DEPENDENT = 1 << 10
    SEPARABLE_DIFFUSE = 1 << 11
    BATCHED = 1 << 12
    # --- compounds (aliases; ``has`` asks for any of their bits)
    REFLECTION = DIFFUSE_REFLECTION | GLOSSY_REFLECTION | DELTA_REFLECTION
    TRANSMISSION = DIFFUSE_TRANSMISSION | GLOSSY_TRANSMISSION | DELTA_TRANSMISSION | NULL
    DIFFUSE = DIFFUSE_REFLECTION | DIFFUSE_TRANSMISSION
    GLOSSY = GLOSSY_REFLECTION | GLOSSY_TRANSMISSION
    SMOOTH = DIFFUSE | GLOSSY
    DELTA = DELTA_REFLECTION | DELTA_TRANSMISSION | NULL
    LOBES = SMOOTH | DELTA

    def has(self, mask: BSDFFlags) -> bool:
        """True if any bit of ``mask`` is set (e.g. ``flags.has(BSDFFlags.DELTA)``: some Dirac lobe)."""
        return bool(self & mask)

    @property
    def lobes(self) -> BSDFFlags:
        """The lobe bits only."""
        return self & BSDFFlags.LOBES

    @property
    def is_delta_only(self) -> bool:
        """Every lobe is a Dirac delta (there is at least one): next-event estimation is useless."""
        return self.has(BSDFFlags.DELTA) and not self.has(BSDFFlags.SMOOTH)

    @property
    def transmits(self) -> bool:
        """Some lobe lets light through the surface (refraction, null pass-through)."""
        return self.has(BSDFFlags.TRANSMISSION)

    @property
    def polarising(self) -> bool:
        return self.has(BSDFFlags.POLARISING)

    @property
    def retarding(self) -> bool:
        return self.has(BSDFFlags.RETARDING)

    @property
    def wavelength_dependent(self) -> bool:
        return self.has(BSDFFlags.WAVELENGTH_DEPENDENT)

    @property
    def batched(self) -> bool:
        return self.has(BSDFFlags.BATCHED)

    @staticmethod
    def when(condition: bool, flags: BSDFFlags) -> BSDFFlags:
        """``flags`` if ``condition`` else NONE (for composing instance flags)."""
        return flags if condition else BSDFFlags.NONE


#: What an unknown model is assumed to do (conservative: every reflection lobe, all capabilities
#: that make a reader take the safe, general path; no transmission, as a BSDF without flags had).
UNKNOWN_MODEL_FLAGS = (BSDFFlags.REFLECTION | BSDFFlags.SEPARABLE_DIFFUSE | BSDFFlags.POLARISING
                       | BSDFFlags.RETARDING | BSDFFlags.WAVELENGTH_DEPENDENT)
