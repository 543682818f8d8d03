"""Light selection: which light a next-event sample goes to (uniform or by estimated importance).

Part of engine.render.lights (its package docstring states the light interface)."""

from __future__ import annotations

import threading

import numpy as np

from ...errors import SceneError
from ...polarisation.sources import uv_tangent
from ...kernels.light_sampling import (GLOBAL_SHARE, SELECT_CONSTANT, SELECTION_PARAMS, choose_light,
                                       selection_probabilities)
from ...scene.description import DirectionalLight, EnvironmentLight, PointLight, SpotLight
from ...textures import TexturedSpectrum
from .area import mesh_emitter
from .environment import EnvironmentEmitter, EnvironmentMapEmitter
from .lamps import DirectionalEmitter, PointEmitter, SpotEmitter
from .textured import TexturedAreaEmitter
from .tree import LightTree, splits_into_triangles


#: Scene.light_selection's values (engine.scene.description.Scene)
SELECTIONS = ("uniform", "power", "cycles")


class LightSet:
    """All lights of a compiled scene.  NEE picks one light per vertex: uniformly (probability
    1/count, ``Scene.light_selection`` "uniform"; ``prob[i]``), with "cycles" as Cycles without its light tree
    (``cycles_probabilities``: emissive meshes by area, other lights uniformly, a constant sky beside them never:
    BSDF sampling alone finds it), or, with
    "power", by importance:
    for up to ``SPATIAL_MAX`` lights, per shading point ∝ each light's estimated irradiance
    there (power/dist² × ``facing_factor``, as the importance of Cycles' light tree without the
    tree), mixed with
    ``GLOBAL_SHARE`` of the power distribution (so no light that can contribute gets
    probability 0); for more lights ∝ power alone.  Every MIS pdf includes the probability
    with which the light would have been chosen at the vertex the ray left (``prob_at``).
    With RenderSettings.light_tree the integrator chooses with ``light_tree()`` instead (engine.render.lights.tree,
    built on first use; ``uses_tree`` says when).
    """

    SPATIAL_MAX = 64
    GLOBAL_SHARE = GLOBAL_SHARE

    def __init__(self, scene, compiled):
        self.lights = []
        self.environment = None
        self.environment_index = -1
        self.camera_hidden = set()     # lights (indices) that camera rays do not see
        self._triangle_area = []       # per mesh light: its area where Cycles counts its triangles, else 0
        self._mesh_emitters(scene, compiled)
        self._lamps(scene)
        self._triangle_area += [0.0] * (len(self.lights) - len(self._triangle_area))
        #: some light emits polarised light (engine.render.polarised_light): the transport carries it
        self.polarised = any(light.polarisation is not None for light in self.lights)
        self._selection(scene, compiled)
        self._spatial_records()
        self.hittable = [i for i, light in enumerate(self.lights) if light.hittable]
        self._compiled = compiled
        self._tree = None
        self._tree_lock = threading.Lock()

    def uses_tree(self, mode: str) -> bool:
        """Whether RenderSettings.light_tree ``mode`` ("on", "off", "auto") chooses lights with the light tree:
        "auto" where the scene has more emitters — lamps, and each triangle of a mesh light sampled by area —
        than the per-point selection weighs one by one (SPATIAL_MAX)."""
        if mode == "off" or not self.lights:
            return False
        if mode == "on":
            return True
        count = sum(len(light.tris) if splits_into_triangles(light) else 1 for light in self.lights)
        return count > self.SPATIAL_MAX

    def light_tree(self) -> LightTree:
        """The scene's light tree, built on first use (once, whichever thread asks first)."""
        with self._tree_lock:
            if self._tree is None:
                self._tree = LightTree(self, self._compiled)
            return self._tree

    def _mesh_emitters(self, scene, compiled) -> None:
        """The emissive meshes' lights (tri_emitter filled in)."""
        for mesh_index, mesh in enumerate(scene.meshes):
            if mesh.emission is None:
                continue
            tris = np.nonzero((compiled.tri_mesh == mesh_index) & (compiled.tri_area > 0))[0]
            if len(tris) == 0:
                continue
            compiled.tri_emitter[tris] = len(self.lights)
            # Cycles' emissive triangles (a mesh that occludes; one that does not is a lamp in Cycles' sense)
            self._triangle_area.append(float(compiled.tri_area[tris].sum()) if getattr(mesh, "occluder", True)
                                       else 0.0)
            if not getattr(mesh, "visible_camera", True) and not getattr(mesh, "occluder", True):
                self.camera_hidden.add(len(self.lights))
            two_sided, spread = getattr(mesh, "two_sided", False), getattr(mesh, "spread_deg", 180.0)
            if isinstance(mesh.emission, TexturedSpectrum):     # radiance that varies over the surface
                self.lights.append(TexturedAreaEmitter(mesh.emission, tris, compiled, two_sided, spread,
                                                       getattr(mesh, "emission_sampling", "luminance"),
                                                       f"meshes[{mesh_index}] ({mesh.name!r}).emission"))
            else:
                self.lights.append(mesh_emitter(mesh.emission, tris, compiled, two_sided, spread))
            if getattr(mesh, "emission_polarisation", None) is not None:
                axis = getattr(mesh, "emission_axis", None)
                self.lights[-1].set_polarisation(mesh.emission_polarisation, axis if axis is not None else
                                                 uv_tangent(mesh.vertices, mesh.faces, mesh.uv))
            if getattr(mesh, "emission_under_layers", False):
                _under_layers(self.lights[-1], compiled, tris)
            if not getattr(mesh, "visible_indirect", True):
                self.lights[-1].shades_nothing = True

    def _lamps(self, scene) -> None:
        """The scene's lights: environment, spot, point, directional."""
        for index, light in enumerate(scene.lights):
            if not getattr(light, "visible_camera", True):
                self.camera_hidden.add(len(self.lights))
            if isinstance(light, EnvironmentLight):
                image = getattr(light, "image", None)
                self.environment = (EnvironmentEmitter(light.radiance) if image is None else
                                    EnvironmentMapEmitter(image, light.strength, light.rotation_deg, light.grid,
                                                          interpolation_space=getattr(light, "interpolation_space",
                                                                                      "linear")))
                if getattr(light, "stokes", None) is not None and image is not None:
                    self.environment.set_stokes(light.stokes, light.polarisation)
                elif getattr(light, "sky", None) is not None and image is not None:
                    self.environment.set_sky(light.sky, light.polarisation)
                self.environment_index = len(self.lights)
                self.lights.append(self.environment)
            elif isinstance(light, SpotLight):
                self.lights.append(SpotEmitter(light.intensity, light.position, light.direction,
                                               light.cone_angle_deg, light.blend,
                                               getattr(light, "blend_profile", "angle"),
                                               getattr(light, "radius", 0.0), getattr(light, "soft_falloff", True)))
            elif isinstance(light, PointLight):
                self.lights.append(PointEmitter(light.intensity, light.position, getattr(light, "radius", 0.0),
                                                getattr(light, "soft_falloff", True)))
            elif isinstance(light, DirectionalLight):
                self.lights.append(DirectionalEmitter(light.irradiance, light.direction,
                                                      getattr(light, "angle_deg", 0.0)))
            else:       # e.g. a light of another copy of this package: never leave a light out silently
                raise SceneError(f"lights[{index}]", f"is a {type(light).__module__}.{type(light).__name__}, not "
                                                     "one of engine.scene.description's light types")
            self.lights[-1].set_polarisation(getattr(light, "polarisation", None),
                                             getattr(light, "polarisation_axis", None))

    def _selection(self, scene, compiled) -> None:
        """Selection probabilities: uniform, as Cycles without its tree, or by power (``light_selection``)."""
        count = len(self.lights)
        self.select_prob = 1.0 / count if count else 0.0
        self.selection = getattr(scene, "light_selection", "uniform")
        if self.selection not in SELECTIONS:
            raise SceneError("light_selection", f"must be one of {SELECTIONS}, got {self.selection!r}")
        self.prob = np.full(count, self.select_prob)
        self.mix_prob = self.prob
        self.cdf = None
        sky = np.array([lt.constant_sky for lt in self.lights], bool)
        if self.selection == "cycles" and count >= 1:
            prob = cycles_probabilities(np.array(self._triangle_area), sky,
                                        np.array([lt.shades_nothing for lt in self.lights], bool))
            if prob is not None:
                self.prob, self.cdf = prob, np.cumsum(prob)
                self.cdf[-1] = 1.0
        if self.selection == "power" and count > 1:
            radius = max(float(np.linalg.norm(compiled.vertices - compiled.vertices.mean(0), axis=1).max()), 1e-9)
            power = np.array([0.0 if lt.shades_nothing else lt.power(radius) if lt.at_infinity else lt.power()
                              for lt in self.lights])
            power = np.where(np.isfinite(power) & (power > 0), power, 0.0)
            if power.sum() > 0:
                self.prob = power / power.sum()
                self.cdf = np.cumsum(self.prob)
                self.cdf[-1] = 1.0
                # the global share mixed into the per-point probabilities leaves a constant sky out
                # beside other lights (EnvironmentEmitter.SELECTION_SHARE)
                local = np.where(sky, 0.0, power)
                self.mix_prob = local / local.sum() if local.sum() > 0 else self.prob
        #: whether next-event estimation samples any light (not where "cycles" leaves a constant sky alone to BSDF rays)
        self.sampled = bool(count) and bool(np.any(self.prob > 0))

    def _spatial_records(self) -> None:
        """Every light's importance formula as (kind, parameters) for the per-point selection (≤ SPATIAL_MAX)."""
        count = len(self.lights)
        self.spatial = self.selection == "power" and self.cdf is not None and count <= self.SPATIAL_MAX
        if self.spatial:
            records = [light.selection_record() for light in self.lights]
            self._kinds = np.array([k for k, _ in records], np.int64)
            self._params = np.zeros((count, SELECTION_PARAMS))
            for i, (_, row) in enumerate(records):
                self._params[i, :len(row)] = row
                if self.lights[i].shades_nothing:       # its importance: none (a constant 0)
                    self._kinds[i], self._params[i, :] = SELECT_CONSTANT, 0.0

    def probabilities(self, p, n=None):
        """Selection probabilities (count, N) at shading points p (3, N) with side normals n (the
        geometric normal on the side the path arrived from) or None."""
        if not self.spatial:
            return np.repeat(self.prob[:, None], p.shape[1], axis=1)
        return selection_probabilities(p, n, self._kinds, self._params, self.mix_prob)

    def prob_at(self, li, p, n=None):
        """Probability (N,) or scalar that NEE at points p (3, N) with side normals n picks light ``li``."""
        if not self.spatial or p is None:
            return self.prob[li]
        return self.probabilities(p, n)[li]

    def choose(self, u, p=None, n=None):
        """(light index (N,), the remainder of u rescaled to [0, 1), the chosen lights'
        probabilities (N,) or None where they are ``prob[index]``) for uniform numbers u (N,)
        at shading points p (3, N) with side normals n."""
        count = len(self.lights)
        if self.cdf is None:
            choice = np.minimum((u * count).astype(np.int64), count - 1)
            return choice, u * count - choice, None
        if self.spatial and p is not None:
            return choose_light(u, self.probabilities(p, n))
        choice = np.minimum(np.searchsorted(self.cdf, u, side="right"), count - 1)
        lo = np.where(choice > 0, self.cdf[np.maximum(choice - 1, 0)], 0.0)
        rest = (u - lo) / np.where(self.prob[choice] > 0, self.prob[choice], 1.0)
        return choice, np.clip(rest, 0.0, np.nextafter(1.0, 0.0)), None

    def __len__(self):
        return len(self.lights)


def cycles_probabilities(triangle_area: np.ndarray, constant_sky: np.ndarray, shades_nothing: np.ndarray):
    """Selection probabilities (count,) as Cycles picks lights without its light tree (scene/light.cpp
    device_update_distribution, kernel/light/distribution.h), or None where no light qualifies: the emissive
    triangles (``triangle_area`` > 0: each mesh light's area where Cycles counts its triangles) ∝ area, every other
    light uniformly (1/num_lights), half each where both kinds exist.  A constant sky gets 0, beside other lights or
    alone (test_enabled_lights: background MIS off unless the world varies or has a portal; BSDF rays find it, MIS
    weight 1: all zeros where it is the only light), and so do lights that light nothing (``shades_nothing``: Cycles
    leaves objects invisible to indirect rays out)."""
    usable = ~shades_nothing
    if (usable & constant_sky).any() and not (usable & ~constant_sky).any():
        return np.zeros(constant_sky.size)
    usable &= ~constant_sky
    area = np.where(usable, triangle_area, 0.0)
    lamps = usable & (triangle_area <= 0.0)
    if area.sum() <= 0.0 and not lamps.any():
        return None
    share = 0.5 if area.sum() > 0.0 and lamps.any() else 1.0
    prob = np.where(lamps, share / max(lamps.sum(), 1), 0.0)
    return prob + (share * area / area.sum() if area.sum() > 0.0 else 0.0)


def _under_layers(light, compiled, tris) -> None:
    """An emissive mesh's radiance × its material's layer attenuation (engine.materials.mix.emission_weight), as a
    directional factor of the light (its ``profile``, after any spread); nothing where no layer covers it."""
    from ...materials.mix import emission_weight
    materials = np.unique(compiled.tri_material[tris])
    weight = emission_weight(compiled.materials[int(materials[0])]) if materials.size == 1 else None
    if weight is None:
        return
    spread = light.profile
    light.profile = weight if spread is None else (lambda c: spread(c) * weight(c))
