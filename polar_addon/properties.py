"""Polar's settings stored in .blend files: render settings (Scene), pass toggles (ViewLayer), the
polarisation of lights (Light), of a material's emission (Material) and of a Sky Texture (World).

Enum items carry explicit numbers: Blender stores enums as integers in files,
so the numbers are stable forever — add new items with new numbers, never
renumber or reorder.
"""

import math

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty,
                        PointerProperty, StringProperty)

POLARISATION_ITEMS = [
    ("AUTO", "Auto", "Choose the cheapest transport that is exact for this scene (reported in the stats)", 0),
    ("FULL", "Full Stokes", "Full 4×4 Mueller transport: linear and circular polarisation", 1),
    ("LINEAR", "Linear Only", "3×3 Mueller transport: S3 is 0 (exact only where nothing retards)", 2),
    ("OFF", "Off", "Scalar transport: S1 = S2 = S3 = 0 (exact only where everything depolarises)", 3),
]
POLARISATION_TO_ENGINE = {"AUTO": "auto", "FULL": "full", "LINEAR": "linear", "OFF": "off"}

SPECTRAL_ITEMS = [
    ("SPECTRAL", "Spectral", "Four wavelengths per path over 360–830 nm, CIE 1931 colour", 0),
    ("MONO", "Monochrome", "One wavelength (for verification); colours by their luminance", 1),
    ("RGB", "RGB (as Cycles)", "Red, green and blue channels multiplied as Cycles multiplies colours (a look-match "
     "with Cycles renders); models that need a wavelength use one per channel", 2),
]

VOLUME_MIE_ITEMS = [
    ("CYCLES", "Cycles' Fit", "Volume Scatter ▸ Mie as Cycles renders it: its fitted Henyey–Greenstein + Draine blend "
     "for the droplet diameter (depolarising: the same brightness as Cycles)", 0),
    ("LORENZ_MIE", "Lorenz–Mie", "Volume Scatter ▸ Mie as exact Lorenz–Mie scattering by water droplets (n = 1.33) "
     "of that diameter: polarising and retarding (fog bows, glories; slower, full Stokes)", 1),
]

SAMPLER_ITEMS = [
    ("INDEPENDENT", "Independent", "Every random number an independent hash of (seed, pixel, sample, dimension)", 0),
    ("STRATIFIED", "Stratified", "Pixel jitter, lens, wavelengths and the first bounce's light and BSDF numbers "
     "from per-pixel scrambled Sobol' points (as Cycles' Sobol' patterns): same expectation, less noise, most at "
     "the edges of bright lights seen by the camera, on lamp-lit surfaces, in depth of field and in colour", 1),
    ("SOBOL", "Sobol", "Stratified's numbers at the camera and first bounce, and every deeper bounce's (light "
     "choice and point, BSDF lobe and direction, roulette) from per-pixel shuffled, Owen-scrambled Sobol' "
     "sequences (as Cycles' Sobol-Burley pattern): same expectation, less noise (most in glass)", 2),
    ("PADDED", "Padded Sobol", "Every number of every bounce, the camera's too, from its own per-pixel shuffled "
     "Sobol' (0, 2)-sequence pair (as Mitsuba's ldsampler and pbrt's PaddedSobol), the pixel jitter Owen-"
     "scrambled, the others digitally shifted: same expectation, the least noise (rough metals, edges)", 3),
    ("CYCLES", "Cycles Sobol", "Cycles' Sobol-Burley pattern: each role's numbers (pixel jitter, lens, the light's "
     "choice and point, the BSDF's lobe and direction, roulette) one point of a per-pixel shuffled, Owen-scrambled "
     "Sobol' set, so a choice is stratified with its point: same expectation, less noise", 4),
]
HALVES_ITEMS = [
    ("AUTO", "Auto", "One sequence (as One Sequence), with adaptive sampling too", 0),
    ("ONE_SEQUENCE", "One Sequence", "A pixel's samples are one low-discrepancy sequence (as Cycles): less noise; "
     "adaptive sampling takes the error from two classes of its samples, as Cycles", 1),
    ("INDEPENDENT", "Independent Halves", "The even and the odd samples are two independently scrambled sequences, "
     "whose difference estimates the error (adaptive sampling's)", 2),
]
HALVES_TO_ENGINE = {"AUTO": "auto", "ONE_SEQUENCE": "one_sequence", "INDEPENDENT": "independent"}
PARALLEL_ITEMS = [
    ("AUTO", "Auto", "Worker processes where many materials would make threads slower and the render pays for "
     "starting them (a second or two, once per Blender session); otherwise threads", 0),
    ("THREADS", "Threads", "Worker threads of Blender's process", 1),
    ("PROCESSES", "Processes", "A pool of worker processes kept between renders: every core, also for scenes "
     "whose materials make threads contend (the first render starts them)", 2),
]
PARALLEL_TO_ENGINE = {"AUTO": "auto", "THREADS": "threads", "PROCESSES": "processes"}
SAMPLER_TO_ENGINE = {"INDEPENDENT": "independent", "STRATIFIED": "stratified", "SOBOL": "sobol", "PADDED": "padded",
                     "CYCLES": "cycles"}

PASS_NAMES = ("S0", "S1", "S2", "S3", "DoP", "DoLP", "AoLP", "DoCP", "Polariser",
              "VisDoP", "VisS1", "VisS2", "VisS3", "VisAoLP", "Noise", "Polarisation Mosaic",
              "Denoising Albedo", "Denoising Normal")
#: Denoising guides for the compositor's Denoise node (as Cycles' Denoising Data); opt-in.
DENOISE_PASSES = ("Denoising Albedo", "Denoising Normal")
#: Passes on by default; the false-colour visualisation passes are opt-in.
DEFAULT_PASSES = ("S0", "S1", "S2", "S3", "DoP", "DoLP", "AoLP", "DoCP", "Polariser")

POLARISER_TYPE_ITEMS = [
    ("LINEAR", "Linear", "Linear polariser at the given angle (Malus's law)", 0),
    ("CIRCULAR_RIGHT", "Circular (Right)", "Passes right-circular light (quarter-wave plate + polariser)", 1),
    ("CIRCULAR_LEFT", "Circular (Left)", "Passes left-circular light", 2),
    ("RETARDER", "Retarder + Linear", "A linear retarder followed by a linear polariser", 3),
]


NOISE_QUANTITY_ITEMS = [
    ("S0", "S0 (relative)", "Relative standard error of the luminance S0, |Y_A − Y_B| / (Y_A + Y_B) from the even "
     "and odd samples. It plays the role of Cycles' Noise Threshold but is not Cycles' formula", 0),
    ("DOLP", "DoLP", "Absolute standard error of the degree of linear polarisation, ½|DoLP_A − DoLP_B|", 1),
    ("AOLP", "AoLP (degrees)", "Standard error of the angle of linear polarisation in degrees, where DoLP > 0.05", 2),
    ("DOCP", "DoCP", "Absolute standard error of the degree of circular polarisation, ½|DoCP_A − DoCP_B|", 3),
    ("STOKES", "Stokes", "The largest of the S0 error and the errors of S1/S0, S2/S0, S3/S0", 4),
]
NOISE_QUANTITY_TO_ENGINE = {"S0": "s0", "DOLP": "dolp", "AOLP": "aolp", "DOCP": "docp", "STOKES": "stokes"}


def _adaptive_changed(self, context):
    # The Noise pass exists only with adaptive sampling: refresh the compositor sockets.
    for view_layer in self.id_data.view_layers:
        view_layer.update_render_passes()


def _polariser_changed(self, context):
    from .compositor import sync_group_nodes
    sync_group_nodes(self.id_data)


class PolarRenderSettings(bpy.types.PropertyGroup):
    samples: IntProperty(name="Samples", description="Samples per pixel for final renders",
                         default=16, min=1, soft_max=4096, max=1 << 20)
    preview_samples: IntProperty(name="Preview Samples", description="Samples per pixel for material previews "
                                 "and the viewport", default=4, min=1, max=1 << 16)
    max_bounces: IntProperty(name="Max Bounces", description="Maximum number of bounces, as Cycles counts them "
                             "(0 = direct lighting only: one scattering event per path)",
                             default=15, min=0, max=1023)
    seed: IntProperty(name="Seed", description="Random seed; the same seed gives the same image", default=0,
                      min=0)
    sampler: EnumProperty(name="Pattern", items=SAMPLER_ITEMS, default="SOBOL",
                          description="Random number pattern (Cycles' Sampling Pattern)")
    halves: EnumProperty(name="Even/Odd Samples", items=HALVES_ITEMS, default="AUTO",
                         description="How a pixel's even and odd samples draw the pattern (not with Independent)")
    use_animated_seed: BoolProperty(name="Animated Seed", description="Add the frame number to the seed so "
                                    "that noise changes from frame to frame", default=False)
    spectral: EnumProperty(name="Spectral", items=SPECTRAL_ITEMS, default="SPECTRAL")
    wavelength_nm: FloatProperty(name="Wavelength", description="Wavelength of monochrome renders (nm)",
                                 default=550.0, min=360.0, max=830.0)
    polarisation: EnumProperty(name="Polarisation", items=POLARISATION_ITEMS, default="AUTO")
    skip_clear_layers: BoolProperty(name="Skip Clear Layers", description="Skip layered-material coats whose "
                                    "index equals the medium above and that absorb nothing (exact; reported "
                                    "in the render stats)", default=True)
    threads: IntProperty(name="Threads", description="Worker threads (0 = automatic: one per CPU core, or one "
                                                     "where many materials would make two threads slower)",
                         default=0, min=0,
                         max=256)
    parallel: EnumProperty(name="Parallel", items=PARALLEL_ITEMS, default="AUTO",
                           description="How the workers run: threads or worker processes (the image is the same)")
    batch_rays: IntProperty(name="Batch Size", description="Paths traced at once; lower it to save memory",
                            default=1 << 17, min=1024, max=1 << 24)
    texture_bake_resolution: IntProperty(name="Texture Bake Resolution", description="Texels per side of the "
                                         "images Cycles bakes procedural or unsupported texture graphs of material "
                                         "inputs to, on the object's UV map", default=512, min=8, max=8192,
                                         soft_min=64, soft_max=4096)
    use_adaptive_sampling: BoolProperty(name="Noise Threshold", description="Adaptive sampling: after Min "
                                        "Samples, only tiles whose estimated error is above the threshold get more "
                                        "samples (up to Max Samples or the Time Limit)", default=False,
                                        update=_adaptive_changed)
    adaptive_threshold: FloatProperty(name="Noise Threshold", description="Standard error to reach, of the chosen "
                                      "quantity (relative for S0 and Stokes, absolute for DoLP and DoCP, degrees "
                                      "for AoLP). Tiles far noisier than the image's average stop earlier, at their "
                                      "share of the error (more samples there buy less accuracy than elsewhere). "
                                      "Like Cycles' Noise Threshold in role, not in formula",
                                      default=0.01, min=1e-5, max=90.0, soft_max=1.0, precision=4, step=0.1)
    noise_quantity: EnumProperty(name="Quantity", items=NOISE_QUANTITY_ITEMS, default="S0",
                                 description="What the noise threshold applies to")
    adaptive_min_samples: IntProperty(name="Min Samples", description="Samples every pixel gets before the noise "
                                      "is tested (at least 2: the error comes from even and odd samples)",
                                      default=16, min=2, max=1 << 20)
    time_limit: FloatProperty(name="Time Limit", description="Stop sampling after this many seconds (0 = no "
                              "limit); the render then shows the samples done. Without Noise Threshold the time is "
                              "spent where the noise is (samples ∝ noise/√cost per tile, as the threshold shares them)",
                              default=0.0, min=0.0,
                              soft_max=3600.0)
    use_denoising: BoolProperty(name="Denoise", description="Denoise the final render with OpenImageDenoise as "
                                "the Polar Denoise compositor group does: the analyser images (S0 ± S1, S2, S3)/2 "
                                "each denoised with the albedo and normal guides, recombined into S0…S3 (the "
                                "Combined, derived and false-colour passes follow them; the Noise pass stays the "
                                "render's). Quality: Render ▸ Performance ▸ Compositor ▸ Denoise (final)",
                                default=False)
    denoising_clamp_dop: BoolProperty(name="Clamp DoP", description="After denoising, scale S1…S3 per pixel and "
                                      "colour channel so that the degree of polarisation stays ≤ 1 (the Polar "
                                      "Denoise group's Clamp DoP)", default=True)
    estimate_report: StringProperty(name="Estimate", description="The last cost estimate", default="",
                                    options={"SKIP_SAVE"})
    polariser_type: EnumProperty(name="Filter", items=POLARISER_TYPE_ITEMS, default="LINEAR",
                                 update=_polariser_changed,
                                 description="Virtual filter for the Polariser pass and the compositor group")
    polariser_angle: FloatProperty(name="Angle", description="Transmission axis of the polariser, degrees from "
                                   "image right towards image up", default=0.0, min=-360.0, max=360.0,
                                   update=_polariser_changed)
    polariser_extinction: FloatProperty(name="Extinction", description="t_min/t_max of the polariser "
                                        "(0 = ideal)", default=0.0, min=0.0, max=1.0, update=_polariser_changed)
    retarder_angle: FloatProperty(name="Retarder Angle", description="Fast axis of the retarder (degrees)",
                                  default=45.0, min=-360.0, max=360.0, update=_polariser_changed)
    retardance: FloatProperty(name="Retardance", description="Retardance of the retarder (degrees)",
                              default=90.0, min=-360.0, max=360.0, update=_polariser_changed)
    mosaic_angles: FloatVectorProperty(name="Mosaic Angles", size=4, default=(90.0, 45.0, 135.0, 0.0),
                                       min=-360.0, max=360.0,
                                       description="Micro-polariser angles of the Polarisation Mosaic pass "
                                       "(degrees from image right towards image up): top row left, right, "
                                       "second row left, right")
    mosaic_extinction: FloatProperty(name="Mosaic Extinction", description="t_min/t_max of the micro-"
                                     "polarisers (0 = ideal)", default=0.0, min=0.0, max=1.0)
    world_bake_resolution: IntProperty(name="World Bake Width", description="Width in pixels of the "
                                       "equirectangular map into which Cycles bakes worlds that Polar cannot map "
                                       "directly (Sky Texture, gradients, mixes); the height is half of it. The "
                                       "bake is kept in memory while the world is unchanged",
                                       default=1024, min=16, soft_max=4096, max=16384)
    world_bake_samples: IntProperty(name="World Bake Samples", description="Cycles samples per texel of a baked "
                                    "world: they average each texel's footprint, so that a small bright sun disc "
                                    "keeps its power (16: within ~2 %; 128: within noise)",
                                    default=16, min=1, soft_max=256, max=4096)
    volume_mie: EnumProperty(name="Volume Mie", items=VOLUME_MIE_ITEMS, default="CYCLES",
                             description="How Volume Scatter's Mie phase is rendered")


def pass_property(name: str) -> str:
    """ViewLayer property that toggles the pass ``name`` ("Polarisation Mosaic" → use_pass_polarisation_mosaic)."""
    return "use_pass_" + name.lower().replace(" ", "_")


def _refresh_passes(self, context):
    # id_data of a ViewLayer property group is the Scene: refresh every layer's sockets.
    for view_layer in self.id_data.view_layers:
        view_layer.update_render_passes()


class PolarViewLayerSettings(bpy.types.PropertyGroup):
    use_pass_s0: BoolProperty(name="S0", description="Intensity (colour)", default=True, update=_refresh_passes)
    use_pass_s1: BoolProperty(name="S1", description="Horizontal − vertical linear polarisation (colour, signed)",
                              default=True, update=_refresh_passes)
    use_pass_s2: BoolProperty(name="S2", description="+45° − −45° linear polarisation (colour, signed)",
                              default=True, update=_refresh_passes)
    use_pass_s3: BoolProperty(name="S3", description="Right − left circular polarisation (colour, signed)",
                              default=True, update=_refresh_passes)
    use_pass_dop: BoolProperty(name="DoP", description="Degree of polarisation", default=True,
                               update=_refresh_passes)
    use_pass_dolp: BoolProperty(name="DoLP", description="Degree of linear polarisation", default=True,
                                update=_refresh_passes)
    use_pass_aolp: BoolProperty(name="AoLP", description="Angle of linear polarisation (radians, from image "
                                "right towards image up)", default=True, update=_refresh_passes)
    use_pass_docp: BoolProperty(name="DoCP", description="Degree of circular polarisation (signed)", default=True,
                                update=_refresh_passes)
    use_pass_polariser: BoolProperty(name="Polariser", description="The image through the scene's virtual "
                                     "polariser (Render properties ▸ Virtual Polariser)", default=True,
                                     update=_refresh_passes)
    use_pass_visdop: BoolProperty(name="DoP (false colour)", default=False, update=_refresh_passes,
                                  description="Degree of polarisation, viridis 0 … 1")
    use_pass_viss1: BoolProperty(name="S1/S0 (false colour)", default=False, update=_refresh_passes,
                                 description="Blue −1 … white 0 … red +1")
    use_pass_viss2: BoolProperty(name="S2/S0 (false colour)", default=False, update=_refresh_passes,
                                 description="Blue −1 … white 0 … red +1")
    use_pass_viss3: BoolProperty(name="S3/S0 (false colour)", default=False, update=_refresh_passes,
                                 description="Blue −1 … white 0 … red +1")
    use_pass_visaolp: BoolProperty(name="AoLP (false colour)", default=False, update=_refresh_passes,
                                   description="Angle of linear polarisation as hue, DoLP as saturation")
    use_pass_noise: BoolProperty(name="Noise", default=True, update=_refresh_passes,
                                 description="Per-pixel standard error of the noise quantity (with adaptive "
                                 "sampling only)")
    use_pass_polarisation_mosaic: BoolProperty(name="Polarisation Mosaic", default=False, update=_refresh_passes,
                                               description="What a polarisation camera records: a 2×2 mosaic of "
                                               "micro-polarisers (Render properties ▸ Virtual Polariser)")
    use_pass_denoising_albedo: BoolProperty(name="Denoising Albedo", default=False, update=_refresh_passes,
                                            description="Albedo at the first non-mirror hit, a guide for the "
                                            "compositor's Denoise node (as Cycles' Denoising Data)")
    use_pass_denoising_normal: BoolProperty(name="Denoising Normal", default=False, update=_refresh_passes,
                                            description="World-space shading normal at the first non-mirror "
                                            "hit, a guide for the compositor's Denoise node")

    def enabled_passes(self):
        return [name for name in PASS_NAMES if getattr(self, pass_property(name))]


SOURCE_POLARISATION_ITEMS = [
    ("NONE", "Unpolarised", "The source emits unpolarised light (as every Cycles light)", 0),
    ("LINEAR", "Linear", "Linearly polarised at an angle measured in the source's own frame (the light's local X "
     "axis; on a mesh its UV map's U direction, else the object's local X), e.g. an LCD screen", 1),
    ("CIRCULAR", "Circular", "Circularly polarised (e.g. a 3D cinema projector, an OLED screen's circular "
     "polariser seen from behind)", 2),
]
HANDEDNESS_ITEMS = [
    ("RIGHT", "Right", "Right-handed: S3 > 0 (optics convention: clockwise to a viewer looking into the beam)", 0),
    ("LEFT", "Left", "Left-handed: S3 < 0", 1),
]
SOURCE_POLARISATION_TO_ENGINE = {"NONE": "none", "LINEAR": "linear", "CIRCULAR": "circular"}


class PolarSourceSettings(bpy.types.PropertyGroup):
    """The polarisation of a light, or of a material's emission (Emission shader, Principled emission)."""
    polarisation: EnumProperty(name="Polarisation", items=SOURCE_POLARISATION_ITEMS, default="NONE",
                               description="The polarisation of the emitted light")
    degree: FloatProperty(name="Degree", min=0.0, max=1.0, default=1.0, subtype="FACTOR",
                          description="Degree of polarisation: 1 fully polarised, 0 unpolarised")
    angle: FloatProperty(name="Angle", default=0.0, subtype="ANGLE", soft_min=-math.pi, soft_max=math.pi,
                         description="Angle of the electric field from the source's X axis towards its Y axis "
                         "(seen along the light's travel)")
    handedness: EnumProperty(name="Handedness", items=HANDEDNESS_ITEMS, default="RIGHT")

    def engine_dict(self):
        """The scene format's "polarisation" object (engine.polarisation.sources), None when unpolarised."""
        kind = SOURCE_POLARISATION_TO_ENGINE[self.polarisation]
        if kind == "none" or self.degree <= 0.0:
            return None
        if kind == "linear":
            return {"type": "linear", "degree": float(self.degree), "angle": math.degrees(float(self.angle))}
        return {"type": "circular", "degree": float(self.degree), "handedness": self.handedness.lower()}


SKY_POLARISATION_ITEMS = [
    ("BERRY", "Berry (neutral points)", "A Sky Texture's light is polarised as real clear skies are: maximum "
     "degree 0.3–0.8 (lower with haze), angle across the plane of the sun, with the Arago, Babinet and Brewster "
     "neutral points (Berry, Dennis & Lee 2004)", 0),
    ("RAYLEIGH", "Rayleigh", "Single Rayleigh scattering by air (depolarisation factor 0.031): degree up to 0.94 "
     "at 90° from the sun, neutral only at the sun and the antisun", 1),
    ("OFF", "Off", "The sky is unpolarised (as in Cycles)", 2),
]
SKY_POLARISATION_TO_ENGINE = {"BERRY": "berry", "RAYLEIGH": "rayleigh", "OFF": None}


class PolarWorldSettings(bpy.types.PropertyGroup):
    """How Polar polarises a world's Sky Texture (its radiance stays Cycles' own)."""
    sky_polarisation: EnumProperty(name="Sky Polarisation", items=SKY_POLARISATION_ITEMS, default="BERRY",
                                   description="The polarisation of daylight from a Sky Texture in this world")

    def engine_model(self):
        """The model of engine.spectral.daylight.ClearSky ("berry", "rayleigh"), None when off."""
        return SKY_POLARISATION_TO_ENGINE[self.sky_polarisation]


classes = (PolarRenderSettings, PolarViewLayerSettings, PolarSourceSettings, PolarWorldSettings)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.polar = PointerProperty(type=PolarRenderSettings)
    bpy.types.ViewLayer.polar = PointerProperty(type=PolarViewLayerSettings)
    bpy.types.Light.polar = PointerProperty(type=PolarSourceSettings)
    bpy.types.Material.polar = PointerProperty(type=PolarSourceSettings)
    bpy.types.World.polar = PointerProperty(type=PolarWorldSettings)


def unregister():
    del bpy.types.World.polar
    del bpy.types.Material.polar
    del bpy.types.Light.polar
    del bpy.types.ViewLayer.polar
    del bpy.types.Scene.polar
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
