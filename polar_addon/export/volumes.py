"""Blender volume shaders → engine media (engine.scene.description.Interior): Material Output ▸ Volume (the
interior of the object's closed mesh), World Output ▸ Volume (the world medium) and Volume objects (OpenVDB
grids), as Cycles' svm volume closures (kernel/svm/closure.h) define them, per unit length:

- Volume Scatter: σ_s = ρ·Color, σ_a = 0, its Phase — Henyey–Greenstein (Anisotropy), Fournier–Forand
  (Backscatter, IOR), Draine (Anisotropy, Alpha), Rayleigh (the polarising engine.media.rayleigh with δ = 0:
  Cycles' S0 exactly), Mie (:data:`MIE_MODEL`: Cycles' fitted HG + Draine blend, ``cycles_mie``, depolarising,
  by default; "lorenz_mie": exact Lorenz–Mie of water droplets n = 1.33 of that Diameter, polarising and
  retarding);
- Volume Absorption: σ_a = ρ·(1 − Color);
- Principled Volume: σ_s = ρ·Color with HG(Anisotropy), σ_a = ρ·max(1 − Color, 0)·max(1 − √Absorption Color, 0);
  emission ε = Emission Strength·Emission Color + Blackbody Tint·σ/π·10⁻⁶·mix(1, T⁴, Blackbody Intensity)·
  colour(T) (polar_addon.export.blackbody; not scaled by ρ), T = Temperature × the Volume object's Temperature
  Attribute grid per point (an emission grid on the density grid's lattice), or Temperature alone on a mesh;
  its Color Attribute: the Volume object's RGB grid g per point (a Vec3 OpenVDB grid, resampled on the density
  grid's nodes), Color·g the medium's colour grid (engine Interior.colour_grid: σ_s = ρ·Color·g, σ_a =
  ρ·max(1 − Color·g, 0)·max(1 − √Absorption Color, 0)) where the Principled Volume is the volume's only closure
  (otherwise, and on a mesh where the attribute does not exist, its Color alone, one warning);
- Volume Coefficients: σ_s, σ_a its coefficients, the phase as Volume Scatter's, ε its Emission Coefficients;
- Mix Shader (1 − Fac, Fac) and Add Shader: the coefficients add up with the weights; where several scattering
  closures have different phase functions the medium's phase function is their mixture
  (engine.media.mixture) weighted by each one's mean σ_s over R, G, B (Cycles picks a closure per colour
  channel's weight: where the closures' colours are not proportional the two differ, one warning).

ρ is the Density input (≥ 0; linked to anything but an Attribute node on a Volume object: its own value, one
warning, as the exporter does for every input it cannot evaluate per point).  Principled Volume's Density
Attribute (default "density") and an Attribute node on Density read the Volume object's grid of that name
(:func:`volume_object`); on a mesh the attribute does not exist, and Cycles then uses ρ alone (so does Polar).
"""

from __future__ import annotations

import contextvars
import math
import os
from dataclasses import dataclass

import numpy as np

from ...engine.errors import SceneError
from ...engine.media.catalogue import make_phase
from ...engine.media.colour_grid import ColourGrid
from ...engine.media.grid import DensityGrid
from ...engine.media.mixture import PhaseMixture
from ...engine.scene.description import Interior, Mesh
from .. import compat
from . import blackbody
from .node_links import follow
from .node_reader import Reader

#: Cycles' Mie phase → "cycles_mie" (its fitted blend, depolarising: S0 as Cycles) or "lorenz_mie" (exact
#: Lorenz–Mie of water droplets, polarising); set per render from Render Properties ▸ Volumes ▸ Mie
MIE_MODEL = contextvars.ContextVar("polar_volume_mie", default="cycles_mie")
#: Refractive index of Cycles' Mie droplets (water) for the exact Lorenz–Mie option
WATER_N = 1.33
#: Most nodes of a dense grid read from an OpenVDB file (float64: 32 MiB); larger grids are averaged over blocks
MAX_GRID_NODES = 1 << 22
#: Volume nodes Cycles' svm evaluates
VOLUME_NODES = ("ShaderNodeVolumeScatter", "ShaderNodeVolumeAbsorption", "ShaderNodeVolumePrincipled",
                "ShaderNodeVolumeCoefficients", "ShaderNodeMixShader", "ShaderNodeAddShader")


@dataclass
class Closure:
    """One volume closure: σ_s, σ_a (3,) per unit length, its phase function (None: no scattering) and the
    name of the grid attribute its density reads (None: none)."""
    scattering: np.ndarray
    absorption: np.ndarray
    phase: object = None
    attribute: str | None = None
    #: emission ε (3,) per unit length (linear Rec. 709) where it does not vary, and the blackbody read per point:
    #: (Blackbody Intensity, Temperature, weight·Tint (3,), temperature attribute) or None
    emission: np.ndarray | None = None
    blackbody: tuple | None = None
    #: a Principled Volume's Color Attribute: (grid name, weight·ρ, Color (3,), max(1 − √Absorption Color, 0) (3,))
    coloured: tuple | None = None


def _phase(node, r, owner):
    """The engine phase function of a Volume Scatter / Volume Coefficients node's Phase (its inputs clamped to
    the ranges Cycles clamps them to)."""
    kind = getattr(node, "phase", "HENYEY_GREENSTEIN")
    field = f"{owner}.{node.name}"
    if kind == "FOURNIER_FORAND":
        return make_phase("fournier_forand", {"backscatter": min(max(r.float("Backscatter"), 0.0), 0.5),
                                              "ior": max(r.float("IOR"), 1.0)}, field, text=False)
    if kind == "DRAINE":
        return make_phase("draine", {"g": min(max(r.float("Anisotropy"), -1.0), 1.0),
                                     "alpha": min(max(r.float("Alpha"), 0.0), 1000.0)}, field, text=False)
    if kind == "RAYLEIGH":
        return make_phase("rayleigh", {"depolarisation": 0.0}, field, text=False)
    if kind == "MIE":
        d = max(r.float("Diameter"), 0.0)
        if MIE_MODEL.get() == "lorenz_mie":
            return make_phase("mie", {"radius": min(max(0.5 * d, 1e-4), 50.0), "n": WATER_N}, field, text=False)
        return make_phase("cycles_mie", {"diameter": min(d, 1000.0)}, field, text=False)
    return make_phase("henyey_greenstein", {"g": min(max(r.float("Anisotropy"), -1.0), 1.0)}, field, text=False)


def _density(node, r, name="Density"):
    """(ρ ≥ 0, grid attribute or None): an Attribute node on Density reads that grid (ρ = 1 times it)."""
    sock = node.inputs.get(name)
    source = follow(sock) if sock is not None and sock.is_linked else None
    if source is not None and source.bl_idname == "ShaderNodeAttribute":
        return 1.0, source.attribute_name
    return max(r.float(name), 0.0), None


def _vector(sock):
    v = sock.default_value
    return np.array([float(x) for x in v[:3]] if hasattr(v, "__len__") else [float(v)] * 3)


def volume_closures(node, owner, warnings, weight=1.0, depth=0) -> list[Closure]:
    """The closures (see the module docstring) of the volume graph at ``node``, scaled by ``weight``; ``owner``
    names the material or world in messages."""
    kind = node.bl_idname
    r = Reader(owner, node, warnings)
    if kind in ("ShaderNodeMixShader", "ShaderNodeAddShader"):
        if depth > 32:
            raise SceneError(f"material {owner!r}", "volume shader mixes nest more than 32 deep")
        shaders = [sk for sk in node.inputs if sk.type == "SHADER"]
        if kind == "ShaderNodeMixShader":
            fac = min(max(float(r._constant(node.inputs[0].name).default_value), 0.0), 1.0)
            weights = (1.0 - fac, fac)
        else:
            weights = (1.0, 1.0)
        out = []
        for sk, w in zip(shaders, weights):
            child = follow(sk)
            if child is not None and w > 0:
                out += volume_closures(child, owner, warnings, weight * w, depth + 1)
        return out
    zero = np.zeros(3)
    if kind == "ShaderNodeVolumeAbsorption":
        density, attribute = _density(node, r)
        return [Closure(zero, weight * density * (1.0 - np.array(r.rgb("Color", -math.inf))), None, attribute)]
    if kind == "ShaderNodeVolumeScatter":
        density, attribute = _density(node, r)
        sigma_s = weight * density * np.maximum(np.array(r.rgb("Color", -math.inf)), 0.0)
        return [Closure(sigma_s, zero, _phase(node, r, owner), attribute)]
    if kind == "ShaderNodeVolumePrincipled":
        density = max(r.float("Density"), 0.0)
        attribute = _attribute_name(node, "Density Attribute")
        colour = np.array(r.rgb("Color", -math.inf))
        absorption_colour = np.array(r.rgb("Absorption Color", 0.0))
        colour_attribute = _attribute_name(node, "Color Attribute")
        emission = weight * max(r.float("Emission Strength"), 0.0) * np.maximum(r.rgb("Emission Color", 0.0), 0.0)
        bb = max(r.float("Blackbody Intensity"), 0.0)
        blackbody = None
        if bb > 0:
            tint = weight * np.maximum(np.array(r.rgb("Blackbody Tint", 0.0)), 0.0)
            blackbody = (bb, max(r.float("Temperature"), 0.0), tint, _attribute_name(node, "Temperature Attribute"))
        tint = np.maximum(1.0 - np.sqrt(absorption_colour), 0.0)
        sigma_s = weight * density * np.maximum(colour, 0.0)
        sigma_a = weight * density * np.maximum(1.0 - colour, 0.0) * tint
        g = min(max(r.float("Anisotropy"), -1.0), 1.0)
        coloured = (colour_attribute, weight * density, colour, tint) if colour_attribute is not None else None
        return [Closure(sigma_s, sigma_a, make_phase("henyey_greenstein", {"g": g}, f"{owner}.{node.name}",
                                                     text=False), attribute, emission, blackbody, coloured)]
    if kind == "ShaderNodeVolumeCoefficients":
        sigma_s = weight * np.maximum(_vector(node.inputs["Scatter Coefficients"]), 0.0)
        sigma_a = weight * np.maximum(_vector(node.inputs["Absorption Coefficients"]), 0.0)
        sock = node.inputs.get("Emission Coefficients")
        emission = weight * np.maximum(_vector(sock), 0.0) if sock is not None else None
        return [Closure(sigma_s, sigma_a, _phase(node, r, owner) if sigma_s.max() > 0 else None, emission=emission)]
    warnings.append(f"{owner}: volume shader {kind} is not simulated (Polar renders Volume Scatter, Volume "
                    "Absorption, Principled Volume, Volume Coefficients and their mixes); it is left clear")
    return []


def _attribute_name(node, socket) -> str | None:
    """The grid name a Principled Volume attribute socket (a string) names, None when empty or absent."""
    sock = node.inputs.get(socket)
    return (sock.default_value if sock is not None else "") or None


def _emission(closures, grid, temperature) -> dict:
    """Interior keywords of the closures' emission: ``emission`` (3,) where it does not vary, or ``emission_grid``
    (a ColourGrid on the density ``grid``'s lattice) where a blackbody reads the ``temperature`` grid."""
    constant = sum((c.emission for c in closures if c.emission is not None), np.zeros(3))
    per_point = []
    for c in closures:
        if c.blackbody is None:
            continue
        intensity, T, tint, _ = c.blackbody
        if temperature is not None and grid is not None:
            per_point.append((intensity, T, tint))
        else:                       # no temperature grid (a mesh, or none read): Temperature alone, as Cycles
            constant = constant + blackbody.emission(T, intensity, tint)
    if not per_point:
        return {"emission": [float(x) for x in constant]} if constant.max() > 0 else {}
    n = grid.values.shape
    t_nodes = temperature.density(_nodes(grid)).reshape(n)
    values = np.broadcast_to(constant, n + (3,)).copy()
    for intensity, T, tint in per_point:
        values += blackbody.emission(T * t_nodes, intensity, tint)
    return {"emission_grid": ColourGrid(np.moveaxis(values, -1, 0), grid.lo, grid.hi, field="emission grid")}


def _nodes(grid) -> np.ndarray:
    """The world positions (3, N) of a DensityGrid's nodes, in its values' (C) order."""
    n = grid.values.shape
    X, Y, Z = np.meshgrid(*(np.linspace(grid.lo[a], grid.hi[a], n[a]) for a in range(3)), indexing="ij")
    return np.stack((X.ravel(), Y.ravel(), Z.ravel()))


def _coloured(closures, grid, temperature, colour) -> Interior | None:
    """The medium of a lone Principled Volume whose Color Attribute read the RGB grid ``colour`` (3 DensityGrids):
    σ_s = weight·ρ, σ_a = weight·ρ·max(1 − √Absorption Color, 0), its colour grid Color·g on the density ``grid``'s
    nodes (engine Interior.colour_grid; None where that does not apply: see the module docstring)."""
    c = closures[0]
    if len(closures) != 1 or c.coloured is None or colour is None or grid is None:
        return None
    _, scale, rgb, tint = c.coloured
    at = _nodes(grid)
    values = np.stack([np.maximum(rgb[i] * colour[i].density(at), 0.0) for i in range(3)])
    return Interior([float(x) for x in scale * tint], scattering=[scale] * 3, phase=c.phase, grid=grid,
                    colour_grid=ColourGrid(values.reshape((3,) + grid.values.shape), grid.lo, grid.hi,
                                           field="colour grid"),
                    **_emission(closures, grid, temperature))


def medium_of(closures, owner, warnings, grid=None, temperature=None, colour=None) -> Interior | None:
    """The Interior of the closures (None when it neither absorbs, scatters nor emits): their summed coefficients
    and their phase functions (one, or their mixture: see the module docstring); ``grid`` scales both; their
    emission (not scaled), per point where a blackbody reads the ``temperature`` grid (a DensityGrid); a lone
    Principled Volume's colour per point where its Color Attribute read ``colour`` (3 DensityGrids: r, g, b)."""
    if not closures:
        return None
    coloured = _coloured(closures, grid, temperature, colour)
    if coloured is not None:
        return coloured
    for c in closures:              # (on a mesh the attribute does not exist: Cycles uses Color alone, as here)
        if c.coloured is not None and colour is not None:
            warnings.append(f"{owner}: the Color Attribute {c.coloured[0]!r} of its Principled Volume is read only "
                            "where that Principled Volume is the volume's one closure (no mixes); its Color is used "
                            "everywhere")
    sigma_s = sum(c.scattering for c in closures)
    sigma_a = sum(c.absorption for c in closures)
    if not (np.all(np.isfinite(sigma_s)) and np.all(np.isfinite(sigma_a))):
        raise SceneError(owner, f"the volume's coefficients must be finite, got σ_s {sigma_s.tolist()}, "
                                f"σ_a {sigma_a.tolist()}")
    sigma_a = np.maximum(sigma_a, 0.0)      # a Color above 1 would absorb negatively: Cycles' too, none here
    emits = _emission(closures, grid, temperature)
    scatterers = [c for c in closures if c.phase is not None and c.scattering.max() > 0]
    if not scatterers:
        if sigma_a.max() <= 0 and not emits:
            return None
        return Interior([float(x) for x in sigma_a], grid=grid, **emits)
    phases, weights = [], []
    for c in scatterers:
        described = c.phase.describe()
        same = next((i for i, p in enumerate(phases) if p.describe() == described), None)
        if same is None:
            phases.append(c.phase)
            weights.append([c.scattering])
        else:
            weights[same].append(c.scattering)
    colours = [sum(w) for w in weights]
    if len(phases) == 1:
        phase = phases[0]
    else:
        phase = PhaseMixture(phases, [float(np.mean(c)) for c in colours])
        ref = colours[0] / max(float(np.mean(colours[0])), 1e-300)
        if any(not np.allclose(c / max(float(np.mean(c)), 1e-300), ref, rtol=1e-6, atol=0) for c in colours[1:]):
            warnings.append(f"{owner}: its volume mixes phase functions whose scattering colours differ; Polar "
                            "weights the phase functions by their mean scattering coefficient (Cycles per colour "
                            "channel)")
    return Interior([float(x) for x in sigma_a], scattering=[float(x) for x in sigma_s], phase=phase, grid=grid,
                    **emits)


def material_medium(volume_node, material_name, warnings) -> Interior | None:
    """The medium of a material's Volume graph (a mesh's interior; its density attributes are 1 on a mesh)."""
    return medium_of(volume_closures(volume_node, f"material {material_name!r}", warnings),
                     f"material {material_name!r}", warnings)


def world_medium(world, warnings) -> Interior | None:
    """The world medium of World Output ▸ Volume (None: none or clear)."""
    tree = compat.node_tree_in_use(world) if world is not None else None
    output = (tree.get_output_node("ALL") or tree.get_output_node("CYCLES")) if tree is not None else None
    sock = output.inputs.get("Volume") if output is not None else None
    node = follow(sock) if sock is not None else None
    if node is None:
        return None
    owner = f"world {world.name!r}"
    return medium_of(volume_closures(node, owner, warnings), owner, warnings)


# --------------------------------------------------------------------------- Volume objects (OpenVDB)

def volume_object(obj, M, material, warnings):
    """(Mesh, Interior) of a Volume object placed by ``M`` with ``material`` (its first slot): the box around its
    grid as a transparent surface whose interior is the material's medium with the density grid its volume
    shader reads (Principled Volume's Density Attribute or an Attribute node), read from the object's OpenVDB
    file (:func:`read_grid`); None with one warning where there is nothing to read (no file: a generated volume,
    a simulation cache not on disk; no such grid; no volume shader)."""
    name = f"Volume object {obj.name!r}"
    tree = compat.node_tree_in_use(material) if material is not None else None
    output = (tree.get_output_node("ALL") or tree.get_output_node("CYCLES")) if tree is not None else None
    node = follow(output.inputs["Volume"]) if output is not None and "Volume" in output.inputs else None
    if node is None:
        warnings.append(f"{name}: its material has no Volume shader; skipped")
        return None
    owner = f"material {material.name!r}"
    closures = volume_closures(node, owner, warnings)
    attributes = list(dict.fromkeys(c.attribute for c in closures if c.attribute))
    if not attributes:
        warnings.append(f"{name}: its volume shader reads no grid (Density Attribute or an Attribute node on "
                        "Density); skipped")
        return None
    if len(attributes) > 1:
        warnings.append(f"{name}: its volume shader reads grids {', '.join(map(repr, attributes))}; Polar scales "
                        f"every closure by {attributes[0]!r}")
    path = compat.volume_file(obj)
    if path is None:
        warnings.append(f"{name}: its grids are generated, not read from a file (Mesh to Volume, geometry nodes, a "
                        "simulation cache not on disk), which Polar does not simulate; skipped")
        return None
    grid = read_grid(path, attributes[0], M, warnings, name)
    if grid is None:
        return None
    hot = list(dict.fromkeys(c.blackbody[3] for c in closures if c.blackbody is not None and c.blackbody[3]))
    temperature = read_grid(path, hot[0], M, warnings, name) if hot else None
    tinted = list(dict.fromkeys(c.coloured[0] for c in closures if c.coloured is not None))
    colour = read_grid(path, tinted[0], M, warnings, name, channels=3) if tinted else None
    interior = medium_of(closures, owner, warnings, grid=grid, temperature=temperature, colour=colour)
    if interior is None:
        return None
    return box_mesh(f"{obj.name} (volume)", grid.lo, grid.hi), interior


def box_mesh(name, lo, hi) -> Mesh:
    """A closed box [lo, hi] with outward faces (no material assigned yet: ``materials`` is set by the caller)."""
    c = np.array([[lo[0], lo[1], lo[2]], [hi[0], lo[1], lo[2]], [hi[0], hi[1], lo[2]], [lo[0], hi[1], lo[2]],
                  [lo[0], lo[1], hi[2]], [hi[0], lo[1], hi[2]], [hi[0], hi[1], hi[2]], [lo[0], hi[1], hi[2]]])
    faces = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                      [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]], np.int64)
    return Mesh(name, c, faces, [], np.zeros(len(faces), np.int64))


def read_grid(path, grid_name, M, warnings, what, max_nodes=MAX_GRID_NODES, channels=1):
    """The float grid ``grid_name`` of the OpenVDB file ``path`` as a dense DensityGrid in world space (object
    matrix ``M``): its active voxels' index box, averaged over blocks of f³ voxels where it has more than
    ``max_nodes`` voxels (the mean density, hence the mean optical depth, is kept; detail finer than f voxels is
    lost: one warning), then resampled trilinearly onto a lattice over the box's world bounds with as many nodes
    per axis (an object rotation resamples; negative values count as 0).  ``channels`` 3: a vector grid (Vec3, e.g.
    a Color Attribute; a float grid counts as grey) as a list of three DensityGrids (r, g, b) on one lattice."""
    openvdb = compat.openvdb_module()
    if openvdb is None:
        warnings.append(f"{what}: this Blender has no openvdb module to read {os.path.basename(path)!r}; skipped")
        return None
    try:
        grid = openvdb.read(path, grid_name)
    except (KeyError, RuntimeError, OSError, ValueError) as e:
        warnings.append(f"{what}: grid {grid_name!r} cannot be read from {os.path.basename(path)!r} ({e}); skipped")
        return None
    (i0, j0, k0), (i1, j1, k1) = grid.evalActiveVoxelBoundingBox()
    shape = np.array([i1 - i0 + 1, j1 - j0 + 1, k1 - k0 + 1], np.int64)
    if np.any(shape < 1) or i1 < i0:
        warnings.append(f"{what}: grid {grid_name!r} has no active voxels; skipped")
        return None
    f = max(1, math.ceil((float(np.prod(shape)) / max_nodes) ** (1.0 / 3.0)))
    if f > 1:
        warnings.append(f"{what}: grid {grid_name!r} ({'×'.join(map(str, shape))} voxels) is averaged over "
                        f"{f}×{f}×{f}-voxel blocks to fit {max_nodes} nodes")
    vector = "vec3" in type(grid).__name__.lower()
    if vector != (channels == 3):
        warnings.append(f"{what}: grid {grid_name!r} is a {'vector' if vector else 'float'} grid, read as "
                        f"{'its first component' if vector else 'grey'}")
    pooled = _pooled(grid, (i0, j0, k0), shape, f, 3 if vector else 1)
    if vector and channels == 1:
        pooled = pooled[..., 0]
    elif channels == 3:
        pooled = pooled if vector else np.repeat(pooled[..., None], 3, axis=-1)
        return [_resampled(pooled[..., c], grid, M, f, (i0, j0, k0), what) for c in range(3)]
    return _resampled(pooled, grid, M, f, (i0, j0, k0), what)


def _resampled(pooled, grid, M, f, start, what) -> DensityGrid:
    """The pooled index-space values (read_grid) resampled onto a world-space lattice over their box."""
    # index → object space (a linear VDB transform: origin and three axes), then → world
    origin = np.array(grid.transform.indexToWorld((0.0, 0.0, 0.0)))
    axes = np.array([np.array(grid.transform.indexToWorld(tuple(e))) - origin for e in np.eye(3)]).T
    A = M[:3, :3] @ axes
    t = M[:3, :3] @ origin + M[:3, 3]
    first = np.array(start, np.float64) + 0.5 * (f - 1)          # the pooled nodes' index positions
    for a in range(3):                                                  # one node along an axis: two equal ones
        if pooled.shape[a] == 1:
            pooled = np.concatenate((pooled, pooled), axis=a)
    last = first + f * (np.array(pooled.shape) - 1)
    in_index = DensityGrid(np.maximum(pooled, 0.0), first, last, field=f"{what}.grid")
    corners = np.array([[first[0] if a == 0 else last[0], first[1] if b == 0 else last[1],
                         first[2] if c == 0 else last[2]] for a in (0, 1) for b in (0, 1) for c in (0, 1)])
    world = corners @ A.T + t
    lo, hi = world.min(axis=0), world.max(axis=0)
    n = np.array(pooled.shape)
    X, Y, Z = np.meshgrid(*(np.linspace(lo[a], hi[a], n[a]) for a in range(3)), indexing="ij")
    local = np.linalg.solve(A, np.stack((X.ravel(), Y.ravel(), Z.ravel())) - t[:, None])     # index positions
    for end in (first, last):                       # the box's own faces, not rounding, decide what is inside
        local = np.where(np.abs(local - end[:, None]) < 1e-6 * f, end[:, None], local)
    values = in_index.density(local).reshape(tuple(n))
    return DensityGrid(values, lo, hi, field=f"{what}.grid")


def _pooled(grid, start, shape, f, channels=1) -> np.ndarray:
    """Block means of f³ voxels of the grid's index box from ``start`` of ``shape``, read slab by slab (a vector
    grid's ``channels`` 3 on a last axis)."""
    out_shape = tuple(int(math.ceil(s / f)) for s in shape)
    tail = (channels,) if channels > 1 else ()
    out = np.zeros(out_shape + tail, np.float64)
    for a in range(out_shape[0]):
        nx = int(min(f, shape[0] - a * f))
        slab = np.zeros((nx, int(shape[1]), int(shape[2])) + tail, np.float32)
        grid.copyToArray(slab, ijk=(int(start[0] + a * f), int(start[1]), int(start[2])))
        pad = [(0, f - nx), (0, out_shape[1] * f - shape[1]), (0, out_shape[2] * f - shape[2])] + [(0, 0)] * len(tail)
        block = np.pad(slab.astype(np.float64), pad)
        block = block.reshape((f, out_shape[1], f, out_shape[2], f) + tail).sum(axis=(0, 2, 4))
        out[a] = block / (f ** 3)
    return out

