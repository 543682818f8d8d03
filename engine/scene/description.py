"""The in-memory scene: what the JSON loader, the Python API and the Blender
exporter all produce, and what the renderer compiles.

Units: lengths in scene units, angles in degrees at this level, wavelengths
in nm.  Radiance and intensity are relative ("radiance 1" white light develops
to linear sRGB (1, 1, 1)).  World space is right-handed; any axis may be up.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..errors import SceneError


@dataclass
class Camera:
    """Perspective (pinhole or thin lens), orthographic or equirectangular camera looking from origin
    to target.

    Basis: f = unit(target − origin), r = unit(f × up), u_cam = r × f.
    ``fov_deg`` is the full angle along ``fov_axis`` ("x": horizontal,
    "y": vertical).  ``ortho_width`` is the full width of an orthographic view.
    ``shift`` is the lens shift in units of the larger image side (Blender).
    Rays start at depth ``clip_start`` and end at depth ``clip_end`` along the
    viewing axis (planes ⟂ the axis, as Blender's clipping).

    Thin lens (Cycles' model): ``aperture_radius`` > 0 (scene units) samples the ray origin on a
    lens disk (or a regular polygon of ``aperture_blades`` ≥ 3 sides inscribed in it, an edge
    midpoint at ``aperture_rotation_deg`` from the camera's right axis; x divided by
    ``aperture_ratio``) ⟂ the view axis, aimed at the pinhole ray's point on the focus plane at
    depth ``focus_distance`` (a sphere of that radius for panoramas).  0 = pinhole.
    ``projection`` "equirectangular": longitude (positive to the camera's right, 0 = forward)
    over ``longitude_deg`` left → right and latitude over ``latitude_deg`` bottom → top.
    ``film_transparent``: camera rays that reach the background write alpha 0 and no colour.
    """

    origin: np.ndarray
    target: np.ndarray
    up: np.ndarray
    width: int
    height: int
    fov_deg: float = 40.0
    fov_axis: str = "x"
    projection: str = "perspective"
    ortho_width: float = 2.0
    shift: tuple = (0.0, 0.0)
    clip_start: float = 0.0
    clip_end: float = float("inf")
    aperture_radius: float = 0.0
    focus_distance: float = 1.0
    aperture_blades: int = 0
    aperture_rotation_deg: float = 0.0
    aperture_ratio: float = 1.0
    longitude_deg: tuple = (-180.0, 180.0)
    latitude_deg: tuple = (-90.0, 90.0)
    film_transparent: bool = False


#: ``Mesh.emission_sampling``: how a textured emission's points are sampled (see Mesh)
EMISSION_SAMPLING = ("luminance", "area")


@dataclass
class Interior:
    """An absorbing interior (Beer–Lambert), attached to a material as ``bsdf.interior``.

    A mesh face whose material carries an interior bounds a closed volume of absorption
    coefficient ``absorption`` σ_a(λ) ≥ 0 per scene unit of length (a Spectrum: ConstantSpectrum,
    RGBUnboundedSpectrum — upsampled by the engine's basis; in RGB mode its linear sRGB triple is
    used per channel, as Cycles — or TabulatedSpectrum).  A path segment of length d inside it is
    attenuated by exp(−σ_a(λ)·d); the Stokes vector's polarisation is unchanged (an isotropic
    absorber scales the Mueller matrix by a scalar per wavelength).  Blender's Volume Absorption
    (Color c, Density ρ) is ``Interior.from_color_density(c, ρ)``: σ_a = ρ·(1 − c).  Media entered
    through faces of several such materials add up (Cycles' volume stack): see docs/physics.md
    "Absorbing interiors".  Set it on an instance only (``bsdf.interior = Interior(...)``), so the
    scene fingerprints of materials without one are unchanged; an interior that absorbs nothing
    (σ_a = 0 at every wavelength) is the same as none.

    A participating medium also scatters: ``scattering`` σ_s(λ) ≥ 0 per scene unit (a Spectrum, as
    ``absorption``; None: 0) with the phase function ``phase`` (engine.media.phase.PhaseFunction; None:
    isotropic), and both coefficients are scaled by a density ``grid`` (engine.media.grid.DensityGrid; None:
    1 everywhere, a homogeneous medium).  ``majorant`` (≥ the grid's largest value, or ≥ 1 without a grid;
    None: that value) is the density bound of free-flight sampling (engine.render.participating); a looser
    one costs null collisions, never bias.  Every medium that scatters or has a grid is *tracked*
    (delta tracking); a homogeneous one's absorption stays exact Beer–Lambert.  The world medium
    (``Scene.medium``) is an Interior too.  docs/physics.md "Participating media".

    A medium may emit unpolarised (thermal) light: ``emission`` ε(λ) ≥ 0, radiance per unit length (a number
    or [r, g, b]: an RGBIlluminantSpectrum, as a lamp's colour; or a Spectrum), or per point ``emission_grid``
    (engine.media.colour_grid.ColourGrid of linear sRGB ε(x), instead of ``emission``).  ε is Cycles' volume
    emission (its Emission closure's value: not scaled by the density), dL/ds = ε − σ_t·L; an emitting medium
    is tracked with its whole σ_t (docs/physics.md "Volume emission").

    A grid medium may have a colour per point, ``colour_grid`` (engine.media.colour_grid.ColourGrid of linear
    sRGB C(x), upsampled as a reflectance, C(λ, x) = Σ_c C_c(x)·B_c(λ)): σ_s(λ, x) = ρ(x)·σ_s(λ)·C(λ, x) and
    σ_a(λ, x) = ρ(x)·σ_a(λ)·max(1 − C(λ, x), 0) — Cycles' Principled Volume (Color × Color Attribute = C)
    with σ_s = 1 and σ_a = 1 − √(Absorption Color); it needs ``grid`` (docs/physics.md "Colour grids").
    """

    absorption: object
    scattering: object = None
    phase: object = None
    grid: object = None
    majorant: float | None = None
    emission: object = None
    emission_grid: object = None
    colour_grid: object = None

    def __post_init__(self):
        from ..errors import SceneError
        from ..media.colour_grid import ColourGrid
        from ..spectral import RGBIlluminantSpectrum
        if self.colour_grid is not None:
            if not isinstance(self.colour_grid, ColourGrid):
                raise SceneError("interior.colour_grid", "must be an engine.media.colour_grid.ColourGrid (linear sRGB "
                                                         "per node, ≥ 0)")
            if self.grid is None:
                raise SceneError("interior.colour_grid", "needs a density grid (interior.grid) over the medium")
        self.absorption = _medium_spectrum(self.absorption, "interior.absorption")
        if self.scattering is not None:
            self.scattering = _medium_spectrum(self.scattering, "interior.scattering")
        if self.emission is not None:
            if self.emission_grid is not None:
                raise SceneError("interior.emission", "give either emission or an emission grid, not both")
            e = self.emission
            if isinstance(e, (int, float)) and not isinstance(e, bool):
                e = [e] * 3
            if isinstance(e, (list, tuple, np.ndarray)) and np.shape(e) == (3,):
                e = RGBIlluminantSpectrum(e, field="interior.emission")
            self.emission = _medium_spectrum(e, "interior.emission")
        bound = 1.0 if self.grid is None else self.grid.max
        if self.majorant is not None:
            m = float(self.majorant)
            if not np.isfinite(m) or m < bound:
                raise SceneError("interior.majorant", f"must be a finite number ≥ {bound:g} (the largest density), "
                                                      f"got {self.majorant!r}")
            self.majorant = m

    @classmethod
    def from_color_density(cls, color, density: float) -> Interior:
        """Blender's Volume Absorption: σ_a = density·(1 − color) per channel (Cycles'
        svm_node_closure_volume); color in [0, 1]³, density ≥ 0 (world units⁻¹)."""
        from ..errors import SceneError
        c = np.asarray(color, np.float64)
        if c.shape != (3,) or not np.all(np.isfinite(c)) or np.any(c < 0) or np.any(c > 1):
            raise SceneError("interior.color", f"must be an [r, g, b] list with components in [0, 1], got {color!r}")
        rho = float(density)
        if not np.isfinite(rho) or rho < 0:
            raise SceneError("interior.density", f"must be a finite number ≥ 0, got {density!r}")
        return cls(list(rho * (1.0 - c)))

    @property
    def absorbs(self) -> bool:
        """σ_a > 0 at some wavelength (an interior that absorbs nothing is treated as none)."""
        return _positive(self.absorption) and (self.grid is None or self.grid.max > 0)

    @property
    def scatters(self) -> bool:
        """σ_s > 0 at some wavelength and somewhere (a participating medium)."""
        return (self.scattering is not None and _positive(self.scattering)
                and (self.grid is None or self.grid.max > 0)
                and (self.colour_grid is None or bool(self.colour_grid.max.max() > 0)))

    @property
    def emits(self) -> bool:
        """ε > 0 at some wavelength and somewhere (an emitting medium)."""
        if self.emission_grid is not None:
            return bool(self.emission_grid.max.max() > 0)
        return self.emission is not None and _positive(self.emission)

    @property
    def tracked(self) -> bool:
        """Rendered by delta tracking (it scatters, emits, or its density varies): engine.render.participating."""
        return self.scatters or self.emits or (self.grid is not None and self.absorbs)

    @property
    def renders(self) -> bool:
        """It absorbs, scatters or emits (an interior that does none of them is the same as none)."""
        return self.absorbs or self.scatters or self.emits

    @property
    def density_bound(self) -> float:
        """The majorant density of free-flight sampling (``majorant``, else the largest density)."""
        if self.majorant is not None:
            return self.majorant
        return 1.0 if self.grid is None else self.grid.max


def _positive(spectrum) -> bool:
    """The spectrum is > 0 at some wavelength (its table, else its colour)."""
    values = getattr(spectrum, "values", None)
    if values is not None:
        return bool(np.any(np.asarray(values) > 0))
    return bool(np.any(np.asarray(spectrum.linear_srgb()) > 0))


def _medium_spectrum(value, field: str):
    """A coefficient per unit length as a Spectrum (a number, [r, g, b] or a Spectrum), ≥ 0 and finite."""
    from ..errors import SceneError
    from ..spectral import RGBUnboundedSpectrum, Spectrum, as_spectrum
    if isinstance(value, (list, tuple, np.ndarray)) and np.shape(value) == (3,):
        value = RGBUnboundedSpectrum(value, field=field)
    elif not isinstance(value, Spectrum):
        try:
            value = as_spectrum(value, field)
        except ValueError as e:
            raise SceneError(field, str(e)) from None
    rgb = np.asarray(value.linear_srgb(), np.float64)
    if not np.all(np.isfinite(rgb)) or np.any(rgb < 0):
        raise SceneError(field, f"must be ≥ 0 and finite (per unit length), got {rgb.tolist()}")
    values = getattr(value, "values", None)      # a table: every value, not only its colour
    if values is not None and (not np.all(np.isfinite(values)) or np.any(np.asarray(values) < 0)):
        raise SceneError(field, "table values must be ≥ 0 and finite (per unit length)")
    return value


def interior_of(material) -> Interior | None:
    """The material's absorbing interior (``material.interior``), or None when it has none or it
    absorbs nothing."""
    interior = getattr(material, "interior", None)
    return interior if isinstance(interior, Interior) and interior.renders else None


@dataclass
class Mesh:
    """A triangle mesh in world space.

    ``faces`` are counter-clockwise seen from the front (geometric normal
    (v1 − v0) × (v2 − v0)).  ``normals`` are per-vertex shading normals or None
    (flat shading).  ``material_ids`` index ``materials`` (names in
    Scene.materials) per face.  ``emission`` (a spectral radiance, or None)
    makes the mesh a one-sided area light emitting along its front side; a radiance that varies
    over the surface is a ``TexturedSpectrum`` of kind "illuminant" (strength × a texture's RGB at
    each point: ``engine.textures.textured_emission``, read through the mesh's ``uv`` or ``colors``),
    sampled per ``emission_sampling``: "luminance" (the default: triangles ∝ area × mean emitted
    luminance) or "area" (as a constant emitter: by area, a rectangle by solid angle); constant
    emitters ignore it.
    ``uv`` and ``colors`` are per-vertex attributes read by textured materials (engine.textures).

    Ray visibility (Cycles' Object ▸ Visibility): ``visible_camera`` False hides the mesh from
    camera rays (they pass through), ``visible_shadow`` False lets shadow rays through,
    ``visible_indirect`` False hides it from rays after a scattering event; ``holdout`` makes what
    camera rays see of it transparent (alpha 0, no colour).  ``alpha`` < 1: a pass-through
    surface (Principled Alpha): rays cross it unchanged with probability 1 − alpha, shadow rays
    are attenuated by 1 − alpha; the Stokes vector is unchanged; a TexturedNumber alpha varies over the
    surface (read at each crossing).

    Emitter options (the defaults are the scene format's and the peer format's meaning):
    ``two_sided`` — both faces emit the same radiance (Cycles' Emission shader);
    ``occluder`` — False makes the mesh a lamp in Cycles' sense: rays and shadow rays pass
    through it, it only adds its emission where a ray crosses it (needs ``emission``);
    ``visible_camera`` — False hides a non-occluding emitter from camera rays (point, spot and
    directional lights have the same field for their disks, spheres and discs);
    ``spread_deg`` — Cycles' area-light spread (full angle, 0 < s ≤ 180): radiance
    L·f(θ), f = N·max(0, tan(s/2) − tan θ) with ∫ f cosθ dω = π (the emitted power is kept).
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    materials: list
    material_ids: np.ndarray
    normals: np.ndarray | None = None
    emission: object | None = None
    #: per-vertex texture coordinates (V, 2) (u right, v up, as Blender's UV map), or None
    uv: np.ndarray | None = None
    #: per-vertex colour attributes by name: (V, 3) or (V, 4) linear values in [0, 1]
    colors: dict = field(default_factory=dict)
    #: per-vertex tangents (V, 4): xyz along +u, w = ±1 the handedness (bitangent = w·(n × t)), or
    #: None (tangents are then derived from the UVs, per triangle)
    tangents: np.ndarray | None = None
    visible_camera: bool = True
    visible_shadow: bool = True
    visible_indirect: bool = True
    holdout: bool = False
    alpha: float = 1.0
    two_sided: bool = False
    occluder: bool = True
    spread_deg: float = 180.0
    #: how a textured emission is sampled (see above); a class attribute, not a field: set it on the
    #: instance (``mesh.emission_sampling = "area"``), so the fingerprints of existing scenes
    #: (engine.render.resume) stay what they were
    emission_sampling = "luminance"
    #: the emission lies under its material's sheen and coat layers (Cycles' Principled BSDF: its own emission is
    #: attenuated by them, engine.materials.mix.emission_weight); scene files: ``"under_layers": true`` in the
    #: object's "emission".  A class attribute for the same reason as ``emission_sampling``
    emission_under_layers = False
    #: the emission's polarisation and reference axis (as PointLight.polarisation; None: unpolarised; the axis
    #: None: the surface's UV tangent, else world +X): scene files' ``"polarisation"`` in the object's "emission"
    emission_polarisation = None
    emission_axis = None
    #: Identity for the data passes and Cryptomatte (engine.render.data_passes), class attributes set on the
    #: instance only (so the fingerprints of existing scenes are unchanged; ``dataclasses.replace`` drops them):
    #: ``object_name`` the object's name (None: ``name``), ``asset_name`` its top-level parent's (None: the
    #: object name), ``pass_index`` its Object Index (int ≥ 0), ``material_names`` the names per entry of
    #: ``materials`` (None: the material keys), ``material_pass_indices`` their Material Index (None: 0 each),
    #: ``pass_uv`` (V, 2) the UV map the UV pass shows (None: ``uv``; neither: no UV map, the pass is 0)
    object_name = None
    asset_name = None
    pass_index = 0
    material_names = None
    material_pass_indices = None
    pass_uv = None


@dataclass
class PointLight:
    """Isotropic light of radiant intensity I.  ``radius`` > 0 makes it a Cycles sphere light
    of radiance I/(πr²) (same power, soft shadows): with ``soft_falloff`` a disk of radius r always
    facing the receiver (Cycles' default: irradiance I/(d² + r²) on axis), without it a sphere
    (exactly I/d² outside).  Such lights are sampled by next-event estimation only."""

    position: np.ndarray
    intensity: object             # spectrum: radiant intensity (radiance × area / sr)
    radius: float = 0.0
    soft_falloff: bool = True
    visible_camera: bool = True   # camera rays see the disk/sphere (radius > 0)
    #: the light's polarisation (engine.polarisation.sources.SourcePolarisation; None: unpolarised) and its
    #: reference axis (3,) in world space (None: the default of engine.polarisation.sources); class
    #: attributes set on the instance only when polarised, so the fingerprints of existing scenes are unchanged
    polarisation = None
    polarisation_axis = None


@dataclass
class SpotLight:
    position: np.ndarray
    direction: np.ndarray         # unit axis of the cone (direction light travels)
    intensity: object
    cone_angle_deg: float = 45.0  # full opening angle
    blend: float = 0.0            # size of the smooth edge (see blend_profile)
    #: "angle": smoothstep over the angles half·(1 − blend) … half; "cycles": smoothstep in cos θ over
    #: cos(half) … cos(half) + blend·(1 − cos(half)) (Cycles' spot_light_attenuation).
    blend_profile: str = "angle"
    radius: float = 0.0           # as PointLight.radius
    soft_falloff: bool = True
    visible_camera: bool = True
    #: the light's polarisation (engine.polarisation.sources.SourcePolarisation; None: unpolarised) and its
    #: reference axis (3,) in world space (None: the default of engine.polarisation.sources); class
    #: attributes set on the instance only when polarised, so the fingerprints of existing scenes are unchanged
    polarisation = None
    polarisation_axis = None


@dataclass
class DirectionalLight:
    direction: np.ndarray         # unit direction in which the light travels
    irradiance: object            # spectrum: irradiance on a surface ⟂ direction
    #: full angular diameter of the source; > 0: uniform radiance E/(π sin²(angle/2)) in that cone
    #: (Cycles' sun angle: soft shadows, same irradiance)
    angle_deg: float = 0.0
    visible_camera: bool = True   # camera rays see the sun's disc (angle > 0)
    #: the light's polarisation (engine.polarisation.sources.SourcePolarisation; None: unpolarised) and its
    #: reference axis (3,) in world space (None: the default of engine.polarisation.sources); class
    #: attributes set on the instance only when polarised, so the fingerprints of existing scenes are unchanged
    polarisation = None
    polarisation_axis = None


#: texel grids of an equirectangular map (column i always at u = (i + ½)/W):
#: "mitsuba": row j at v = j/(H − 1) (rows 0 and H − 1 on the poles; the peer format);
#: "cycles": row j at v = (j + ½)/H (texel centres, as Blender and image libraries), clamped to
#: the first/last row within half a texel of the poles.
ENVMAP_GRIDS = ("mitsuba", "cycles")
ENVMAP_INTERPOLATION_SPACES = ("linear", "srgb")


@dataclass
class EnvironmentLight:
    """Light from every direction: constant ``radiance``, or with ``image`` (float (H, W, 3) linear
    sRGB, row 0 = zenith) an equirectangular map × ``strength``, turned by ``rotation_deg`` about
    +Z (or by Euler angles [x, y, z] in degrees, order XYZ as Blender's), its rows on the texel
    ``grid`` "cycles" or "mitsuba" (engine.render.lights.ENVMAP_GRIDS), interpolated in the
    ``interpolation_space`` "linear" or "srgb" (on sRGB-encoded texels, as Cycles does for sRGB
    images; see engine.render.lights.EnvironmentMapEmitter)."""

    radiance: object              # constant spectral radiance from every direction
    image: object = None
    strength: float = 1.0
    rotation_deg: float = 0.0
    grid: str = "cycles"
    interpolation_space: str = "linear"
    #: a polarised environment (class attributes, set on the instance only then, so the fingerprints of existing
    #: scenes are unchanged): ``polarisation`` an engine.polarisation.sources.DirectionalPolarisation, and
    #: ``stokes`` (H, W, 3) the map's normalised S1, S2, S3 (engine.render.lights.EnvironmentMapEmitter.set_stokes)
    #: or ``sky`` the clear-sky model whose polarisation it has (engine.spectral.daylight.ClearSky)
    polarisation = None
    stokes = None
    sky = None


#: The spectral modes of RenderSettings.spectral.
SPECTRAL_MODES = ("spectral", "rgb", "mono")


@dataclass(frozen=True)
class RenderSettings:
    """How to render.  ``max_depth`` counts path segments (as Mitsuba 3):
    1 = only directly visible light, 2 = direct lighting, ….
    ``polarisation``: "full" (4×4 Mueller), "linear" (3×3: S3 = 0), "off"
    (scalar, S1..S3 = 0) or "auto" (the cheapest of these that is exact for
    the scene, see engine.render.effects).
    ``spectral``: "spectral" (4 wavelengths per path over 360–830 nm), "rgb" (Cycles' colour arithmetic:
    every path carries linear-sRGB R, G, B as three channels; RGB colours, lights and textures are used
    as they are, colours multiply channel by channel; models that need a wavelength — measured metals,
    thin layers, HTSG — are evaluated at engine.spectral.RGB_WAVELENGTHS_NM) or "mono" (one wavelength
    ``wavelength_nm``; RGB colours by their luminance).
    Frozen: derive changed settings with ``dataclasses.replace(settings, spp=…)`` (a Scene's
    ``settings`` attribute may be replaced the same way).
    """

    spp: int = 16
    max_depth: int = 16
    rr_depth: int = 5
    seed: int = 0
    spectral: str = "spectral"
    wavelength_nm: float = 550.0
    polarisation: str = "auto"
    batch_rays: int = 1 << 17
    threads: int = 0              # worker threads; 0 = automatic (one per CPU core; one where materials convoy)
    #: How the local workers run (engine.render.processes): "threads" (of this process), "processes" (a pool of
    #: worker processes kept between renders: every core, also where Python-shaded materials make threads convoy on
    #: the GIL) or "auto" (processes for scenes with Python-shaded materials once the pool runs or its start is
    #: amortised: engine.render.processes.choose_parallel).  Same image.
    parallel: str = "auto"
    #: Where no material depends on λ: "auto" traces in RGB with each light's exactly integrated
    #: colour (no chromatic noise, same expectation); "exact" keeps the 4 sampled wavelengths but
    #: one Mueller product per path (bit-for-bit the per-wavelength estimator); "off" never reduces.
    reduce_spectral: str = "auto"
    #: "auto": skip layered coats that are index-matched to the medium above and clear (exact;
    #: engine.materials.simplify); "off": render every layer as given.
    simplify: str = "auto"
    #: Also record the denoising guides (albedo and normal at the first non-delta vertex, as
    #: Cycles' Denoising Albedo / Normal passes); False: the renders are unchanged.
    denoise_data: bool = False
    #: Random numbers of the paths (Cycles' sampling pattern): "sobol", the one default of the scene
    #: format, the command line, the Python API and Blender (the camera's numbers as "stratified" draws them, the
    #: first vertex's as "cycles" does, engine.render.sampler.vertex_pattern, every deeper vertex's — light choice
    #: and point, lobe, direction, roulette — from per-pixel shuffled, Owen-scrambled Sobol' (0, 2)-sequence pairs,
    #: engine.render.sampler.sobol_pairs: same expectation, less noise; with independent ``halves`` the standard
    #: error comes from the even/odd halves), "stratified" (the camera's numbers and the first vertex's light and BSDF
    #: numbers one per-pixel XOR-scrambled Sobol' point set, engine.render.sampler.stratified_pair, the
    #: deeper ones hashed; the default before "sobol"), "padded" (every number, the camera's and the first
    #: vertex's too, from its own shuffled Sobol' pair, engine.render.sampler.padded_pairs), "cycles" (Cycles'
    #: pattern: each role's numbers one point of a shuffled Owen-scrambled Sobol' set, sampler.cycles_pairs) or
    #: "independent" (every number a hash of (seed, pixel, sample, dimension)).
    sampler: str = "sobol"
    #: How a pixel's samples draw the pattern's numbers (the stratifying samplers; "independent" has nothing to
    #: split): "one_sequence" (the sample index used whole: one scrambled sequence per pixel and pair, so a pixel's
    #: first 2^m samples are one (0, m, 2)-net; the error estimate splits them into two classes, engine.render.halves,
    #: whose correlated difference is calibrated), "independent" (the even and odd samples two independently
    #: scrambled sequences, index sample // 2: their means are independent estimates; the images of the versions
    #: before one sequence) or "auto" (= "one_sequence", also for adaptive sampling, a time budget and
    #: ``estimate``; resolve_halves below).  Same expectation either way.
    halves: str = "auto"
    #: How next-event estimation chooses among many lights (Cycles' Light Tree, scene.cycles.use_light_tree):
    #: "on" — the light tree over lamps and emissive triangles (engine.render.lights.tree: Conty & Kulla 2018 as
    #: Cycles builds it: importance by energy, distance, bounds and orientation per shading point); "off" — the
    #: scene's ``light_selection`` (uniform, by power or as Cycles) over whole lights; "auto" (default)
    #: — the tree where the scene has more than 64 emitters (lamps and each triangle of a mesh light sampled by
    #: area), where it helps; otherwise "off".  Same expectation either way.
    light_tree: str = "auto"
    #: Cycles' Light Paths ▸ Max Bounces per kind (engine.render.light_paths): a path whose diffuse, glossy,
    #: transmission or transparent bounces exceed the limit ends at its next surface (that surface's emission
    #: still counts), as Cycles' path_state_next; 0 = only the light found by the first bounce of that kind.
    #: 1024 = no limit (the default: the total stays ``max_depth``).  A bounce's kind is the lobe it sampled.
    max_diffuse_bounces: int = 1024
    #: the same for glossy and mirror reflections (Cycles counts a mirror as glossy)
    max_glossy_bounces: int = 1024
    #: the same for transmissions through a surface (refraction, diffuse transmission)
    max_transmission_bounces: int = 1024
    #: the same for null-lobe pass-throughs (filter sheets; alpha pass-through keeps its own 32 per segment)
    max_transparent_bounces: int = 1024
    #: the same for scattering events in participating media (Cycles' Light Paths ▸ Volume; medium vertices,
    #: engine.render.participating).  It changes only scenes whose media scatter, so it is left out of
    #: ``light_paths_active``: the participating tracer keeps the bookkeeping where it is below ``max_depth`` − 2
    max_volume_bounces: int = 1024
    #: Cycles' Clamping ▸ Direct / Indirect Light: each light contribution of a sample (emission reached, a
    #: light sample) whose linear-sRGB S0 has a component above the limit (max |R|, |G|, |B|, as Cycles renders)
    #: is scaled down to it, all four Stokes components by the same factor (the polarisation is unchanged);
    #: "direct" = light reached by the camera ray or by the first vertex's light and BSDF samples.  0 = off.
    clamp_direct: float = 0.0
    #: the same limit for every other light contribution (Cycles' Clamping ▸ Indirect Light); 0 = off
    clamp_indirect: float = 0.0
    #: Cycles' Caustics ▸ Reflective / Refractive: False drops the glossy (and mirror) reflection / transmission
    #: lobes at a vertex reached by a diffuse bounce (Cycles' PATH_RAY_DIFFUSE closures test).
    caustics_reflective: bool = True
    #: False drops the glossy and smooth transmission lobes there (Cycles' Caustics ▸ Refractive)
    caustics_refractive: bool = True

    @property
    def light_paths_active(self) -> bool:
        """True when any of Cycles' light-path limits above can change the image: a clamp or a caustics switch
        set, or a kind's bounce limit below ``max_depth`` − 2 (a path has at most ``max_depth`` − 1 scattering
        vertices, and a limit reached at the last one ends the path where ``max_depth`` ends it anyway).  The
        wavefront tracer then keeps the per-path bookkeeping; otherwise it runs exactly the arithmetic it ran
        before they existed, and the compiled per-path loop may take the render."""
        return any(getattr(self, f.name) < self.max_depth - 2 if f.kind == "int" else getattr(self, f.name) != f.default
                   for f in LIGHT_PATH_FIELDS if f.name != "max_volume_bounces")

    @property
    def stratified(self) -> bool:
        """True with the low-discrepancy samplers ("stratified", "sobol", "padded", "cycles"): a pixel's samples
        are not independent."""
        return self.sampler != "independent"

    @property
    def split_halves(self) -> bool:
        """True where the film keeps the half sums of two sample classes (engine.render.halves): a low-discrepancy
        sampler with ``halves`` resolved (``resolve_halves``; "auto" unresolved counts as not split)."""
        return self.stratified and self.halves != "auto"


#: RenderSettings.sampler's values
SAMPLERS = ("independent", "stratified", "sobol", "padded", "cycles")
def resolve_halves(settings):
    """``settings`` (RenderSettings) with ``halves`` resolved: "auto" → "one_sequence", adaptive sampling, a time
    budget and ``estimate`` included (their error estimate splits one sequence into two classes,
    engine.render.halves); the "independent" sampler → "independent" (it has no sequence to split: its headers
    and numbers stay as they were).  Idempotent; SceneError naming ``render.halves`` for a value not in HALVES_MODES
    (settings built in Python skip the scene loader's check)."""
    mode = settings.halves
    if mode not in HALVES_MODES:
        raise SceneError("render.halves", f"must be one of {', '.join(map(repr, HALVES_MODES))}, got {mode!r}")
    if not settings.stratified:
        mode = "independent"
    elif mode == "auto":
        mode = "one_sequence"
    return settings if mode == settings.halves else dataclasses.replace(settings, halves=mode)


#: RenderSettings.halves' values
HALVES_MODES = ("auto", "independent", "one_sequence")
#: RenderSettings.parallel's values
PARALLEL_MODES = ("auto", "threads", "processes")
#: RenderSettings.light_tree's values
LIGHT_TREE_MODES = ("auto", "on", "off")


@dataclass(frozen=True)
class LightPathField:
    """One of Cycles' light-path settings of RenderSettings: its field ``name``, ``kind`` ("int", "float",
    "bool"), range [lo, hi] and default; the scene format (``render.<name>``), the command line
    (``--<name with dashes>``), the EXR header (``polar.<name>``, written only when not the default) and the
    Blender exporter all read this one declaration."""
    name: str
    kind: str
    default: object
    lo: float = 0
    hi: float = 0
    help: str = ""


#: Cycles' Light Paths settings (RenderSettings fields; engine.render.light_paths applies them)
LIGHT_PATH_FIELDS = (
    LightPathField("max_diffuse_bounces", "int", 1024, 0, 1024, "most diffuse bounces (Cycles' Light Paths)"),
    LightPathField("max_glossy_bounces", "int", 1024, 0, 1024, "most glossy and mirror reflections"),
    LightPathField("max_transmission_bounces", "int", 1024, 0, 1024, "most transmissions (refraction)"),
    LightPathField("max_transparent_bounces", "int", 1024, 0, 1024, "most transparent (null-lobe) crossings"),
    LightPathField("max_volume_bounces", "int", 1024, 0, 1024, "most scattering events in participating media"),
    LightPathField("clamp_direct", "float", 0.0, 0.0, 1e30, "clamp of direct light per sample (max sRGB; 0 off)"),
    LightPathField("clamp_indirect", "float", 0.0, 0.0, 1e30, "clamp of indirect light per sample (0 off)"),
    LightPathField("caustics_reflective", "bool", True, help="glossy reflection after a diffuse bounce"),
    LightPathField("caustics_refractive", "bool", True, help="glossy transmission after a diffuse bounce"),
)


@dataclass
class Scene:
    camera: Camera
    meshes: list = field(default_factory=list)
    materials: dict = field(default_factory=dict)   # name → BSDF
    lights: list = field(default_factory=list)
    settings: RenderSettings = field(default_factory=RenderSettings)
    source: str = ""
    #: how next-event estimation picks a light: "uniform" (as Mitsuba 3), "power" (probability ∝
    #: each light's estimated power, for scenes of many lights of different strength) or "cycles" (as Cycles
    #: without its light tree: emissive meshes by area, other lights uniformly, half each where both exist, a
    #: constant sky, beside other lights or alone, left to BSDF sampling,
    #: engine.render.lights.selection.cycles_probabilities; Blender scenes with Light Tree off; docs/benchmarks.md
    #: "Real assets against Cycles")
    light_selection: str = "uniform"
    #: the world medium (an Interior: fog everywhere outside the closed media), or None
    medium: object = None
