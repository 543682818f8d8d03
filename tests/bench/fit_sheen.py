"""Measure Cycles' microfiber sheen with bpy renders and fit Polar's own LTC table to it.

    python tests/bench/fit_sheen.py [--measurements FILE] [--remeasure] [--out PATH] [--size PX] [--suns K]

Writes engine/materials/data/sheen_ltc.npz, the table engine/materials/sheen.py reads.  Runs in the bpy
module (Blender as a Python module, Cycles on the CPU, 2 threads); not part of the test command.

What Cycles computes (kernel/closure/bsdf_sheen.h; Zeltner, Burley & Chiang 2022, "Practical
Multiple-Scattering Sheen Using Linearly Transformed Cosines").  Per closure, with μ = N·V (V towards the
viewer) and r = clamp(roughness, 10⁻³, 1), three numbers a, b, E are read from a 32 × 32 table by bilinear
interpolation at x = μ·31, y = r·31 (kernel/util/lookup_table.h: node i at i/31 on both axes, the table
stored roughness-major), and the BRDF·cosθ_i towards the light direction L is

    E · D(L),   D(L) = (1/π) · max(z, 0) · (a / ((a x + b z)² + (a y)² + z²))²

with (x, y, z) the components of L in the frame T = B × N, B = normalize(N × V) (T: the viewer's side of
the tangent plane).  D is a linearly transformed clamped cosine (M⁻¹ = [[a, 0, b], [0, a, 0], [0, 0, 1]]);
with a > 0 it maps the upper hemisphere onto itself, so ∫ D dω = 1 there and E is the directional albedo.
The table itself ships in Blender's source (intern/cycles/scene/shader.tables), not in bpy, and is not
copied: this script measures the lobe and fits a table of its own.

Measurement (about 1½ minutes on 2 cores).  One scene, rendered once per sun direction: flat square
patches side by side in the plane z = 0, seen by an orthographic camera along −z (V = +z), each with a Sheen
BSDF node (Microfiber, Color white) of its own roughness.  Each patch carries custom vertex normals covering
every shading normal of the view hemisphere (μ linear in the patch's x, the normal's azimuth about V in
its y), so one render samples 2-D families of (N, V, L); the sun directions L are at angles γ from V
uniform in cos γ over the whole sphere (back light too), and over the renders the light covers the whole
local hemisphere at every μ.  The sun has angle 0, strength 1 and casts no shadow (a ray towards a light
behind the geometric plane would otherwise hit the patch it left: Cycles' shadow-terminator offset); the
world is black; Max Bounces 0 (direct light only); light tree off, light threshold 0; one sample per
pixel through a 0.01 px Gaussian filter (Cycles' box filter is 1 px whatever its width), so the sample is
the pixel's centre: with one delta light the render is noise-free, and the Normal pass is the shading
normal Cycles used there.  Normalisation, checked on a Diffuse BSDF patch: pixel = sun strength × BRDF ×
cosθ_i (Lambert: cosθ_i/π to 10⁻⁶), so here pixel = E·D(L).  Render sets:

* ``node``: 32 patches at the roughness nodes j/31 (patch 0 at roughness 0, which Cycles clamps to 10⁻³
  and reads mixed 0.969 : 0.031 with row 1), ``--suns`` suns;
* ``between``: 17 patches between the rows 0–4, where rows have empty nodes (E = 0, see below) whose a, b
  only show in the mix with the next row;
* ``mid`` (validation only): the mid-node roughnesses (j + ½)/31 and 0.25/31, 8 other suns;
* spheres (validation only): E alone.  A smooth UV sphere (256 × 128) per roughness under a white world
  seen only through the BSDF's own samples (world sampling off, Max Bounces 1).  Cycles' sheen sampler is
  exact (eval = pdf), so a sample weighs E and the pixel (one sample) is E(μ) itself, or 0 where Cycles
  rejects the sample below the facet's geometric plane.

Fit (about 5½ minutes).  The forward model is Cycles' own: per pixel, (a, b, E) interpolated linearly in
μ between the table's nodes (and in r between two rows) and evaluated as above, 0 where the interpolated
|a| or E is below 10⁻⁵ (Cycles then drops the closure).  Rows are fitted one at a time from r = 1 down,
row j with row j + 1 known (the renders between them are mixes of the two): a least-squares problem in
log a, b, log E of its 32 nodes (Levenberg–Marquardt, analytic Jacobian; residuals weighted
1/(value + 5 % of the 95th percentile of the values in the same μ interval), i.e. relative errors, every
view angle on its own scale), from two starts — the row above, and each node fitted alone to its nearest
points — keeping the better.  Only lit pixels enter; at low roughness Cycles renders nothing beyond some μ
(its E there is below 10⁻⁵): nodes that no lit pixel of the row's own render is nearest to get E = 0.  A
node fitted just below 10⁻⁵ although lit pixels sit at it is put on 10⁻⁵ (Cycles' E is on a 10⁻⁵ grid
— the fitted values fall within a few hundredths of a step of it — and its smallest non-zero value is
exactly the cut-off).  Sign convention a > 0 ((a, b) and (−a, −b) give the same D; Cycles' sampler needs
a > 0).

Printed: per row, the relative error of E·D over its lit pixels (where the value is above 1 % of the
brightest of its μ interval and 10⁻⁴ of the brightest overall), the largest absolute error ÷ the
brightest value, and pixels lit in one and dark in the other; then the same for each render set with the
table as saved (float32), E against the spheres, the normalisation check and the render times.

Data file: arrays ``a``, ``b``, ``albedo`` of shape (32, 32), indexed [i, j] = value at μ = i/31,
r = j/31; ``mu`` and ``roughness`` the node positions.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)

NODES = 32
OUT = os.path.join(REPO, "engine", "materials", "data", "sheen_ltc.npz")
COLUMNS = 8                   # patches per row of the layout
PITCH = 1.25                  # patch spacing (patches are 1 × 1)
CUTOFF = 1e-5                 # Cycles skips the closure where the interpolated |a| or E is below this


# --------------------------------------------------------------------------- the model (Cycles' form)

def interp_weights(mu, n=NODES):
    """(i0, i1, t) of Cycles' lookup_table_read at mu (arrays)."""
    x = np.clip(mu, 0.0, 1.0) * (n - 1)
    i0 = np.minimum(x.astype(np.int64), n - 1)
    i1 = np.minimum(i0 + 1, n - 1)
    return i0, i1, x - i0


def roughness_rows(r, n=NODES):
    """(j0, j1, t) of the roughness axis for a closure roughness r (scalar), snapped to a node when on one."""
    y = min(max(r, 1e-3), 1.0) * (n - 1)
    if abs(y - round(y)) < 1e-9:
        j = int(round(y))
        return j, j, 0.0
    j0 = min(int(y), n - 1)
    return j0, min(j0 + 1, n - 1), y - j0


def ltc(x, y, z, a, b):
    """D and its derivatives dD/da, dD/db."""
    u = a * x + b * z
    q = u * u + a * a * y * y + z * z
    zp = np.maximum(z, 0.0) / np.pi
    d = zp * (a / q) ** 2
    dq_da = 2 * u * x + 2 * a * y * y
    dq_db = 2 * u * z
    dd_da = zp * (2 * a / q ** 2 - 2 * a * a * dq_da / q ** 3)
    dd_db = -2 * zp * a * a * dq_db / q ** 3
    return d, dd_da, dd_db


VIEW = np.array([0.0, 0.0, 1.0])     # towards the camera


def local_light(normals, light, view=VIEW):
    """(x, y, z, μ) of the light direction in Cycles' sheen frame for normals (M, 3)."""
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    mu = n @ view
    b = np.cross(n, view)
    bl = np.linalg.norm(b, axis=1, keepdims=True)
    b = b / np.where(bl > 0, bl, 1.0)
    t = np.cross(b, n)
    return t @ light, b @ light, n @ light, mu


def node_values(p, mu, w=1.0, fixed=None):
    """(a, b, E) per point (M, 3) for the row p (32, 3), mixed as w·p + (1 − w)·fixed (w scalar or (M,))."""
    i0, i1, t = interp_weights(mu)
    q = (1 - t)[:, None] * p[i0] + t[:, None] * p[i1]
    if fixed is not None:
        w = np.broadcast_to(np.asarray(w, float), mu.shape)[:, None]
        q = w * q + (1 - w) * ((1 - t)[:, None] * fixed[i0] + t[:, None] * fixed[i1])
    return q


def shade(q, x, y, z):
    """E·D for per-point (a, b, E) (M, 3); 0 where Cycles skips the closure."""
    with np.errstate(all="ignore"):
        d, _, _ = ltc(x, y, z, q[:, 0], q[:, 1])
        return np.where((np.abs(q[:, 0]) < CUTOFF) | (q[:, 2] < CUTOFF), 0.0, q[:, 2] * d)


def evaluate(table, mu, x, y, z, r):
    """E·D from the table [i_mu, j_r, (a, b, E)] at (μ, r) per point (r scalar)."""
    j0, j1, tr = roughness_rows(r)
    return shade(node_values((1 - tr) * table[:, j0] + tr * table[:, j1], mu), x, y, z)


# --------------------------------------------------------------------------- fitting

def bin_scale(mu, v, fraction=0.05):
    """Per point: ``fraction`` of the 95th percentile of v over the points of its μ interval."""
    i0, _, _ = interp_weights(mu)
    scale = np.zeros(NODES)
    for i in np.unique(i0):
        scale[i] = fraction * np.percentile(v[i0 == i], 95)
    return scale[i0]


class Points:
    """Measurements for one roughness row: μ, x, y, z (the light in the sheen frame), the value v, and the
    weight w of the row being fitted in the closure's mix with ``fixed`` (the next row; 1: a node render)."""

    def __init__(self, mu, x, y, z, v, w):
        self.mu, self.x, self.y, self.z, self.v, self.w = mu, x, y, z, v, w

    @classmethod
    def concat(cls, parts):
        return cls(*(np.concatenate([getattr(p, k) for p in parts]) for k in ("mu", "x", "y", "z", "v", "w")))

    def take(self, sel):
        return Points(self.mu[sel], self.x[sel], self.y[sel], self.z[sel], self.v[sel], self.w[sel])

    @property
    def size(self):
        return self.v.size


def fit_row(pts, p0, live_nodes, shape_nodes, fixed=None, iterations=400, prior=1e-6):
    """Levenberg–Marquardt fit of one roughness row's node values (32, 3) [a, b, E] to the lit points
    ``pts`` (v > 0), from p0 and weakly held to it where the data say little (``prior``).

    Unknowns: log a and b of the ``shape_nodes``, log E of the ``live_nodes`` (a, E > 0); the other nodes
    keep p0's a, b and E = 0 (Cycles skipped the closure there).  Residuals are weighted
    1/(v + 5 % of the 95th percentile of v in its μ interval): relative errors, each view angle on its
    own scale."""
    n = NODES
    mu, x, y, z, v = pts.mu, pts.x, pts.y, pts.z, pts.v
    i0, i1, t = interp_weights(mu)
    w = 1.0 / (v + bin_scale(mu, v))
    idx = np.stack([i0 * 3, i0 * 3 + 1, i0 * 3 + 2, i1 * 3, i1 * 3 + 1, i1 * 3 + 2], axis=1)   # (M, 6)
    coef = np.stack([1 - t, 1 - t, 1 - t, t, t, t], axis=1) * pts.w[:, None]
    live = np.asarray(live_nodes, bool)
    shape = np.asarray(shape_nodes, bool) | live

    def to_p(theta):
        p = p0.copy()
        p[shape, 0] = np.exp(theta[shape, 0])
        p[shape, 1] = theta[shape, 1]
        p[live, 2] = np.exp(theta[live, 2])
        p[~live, 2] = 0.0
        return p

    def residual_jacobian(theta):
        p = to_p(theta)
        q = node_values(p, mu, pts.w, fixed)
        d, da, db = ltc(x, y, z, q[:, 0], q[:, 1])
        e = q[:, 2]
        res = (e * d - v) * w
        g = np.stack([e * da, e * db, d], axis=1) * w[:, None]          # (M, 3) ∂res/∂(a, b, E) of the point
        dp = np.stack([np.where(shape, p[:, 0], 0.0), shape * 1.0, np.where(live, p[:, 2], 0.0)], axis=1).ravel()
        return res, coef * np.concatenate([g, g], axis=1) * dp[idx]     # (M, 6) ∂res/∂θ

    def normal_equations(res, jac):
        jtj = np.bincount((idx[:, :, None] * (3 * n) + idx[:, None, :]).ravel(),
                          (jac[:, :, None] * jac[:, None, :]).ravel(), minlength=(3 * n) ** 2)
        jtr = np.bincount(idx.ravel(), (jac * res[:, None]).ravel(), minlength=3 * n)
        return jtj.reshape(3 * n, 3 * n), jtr

    theta0 = np.stack([np.log(np.maximum(p0[:, 0], 1e-6)), p0[:, 1], np.log(np.maximum(p0[:, 2], 1e-9))], axis=1)
    theta = theta0.copy()
    with np.errstate(all="ignore"):
        res, jac = residual_jacobian(theta)
        jtj, _ = normal_equations(res, jac)
        # Tikhonov weights towards p0, each a small fraction of its parameter's own curvature (a floor
        # for parameters no point depends on)
        dj = np.diag(jtj)
        reg = prior * np.maximum(dj, 1e-12 * max(float(dj.max()), 1e-30))

        def cost_of(r, th):
            return float(r @ r) + float(np.sum(reg * ((th - theta0).ravel()) ** 2))

        cost, lam = cost_of(res, theta), 1e-3
        for _ in range(iterations):
            jtj, jtr = normal_equations(res, jac)
            jtj = jtj + np.diag(reg)
            jtr = jtr + reg * (theta - theta0).ravel()
            diag = np.diag(jtj).copy()
            improved = converged = False
            for _ in range(30):
                step = np.linalg.solve(jtj + lam * np.diag(diag), -jtr)
                trial = theta + step.reshape(n, 3)
                r2, j2 = residual_jacobian(trial)
                c2 = cost_of(r2, trial)
                if np.isfinite(c2) and c2 < cost:
                    converged = cost - c2 < 1e-13 * cost
                    theta, res, jac, cost = trial, r2, j2, c2
                    lam = max(lam / 3, 1e-12)
                    improved = True
                    break
                lam *= 4
            if not improved or converged:
                break
    return to_p(theta)


def local_start(pts, p0, live, fixed=None):
    """Each live node's (a, b, E) fitted alone to the points nearest to it (as if all were at the node),
    from the points where the row weighs most (node renders); mixes with ``fixed`` undone."""
    top = pts.w >= pts.w.max() - 1e-9
    sub = pts.take(top)
    wt = float(sub.w.mean())
    i0, i1, t = interp_weights(sub.mu)
    near = np.where(t < 0.5, i0, i1)
    p = p0.copy()
    for i in np.nonzero(live)[0]:
        sel = near == i
        if not sel.any():
            continue
        one = np.zeros(NODES, bool)
        one[i] = True
        s = sub.take(sel)
        s = Points(np.full(s.size, min(i + 1e-9, NODES - 1) / (NODES - 1)), s.x, s.y, s.z, s.v, np.ones(s.size))
        q = fit_row(s, p0, one, one)[i]
        p[i] = q if fixed is None else (q - (1 - wt) * fixed[i]) / wt
    p[:, 0] = np.maximum(p[:, 0], 1e-4)
    p[:, 2] = np.maximum(p[:, 2], 1e-8)
    return p


def row_cost(p, pts, fixed=None):
    """The weighted least-squares cost fit_row minimises (without its prior)."""
    with np.errstate(all="ignore"):
        q = node_values(p, pts.mu, pts.w, fixed)
        d, _, _ = ltc(pts.x, pts.y, pts.z, q[:, 0], q[:, 1])
        r = (q[:, 2] * d - pts.v) / (pts.v + bin_scale(pts.mu, pts.v))
    c = float(r @ r)
    return c if np.isfinite(c) else np.inf


def cosine_start():
    p = np.zeros((NODES, 3))
    p[:, 0], p[:, 2] = 1.0, 0.5
    return p


# --------------------------------------------------------------------------- scenes (bpy)

def _base_scene(width, height, ortho_scale, centre):
    import bpy
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.type, cam.data.ortho_scale = "ORTHO", ortho_scale
    cam.location, cam.rotation_euler = (centre[0], centre[1], 10.0), (0.0, 0.0, 0.0)
    cam.data.clip_end = 100.0
    scene.collection.objects.link(cam)
    scene.camera = cam
    world = bpy.data.worlds.new("World")
    scene.world = world
    from tests.blender_support import load_addon
    compat = load_addon().polar_addon.compat
    compat.ensure_node_tree(world)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    world.cycles.sampling_method = "NONE"
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device, c.samples = "CPU", 1
    c.use_adaptive_sampling = c.use_denoising = False
    c.pixel_filter_type, c.filter_width = "GAUSSIAN", 0.01        # a point: the sample is the pixel's centre
    c.use_light_tree = False
    c.light_sampling_threshold = 0.0
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = 0
    c.transparent_max_bounces = 0
    scene.render.threads_mode, scene.render.threads = "FIXED", 2
    scene.render.film_transparent = True
    scene.view_layers[0].use_pass_normal = True
    compat.set_multilayer_exr(scene.render.image_settings)
    return scene


def _material(name, kind, roughness):
    import bpy
    from tests.blender_support import load_addon
    mat = bpy.data.materials.new(name)
    load_addon().polar_addon.compat.ensure_node_tree(mat)
    tree = mat.node_tree
    for node in list(tree.nodes):
        if node.type != "OUTPUT_MATERIAL":
            tree.nodes.remove(node)
    out = tree.nodes[0]
    if kind == "diffuse":
        bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
    else:
        bsdf = tree.nodes.new("ShaderNodeBsdfSheen")
        bsdf.distribution = "MICROFIBER"
        bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def _patch(name, x0, y0, n, mat):
    """A flat unit square at (x0, y0) whose custom vertex normals span the view hemisphere."""
    import bpy
    u = np.linspace(0.0, 1.0, n + 1)
    U, Vv = np.meshgrid(u, u)
    mu = U.ravel()
    phi = 2 * np.pi * Vv.ravel()
    s = np.sqrt(np.maximum(1 - mu * mu, 0.0))
    normals = np.stack([s * np.cos(phi), s * np.sin(phi), mu], axis=1)
    verts = np.stack([x0 + U.ravel(), y0 + Vv.ravel(), np.zeros(mu.size)], axis=1)
    faces = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
             for j in range(n) for i in range(n)]
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts.tolist(), [], faces)
    me.shade_smooth()
    me.normals_split_custom_set_from_vertices(normals.tolist())
    me.materials.append(mat)
    ob = bpy.data.objects.new(name, me)
    ob.shadow_terminator_geometry_offset = 0.0
    bpy.context.scene.collection.objects.link(ob)
    return ob


def sun_directions(k):
    """k directions at angles γ from V = +z, uniform in cos γ (in the xz plane)."""
    c = 1 - 2 * (np.arange(k) + 0.5) / k
    return np.stack([np.sqrt(1 - c * c), np.zeros(k), c], axis=1)


def render_patches(roughnesses, suns, size, tmp, kind="sheen"):
    """Renders of the patch scene, one per sun: {values (K, H, W), normals (H, W, 3), index (H, W) (the patch
    of each pixel, −1: none), roughness (patches,), suns (K, 3), seconds}."""
    import bpy
    from mathutils import Vector
    from tests.blender_support import read_multilayer
    rows = -(-len(roughnesses) // COLUMNS)
    width, height = int(round(COLUMNS * PITCH * size)), int(round(rows * PITCH * size))
    scene = _base_scene(width, height, COLUMNS * PITCH, (COLUMNS * PITCH / 2 - 0.125, rows * PITCH / 2 - 0.125))
    for k, r in enumerate(roughnesses):
        col, row = k % COLUMNS, k // COLUMNS
        _patch(f"P{k}", col * PITCH, row * PITCH, 48, _material(f"M{k}", kind, r))
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.data.angle, sun.data.use_shadow = 1.0, 0.0, False
    scene.collection.objects.link(sun)
    scene.render.use_persistent_data = True
    values, normals, alpha = [], None, None
    t0 = time.perf_counter()
    for i, L in enumerate(suns):
        sun.rotation_euler = Vector(tuple(L)).to_track_quat("Z", "Y").to_euler()
        scene.render.filepath = os.path.join(tmp, f"patch_{i}")
        bpy.ops.render.render(write_still=True)
        passes = read_multilayer(scene.render.filepath + ".exr")
        values.append(passes["Combined"][..., :3].mean(axis=-1))
        if normals is None:
            normals, alpha = passes["Normal"][..., :3], passes["Combined"][..., 3]
    seconds = time.perf_counter() - t0
    H, W = alpha.shape                      # the patch under each pixel centre
    xs = (np.arange(W) + 0.5) / size - 0.125
    ys = rows * PITCH - 0.125 - (np.arange(H) + 0.5) / size
    index = np.floor(ys / PITCH).astype(int)[:, None] * COLUMNS + np.floor(xs / PITCH).astype(int)[None, :]
    index = np.where(alpha > 0.5, index, -1)
    return {"values": np.array(values, np.float32), "normals": normals.astype(np.float32), "index": index,
            "roughness": np.array(roughnesses), "suns": np.asarray(suns), "seconds": seconds}


def render_spheres(roughnesses, size, tmp):
    """E measurements: one render per roughness of a sphere under a white world seen only through BSDF
    samples; (values (K, H, W), normals (H, W, 3), mask (H, W), seconds)."""
    import bpy
    from tests.blender_support import read_multilayer
    scene = _base_scene(size, size, 2.1, (0.0, 0.0))
    background = scene.world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    background.inputs["Strength"].default_value = 1.0
    c = scene.cycles
    c.samples = 1           # one sample per pixel: its weight is E exactly, or 0 where Cycles rejects it
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = 1
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, segments=256, ring_count=128)
    obj = bpy.context.object
    obj.data.shade_smooth()
    mat = _material("S", "sheen", 0.5)
    obj.data.materials.append(mat)
    node = [n for n in mat.node_tree.nodes if n.type == "BSDF_SHEEN"][0]
    scene.render.use_persistent_data = True
    values, normals, alpha = [], None, None
    t0 = time.perf_counter()
    for i, r in enumerate(roughnesses):
        node.inputs["Roughness"].default_value = r
        scene.render.filepath = os.path.join(tmp, f"sphere_{i}")
        bpy.ops.render.render(write_still=True)
        passes = read_multilayer(scene.render.filepath + ".exr")
        values.append(passes["Combined"][..., :3].mean(axis=-1))
        if normals is None:
            normals, alpha = passes["Normal"][..., :3], passes["Combined"][..., 3]
    return np.array(values, np.float32), normals.astype(np.float32), alpha > 0.5, time.perf_counter() - t0



def node_roughnesses():
    """The fit renders' roughnesses: the nodes j/31 (row 0 rendered at 0, which Cycles clamps to 10⁻³)."""
    return [j / (NODES - 1) for j in range(NODES)]


def between_roughnesses():
    """Extra fit renders between the rows whose tables have empty nodes (r < 4/31): there the mix with the
    next row is the only witness of a row's lobe shape (a, b) at nodes where its E is 0."""
    return [(j + f) / (NODES - 1) for j in range(4) for f in (0.2, 0.4, 0.6, 0.8)] + [0.1 / (NODES - 1)]


def mid_roughnesses():
    """Validation renders: halfway between the nodes, and 1/4 of the first interval."""
    return [(j + 0.5) / (NODES - 1) for j in range(NODES - 1)] + [0.25 / (NODES - 1)]


def measure(path, size, suns):
    """Render everything and save the raw measurements to ``path``."""
    import bpy  # noqa: F401
    t0 = time.perf_counter()
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        L = sun_directions(suns)
        for key, rough, sun_set, px in (("node", node_roughnesses(), L, size),
                                        ("between", between_roughnesses(), sun_directions(suns + 1), size),
                                        # validation: other suns (in the yz plane), half the resolution
                                        ("mid", mid_roughnesses(), sun_directions(8)[:, [1, 0, 2]], size // 2)):
            r = render_patches(rough, sun_set, px, tmp)
            print(f"{key} renders: {len(sun_set)} suns × {len(rough)} patches of {px} px, {r['seconds']:.1f} s")
            out.update({f"{key}_{k}": v for k, v in r.items()})
        ev, en, emask, s3 = render_spheres(node_roughnesses() + mid_roughnesses(), 256, tmp)
        print(f"white-world sphere renders: {ev.shape[0]}, {s3:.1f} s")
        d = render_patches([0.0], L[:4], 32, tmp, kind="diffuse")
    total = time.perf_counter() - t0
    out.update(sphere_values=ev, sphere_normals=en, sphere_mask=emask, sphere_seconds=s3,
               diffuse_values=d["values"], diffuse_normals=d["normals"], diffuse_index=d["index"],
               diffuse_suns=d["suns"], total_seconds=total)
    np.savez_compressed(path, **out)
    print(f"measurements: {total:.1f} s in all -> {path}")


# --------------------------------------------------------------------------- fit and report

def patch_points(data, key, patch):
    """(μ, x, y, z, v) of every pixel of ``patch`` of render set ``key`` under every sun, lit side only."""
    values, index = data[f"{key}_values"], data[f"{key}_index"]
    sel = index == patch
    n = data[f"{key}_normals"][sel].astype(np.float64)
    out = [[] for _ in range(5)]
    for k, L in enumerate(data[f"{key}_suns"]):
        x, y, z, mu = local_light(n, np.asarray(L, np.float64))
        keep = z > 1e-4
        for o, a in zip(out, (mu, x, y, z, values[k][sel].astype(np.float64))):
            o.append(a[keep])
    return [np.concatenate(o) for o in out]


def row_points(data, j, between_points=600_000):
    """Points of every fit render whose closure reads row j: its node render (row 0: r = 10⁻³, mixed
    0.969 : 0.031 with row 1) and the renders between rows j and j + 1, with the row's weight w in the mix."""
    parts = []
    for key in ("node", "between"):
        for k, r in enumerate(data[f"{key}_roughness"]):
            j0, j1, tr = roughness_rows(float(r))
            if j0 == j and (j1 == j or j1 == j + 1) and (j1 == j or j == 0 or key == "between"):
                mu, x, y, z, v = patch_points(data, key, k)
                parts.append(Points(mu, x, y, z, v, np.full(v.size, 1.0 - tr)))
    pts = Points.concat(parts)
    between = np.nonzero(pts.w < 1 - 0.05)[0] if j > 0 else np.nonzero(pts.w < 0.95)[0]
    if between.size > between_points:       # a fixed random share of the renders between rows (fit time)
        drop = np.random.default_rng(j).choice(between, between.size - between_points, replace=False)
        keep = np.ones(pts.size, bool)
        keep[drop] = False
        pts = pts.take(keep)
    return pts


def lobe_errors(pred, mu, v):
    """Relative errors |pred − v|/v where v is above 1 % of the brightest value of its μ interval (the
    lobe's own scale at that view angle) and above 10⁻⁴ of the brightest overall, and the largest
    |pred − v| ÷ the brightest value overall."""
    i0, _, _ = interp_weights(mu)
    peak = np.zeros(NODES)
    np.maximum.at(peak, i0, v)
    big = (v > 0.01 * peak[i0]) & (v > 1e-4 * v.max())
    return np.abs(pred[big] - v[big]) / v[big], float(np.abs(pred - v).max() / v.max())


def _summary(rel):
    return f"{np.sqrt(np.mean(rel ** 2)):9.2e} / {rel.max():8.2e}"


def fit(data):
    """The table [i_mu, j_r, (a, b, E)], fitted row by row from r = 1 down (row j + 1 known when row j is
    fitted: the renders between them are mixes of the two)."""
    table = np.zeros((NODES, NODES, 3))
    print("row  r      points   live  empty nodes  lobe rel. err rms / max   max abs err ÷ peak")
    t0 = time.perf_counter()
    start = cosine_start()
    for j in range(NODES - 1, -1, -1):
        pts = row_points(data, j)
        fixed = table[:, j + 1] if j + 1 < NODES else None
        lit = pts.take(pts.v > 0)
        # E is free at the nodes nearest to a lit point of the row's own renders (for row 0: of all its
        # renders); beyond them Cycles skipped the closure (E < 1e-5), E = 0.  a and b are free wherever
        # a lit point depends on them.
        own = lit.take(lit.w >= lit.w.max() - 1e-9) if j > 0 else lit
        i0, i1, t = interp_weights(own.mu)
        live = np.zeros(NODES, bool)
        live[np.where(t < 0.5, i0, i1)] = True
        i0, i1, t = interp_weights(lit.mu)
        shape = np.zeros(NODES, bool)
        shape[i0[t < 0.99]] = shape[i1[t > 0.01]] = True
        # two starts, the better fit kept: the row above, and each node fitted alone to its nearest points
        p = min((fit_row(lit, s, live, shape, fixed) for s in (start, local_start(lit, start, live, fixed))),
                key=lambda q: row_cost(q, lit, fixed))
        # a point lit at a node proves E ≥ 1e-5 there (Cycles' cut-off): a node fitted just below it
        # (within 10 %) is put on it
        cut = CUTOFF * (1 + 1e-6)
        near = live & (p[:, 2] < cut) & (p[:, 2] > 0.9 * cut)
        p[near, 2] = cut
        table[:, j] = p
        pred = shade(node_values(p, pts.mu, pts.w, fixed), pts.x, pts.y, pts.z)
        on = pts.v > 0
        rel, ab = lobe_errors(pred[on], pts.mu[on], pts.v[on])
        mismatch = int(np.sum((pred > 0) != on))
        print(f"{j:3d}  {j / (NODES - 1):.3f}  {pts.size:8d}  {on.mean():5.3f}  {int((~live).sum()):3d}          "
              f"{_summary(rel)}      {ab:.1e}  (zero/non-zero mismatches: {mismatch})")
        start = p.copy()
        if shape.any():         # nodes without data start the next row from the last one with data
            start[~shape] = p[np.nonzero(shape)[0][-1]]
    print(f"fit: {time.perf_counter() - t0:.1f} s")
    return table


def report(table, data):
    print("\nvalidation (the table as saved, float32)")
    for label, key in (("fit renders", "node"), ("renders between rows 0–4", "between"),
                       ("mid-node roughness, other suns", "mid")):
        rels, mismatch, count, worst = [], 0, 0, 0.0
        for k, r in enumerate(data[f"{key}_roughness"]):
            mu, x, y, z, v = patch_points(data, key, k)
            pred = evaluate(table, mu, x, y, z, float(r))
            live = v > 0
            mismatch += int(np.sum((pred > 0) != live))
            count += v.size
            if live.any():
                rel, ab = lobe_errors(pred[live], mu[live], v[live])
                rels.append(rel)
                worst = max(worst, ab)
        rel = np.concatenate(rels)
        print(f"  lobe E·D, {label}: rel. err rms {np.sqrt(np.mean(rel ** 2)):.2e}, max {rel.max():.2e} "
              f"({rel.size} of {count} points); max abs err ÷ peak {worst:.1e}; "
              f"zero/non-zero mismatches {mismatch}")
    ev, en, emask = data["sphere_values"], data["sphere_normals"], data["sphere_mask"]
    n = en[emask].astype(np.float64)
    mu = n[:, 2] / np.linalg.norm(n, axis=1)
    errs, small, rejected, covered, mismatch, mismatch_max = [], 0.0, 0, 0, 0, 0.0
    for k, r in enumerate(node_roughnesses() + mid_roughnesses()):
        j0, j1, tr = roughness_rows(r)
        q = node_values((1 - tr) * table[:, j0] + tr * table[:, j1], mu)
        e = np.where((np.abs(q[:, 0]) < CUTOFF) | (q[:, 2] < CUTOFF), 0.0, q[:, 2])
        meas = ev[k][emask].astype(np.float64)
        both = (meas > 0) & (e > 0)
        big = both & (meas >= 1e-3)
        errs.append(np.abs(e[big] - meas[big]) / meas[big])
        small = max(small, float(np.abs(e - meas)[both & ~big].max(initial=0.0)))
        rejected += int(np.sum((meas == 0) & (e > 0)))
        lit = (meas > 0) & (e == 0)
        mismatch += int(lit.sum())
        mismatch_max = max(mismatch_max, float(meas[lit].max(initial=0.0)))
        covered += int(np.sum(e > 0))
    rel = np.concatenate(errs)
    print(f"  albedo E (white-world spheres, 1 sample per pixel): where E ≥ 10⁻³ rel. err rms "
          f"{np.sqrt(np.mean(rel ** 2)):.2e}, max {rel.max():.2e} ({rel.size} pixels); below, max abs err "
          f"{small:.1e}; samples rejected below the facets {rejected / max(covered, 1):.1e}; lit where the "
          f"table's E < 1e-5: {mismatch} pixels, E ≤ {mismatch_max:.2e}")
    dv, dn, di = data["diffuse_values"], data["diffuse_normals"], data["diffuse_index"]
    n = dn[di == 0].astype(np.float64)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    worst = 0.0
    for k, L in enumerate(data["diffuse_suns"]):
        c = n @ L
        lit = c > 0.05
        worst = max(worst, float(np.max(np.abs(dv[k][di == 0][lit] - c[lit] / np.pi) / (c[lit] / np.pi))))
    print(f"  normalisation (Diffuse BSDF patch = strength · cosθ_i/π): max rel. err {worst:.1e}")
    print(f"  render time: fit {data['node_seconds']:.1f} s + {data['between_seconds']:.1f} s, validation "
          f"{data['mid_seconds']:.1f} s + spheres {data['sphere_seconds']:.1f} s; measurement in all "
          f"{data['total_seconds']:.1f} s")


def save(table, path):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    nodes = np.arange(NODES) / (NODES - 1)
    np.savez_compressed(path, a=table[:, :, 0].astype(np.float32), b=table[:, :, 1].astype(np.float32),
                        albedo=table[:, :, 2].astype(np.float32), mu=nodes.astype(np.float32),
                        roughness=nodes.astype(np.float32))
    print(f"table -> {path}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--measurements", default=os.path.join(tempfile.gettempdir(), "polar_sheen_measurements.npz"),
                    help="raw renders (reused if present, unless --remeasure)")
    ap.add_argument("--remeasure", action="store_true")
    ap.add_argument("--out", default=OUT)
    ap.add_argument("--size", type=int, default=128, help="pixels per patch side")
    ap.add_argument("--suns", type=int, default=64)
    args = ap.parse_args(argv)
    if args.remeasure or not os.path.exists(args.measurements):
        measure(args.measurements, args.size, args.suns)
    data = dict(np.load(args.measurements))
    table = fit(data)
    save(table, args.out)
    report(table.astype(np.float32).astype(np.float64), data)


if __name__ == "__main__":
    main()
