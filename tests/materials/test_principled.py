"""The `principled` model (engine/materials/principled.py): Cycles' Principled layer order from polarising
parts, declared once (scene format, the Blender exporter)."""

import math

import numpy as np
import pytest

from engine.errors import SceneError
from engine.materials.evaluate import mueller_at
from engine.materials.principled import specular_ior
from engine.scene.loader import parse_material


def build(**values):
    return parse_material({"type": "principled", **values}, "materials.p")


def leaves(b, w=1.0):
    if b.name != "mix":
        return [(b, w)]
    return [x for c, cw in zip(b.components, b.weights) for x in leaves(c, w * float(cw))]


def test_layer_weights_are_cycles():
    """metal: Metallic; transmission: (1 − Metallic)·Transmission; dielectric: the rest."""
    names = sorted(b.name for b, _ in leaves(build(metallic=0.25, transmission=0.4, roughness=0.3)))
    assert names == ["rough_dielectric", "torrance_sparrow", "torrance_sparrow"]
    weights = sorted(w for _, w in leaves(build(metallic=0.25, transmission=0.4, roughness=0.3)))
    assert weights == pytest.approx(sorted([0.75 * 0.6, 0.75 * 0.4, 0.25]))
    metal = build(metallic=1.0)          # Gulbrandsen's index, reflecting Cycles' F82-Tint curve
    assert metal.name == "torrance_sparrow" and type(metal).__name__ == "F82Reflectance"
    assert metal.base.k.eval(np.array([550.0]))[0] > 0


def test_smooth_black_principled_is_black_glass_and_the_specular_level_scales_f0():
    for level in (0.5, 0.25, 1.0):
        model = build(roughness=0.0, base_color=0.0, ior=1.5, specular_ior_level=level)
        M = np.array(mueller_at(model, 0.0, 0.0, 0.0)["delta"])
        assert M[0, 0] == pytest.approx(min(0.04 * 2 * level, 0.99), rel=1e-9)
    assert specular_ior(1.5, 0.0) == pytest.approx(1.0)
    assert specular_ior(0.8, 0.25) < 1.0                # below 1: the reciprocal index


def test_transmission_is_tinted_by_the_root_of_the_base_colour():
    glass = build(transmission=1.0, roughness=0.0, base_color=[0.64, 0.25, 0.04])
    assert glass.name == "dielectric" and glass.transmission.linear_srgb() == pytest.approx([0.8, 0.5, 0.2])
    film = build(transmission=1.0, roughness=0.0, base_color=1.0, thin_film_thickness=300.0)
    assert film.name == "thin_film"


def test_bad_values_name_the_field():
    with pytest.raises(SceneError, match=r"materials\.p\.metallic: must be a finite number in \[0, 1\]"):
        build(metallic=1.5)
    with pytest.raises(SceneError, match=r"materials\.p\.distribution: must be one of 'multi_ggx', 'ggx'"):
        build(distribution="beckmann")


def test_textures_mapped_by_scale_and_offset_square_and_root_per_point(tmp_path):
    """A roughness texture offset + scale·t gives α = (offset + scale·t)² per point; a base colour so mapped
    tints the transmission by its root per point and wavelength (not the root of the texels then mapped)."""
    import OpenEXR
    from engine.textures.inputs import RootSpectrum, SquaredNumber
    OpenEXR.File({"type": OpenEXR.scanlineimage},
                 {"R": np.array([[0.2, 0.6]], np.float32)}).write(str(tmp_path / "t.exr"))
    tex = {"texture": "t.exr", "color_space": "Non-Color", "scale": 0.5, "offset": 0.25}
    model = parse_material({"type": "principled", "roughness": tex, "metallic": 1.0}, "materials.p",
                           base_dir=str(tmp_path))
    assert isinstance(model.base.m, SquaredNumber)
    assert (model.base.m.lo, model.base.m.hi) == pytest.approx(((0.25 + 0.5 * 0.2) ** 2, (0.25 + 0.5 * 0.6) ** 2))
    glass = parse_material({"type": "principled", "base_color": tex, "transmission": 1.0, "roughness": 0.0},
                           "materials.p", base_dir=str(tmp_path))
    assert isinstance(glass.transmission, RootSpectrum)
    assert glass.transmission.hi == pytest.approx(math.sqrt(0.25 + 0.5 * 0.6))


def test_coat_tint_is_cycles_path_length_approximation_on_every_lobe_below():
    """Cycles' Coat Tint: everything below the coat × 1 + w·(t^(1/cosθ_t) − 1), θ_t the view direction refracted
    into the coat (n), the same factor on reflection and transmission; an index-matched coat still tints, a
    white tint adds nothing."""
    from engine.materials.base import ShadingPoint
    from engine.materials.tinted import CoatTinted
    from engine.spectral import WavelengthLookup
    w, t, n = 0.7, 0.5, 1.6
    model = build(base_color=0.6, metallic=0.3, transmission=0.5, roughness=0.4, coat_weight=w, coat_tint=t,
                  coat_ior=n)
    below = [c for c in model.components[1:]]
    assert len(below) == 3 and all(isinstance(c, CoatTinted) for c in below)
    N = 5
    cos_o = np.linspace(1.0, 0.05, N)
    wo = np.stack([np.sqrt(1 - cos_o ** 2), np.zeros(N), cos_o])
    n_s = np.tile([[0.0], [0.0], [1.0]], (1, N))
    lam = np.tile([[450.0], [550.0], [650.0]], (1, N))
    sp = ShadingPoint(np.zeros((3, N)), n_s, n_s, wo, lam, False, WavelengthLookup(lam))
    cos_t = np.sqrt(1 - (1 - cos_o ** 2) / n ** 2)
    want = 1 + w * (t ** (1 / cos_t) - 1)
    for c in below:
        np.testing.assert_allclose(c.factor(sp), np.tile(want, (3, 1)), rtol=1e-12)
        wi = np.tile([[0.3], [0.1], [-0.95]], (1, N))
        wi /= np.linalg.norm(wi, axis=0)
        np.testing.assert_allclose(c.eval(sp, wi).matrix(), c.base.eval(sp, wi).matrix() * want, rtol=1e-12,
                                   atol=1e-300)
    matched = build(base_color=0.6, roughness=0.4, coat_weight=1.0, coat_tint=t, coat_ior=1.0)
    assert isinstance(matched, CoatTinted)
    np.testing.assert_allclose(matched.factor(sp)[0], t ** (1 / cos_o), rtol=1e-12)
    assert not any(isinstance(c, CoatTinted) for c in build(coat_weight=1.0, coat_tint=1.0).components)


def test_specular_tint_on_a_glass_keeps_reflection_plus_transmission_one():
    """Cycles' Specular Tint on the Principled transmission: reflection × F_t/F, refraction × (1 − F_t)/(1 − F), so
    F·r + (1 − F)·t = 1 per wavelength from either side (energy kept, only redistributed), and a white tint is 1."""
    from engine.materials.base import ShadingPoint
    from engine.materials.dielectric import SmoothDielectric
    from engine.materials.tinted import FresnelTinted
    from engine.polarisation.fresnel import fresnel_reflectance
    from engine.spectral import RGBUnboundedSpectrum, WavelengthLookup
    glass = FresnelTinted(SmoothDielectric(1.6), 1.6, RGBUnboundedSpectrum([1.0, 0.4, 0.1]))
    N = 6
    cos_o = np.array([1.0, 0.7, 0.3, -0.9, -0.5, -0.2])        # negative: the viewer inside the glass
    wo = np.stack([np.sqrt(1 - cos_o ** 2), np.zeros(N), cos_o])
    n_s = np.tile([[0.0], [0.0], [1.0]], (1, N))
    lam = np.tile([[450.0], [550.0], [650.0]], (1, N))
    sp = ShadingPoint(np.zeros((3, N)), n_s, n_s, wo, lam, False, WavelengthLookup(lam))
    refl = glass.base.sample(sp, np.zeros(N), np.zeros((2, N)))            # u_lobe 0: reflect
    refr = glass.base.sample(sp, np.full(N, 0.999999), np.zeros((2, N)))   # u_lobe → 1: refract (where it can)
    r, t = glass._factor(sp, refl.wi), glass._factor(sp, refr.wi)
    eta = np.where(cos_o >= 0, 1.6, 1 / 1.6)
    F = np.array([fresnel_reflectance(np.array([abs(c)]), complex(e))[0] for c, e in zip(cos_o, eta)])
    total = F[None, :] * r + (1 - F[None, :]) * t
    np.testing.assert_allclose(total, 1.0, rtol=1e-12)
    assert not np.allclose(r, 1.0)                                   # the tint does change the split


def test_a_per_point_ior_is_refused_where_it_cannot_be_rendered(tmp_path):
    """An IOR texture: the dielectric's and the glass's index per point, beside a per-point Specular IOR Level too
    (tests/materials/test_glass_per_point_index.py); across 1 (also on a glass): one line naming the field."""
    import OpenEXR
    OpenEXR.File({"type": OpenEXR.scanlineimage},
                 {"R": np.array([[1.2, 2.0]], np.float32)}).write(str(tmp_path / "ior.exr"))
    OpenEXR.File({"type": OpenEXR.scanlineimage},
                 {"R": np.array([[0.8, 1.2]], np.float32)}).write(str(tmp_path / "across.exr"))
    OpenEXR.File({"type": OpenEXR.scanlineimage},
                 {"R": np.array([[0.2, 0.7]], np.float32)}).write(str(tmp_path / "level.exr"))
    tex = {"texture": "ior.exr", "color_space": "Non-Color"}
    model = parse_material({"type": "principled", "ior": tex}, "materials.p", base_dir=str(tmp_path))
    assert model.varies_over_surface
    level = {**tex, "texture": "level.exr"}
    for extra in ({"transmission": 1.0}, {"specular_ior_level": level}, {"transmission": 0.5, "roughness": 0.3}):
        assert parse_material({"type": "principled", "ior": tex, **extra}, "materials.p",
                              base_dir=str(tmp_path)).varies_over_surface
    for extra, name in (({}, "across.exr"), ({"transmission": 1.0}, "across.exr"),
                        ({"transmission": 1.0, "roughness": 0.4}, "across.exr")):
        with pytest.raises(SceneError, match=r"^materials\.p\.ior: "):
            parse_material({"type": "principled", "ior": {**tex, "texture": name}, **extra}, "materials.p",
                           base_dir=str(tmp_path))


@pytest.mark.parametrize("tint", [None, [1.0, 0.6, 0.3]])
def test_metal_index_only_where_the_metallic_weight_is_positive_gives_the_same_bits(tmp_path, tint):
    """A textured Metallic: the metal's textured Gulbrandsen index is computed only at the points whose metallic
    weight is > 0 (TexturedGulbrandsenIndex ``live``; n = 1, κ = 0 elsewhere), and the Principled's value, pdf and
    sample are the bits of the index computed everywhere (every other read of it is weighted by the metallic)."""
    from engine.scene.loader import parse_material
    from engine.textures.conductor_index import TexturedGulbrandsenIndex
    from tests.scene.test_textures import _points_at, _shading_points, _texture_file
    texels = np.array([[0.0, 0.4, 0.0, 1.0, 0.0, 0.7]])
    name = _texture_file(tmp_path, texels)
    colour = _texture_file(tmp_path, np.array([[0.9, 0.2, 0.6, 0.05, 0.3, 0.8]]), "c.exr")
    texture = {"texture": name, "interpolation": "Closest"}
    material = {"type": "principled", "metallic": texture, "roughness": 0.4,
                "base_color": {"texture": colour, "interpolation": "Closest"}}
    if tint is not None:
        material["specular_tint"] = tint
    m = parse_material(material, "materials.p", base_dir=str(tmp_path))
    seen, stack, indices = set(), [m], []
    while stack:                    # the metal's index objects, through mixes and wrappers
        x = stack.pop()
        if id(x) in seen:
            continue
        seen.add(id(x))
        if isinstance(x, TexturedGulbrandsenIndex):
            indices.append(x)
        elif hasattr(x, "__dict__"):
            stack += [v for v in vars(x).values() if hasattr(v, "__dict__") or isinstance(v, (list, tuple))]
        elif isinstance(x, (list, tuple)):
            stack += list(x)
    assert len(indices) == 2 and all(i.live is not None for i in indices)

    def run():
        rng = np.random.default_rng(4)
        n = 6 * 50
        uv = np.repeat(np.stack(((np.arange(6) + 0.5) / 6, np.full(6, 0.5))), 50, axis=1)
        sp = _shading_points(n, rng, _points_at(uv))
        wi = rng.normal(size=(3, n))
        wi[2] = np.abs(wi[2])
        wi /= np.linalg.norm(wi, axis=0)
        q = m.shading_point(sp)
        f, pdf = m.eval_and_pdf(q, wi)
        s = m.sample(q, rng.uniform(size=n), rng.uniform(size=(2, n)))
        eta = next(i for i in indices if i.part == "n").at(sp.surface, sp.lam, False)
        return [f.matrix(), pdf, s.wi, s.pdf, s.weight.matrix()], eta
    live, eta = run()
    assert (eta[:, :50] == 1.0).all() and (eta[:, 50:100] != 1.0).all()       # texel 0: metallic 0
    for i in indices:
        i.live = None
    everywhere, _ = run()
    for a, b in zip(live, everywhere):
        assert a.tobytes() == b.tobytes()
