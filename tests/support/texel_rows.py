"""A model whose one parameter comes from a texture, against the constant model at each texel.

``textured_and_constant(tmp_path, material, key, texels, reps, seed)`` writes a one-row float EXR with the
``texels`` values, parses ``material`` with ``key`` read from it (Closest interpolation) and returns the shading
points (``reps`` per texel, in texel order, upper-hemisphere directions and sampler numbers), the textured model
and, per texel, (its point indices, the constant model with that texel's value — float32 as stored, the
shading points without their surface).  The per-texel tests of every texturable parameter use it.
"""

from __future__ import annotations

import numpy as np


def textured_and_constant(tmp_path, material: dict, key: str, texels, reps: int = 30, seed: int = 0):
    from engine.scene.loader import parse_material
    from tests.scene.test_textures import _points_at, _shading_points, _texture_file
    values = np.asarray(texels, np.float64).reshape(1, -1)
    count = values.shape[1]
    name = _texture_file(tmp_path, values)
    textured = parse_material({**material, key: {"texture": name, "interpolation": "Closest"}}, "materials.m",
                              base_dir=str(tmp_path))
    centres = (np.arange(count) + 0.5) / count
    uv = np.repeat(np.stack((centres, np.full(count, 0.5))), reps, axis=1)
    rng = np.random.default_rng(seed)
    n = uv.shape[1]
    sp = _shading_points(n, rng, _points_at(uv))
    wi = rng.normal(size=(3, n))
    wi[2] = np.abs(wi[2])
    wi /= np.linalg.norm(wi, axis=0)
    u_lobe, u_dir = rng.uniform(size=n), rng.uniform(size=(2, n))
    rows = []
    for i, v in enumerate(values[0].astype(np.float32).astype(np.float64)):
        sel = np.arange(i * reps, (i + 1) * reps)
        sub = sp.take(sel)
        sub.surface = None
        rows.append((sel, float(v), parse_material({**material, key: float(v)}, "materials.m"), sub))
    return sp, wi, u_lobe, u_dir, textured, rows
