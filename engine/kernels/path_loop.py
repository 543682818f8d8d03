"""A compiled per-path bounce loop for scenes of delta-only materials under a constant environment.

The wavefront tracer (engine.render.integrator.PathTracer) runs each bounce of a whole batch as named
stages over (P, P, L, n) arrays, with Python between compiled steps.  Where every material is a smooth
mirror or a smooth dielectric and the only light is a constant environment, a path needs none of that
machinery: :func:`trace_delta_paths` traces the batch in chunks of CHUNK paths whose state stays in small,
cache-resident buffers, every bounce of a chunk in one pass — closest hits of its live paths by Embree's
``rtcIntersect16`` in packets of 16 (engine.kernels.rays), then per path the hit point
(engine.kernels.geometry.surface_at), the material's step (engine.kernels.delta_bounce: conductor, black
glass, measured metal, dielectric; the mirrors' Fresnel values over the chunk's mirror vertices at once),
the throughput update, Russian roulette (engine.kernels.transport) and, where the path leaves the scene, the
environment's light into its radiance — until every path of the chunk escaped, ended or reached ``max_depth``.

Every step is the wavefront's arithmetic in the wavefront's order, read from the same helpers, and every
random number is the one the wavefront draws for that (pixel, sample, dimension, seed) (the samplers
"independent", "stratified" and "sobol": engine.render.sampler), so the radiance is the wavefront's bit for
bit.  The wavefront is this kernel's twin (engine.render.path_loop says which scenes it covers); there is no
NumPy version of it: without Numba the wavefront runs.
"""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner
from .delta_bounce import (_CHUNK, _chunk_buffers, _chunk_fresnel, _fresnel_buffers, _update_chunk,
                           constant_mirror_at, dielectric_at, tabulated_mirror_at)
from .geometry import offset_origin_at, surface_at
from .hashing import sobol_pair_at, uniform_at
from .rays import _ray_setup, _read_hit
from .sobol import owen_pair_at, owen_path_at
from .transport import is_black, roulette_probability

#: The loop's material kinds (engine.render.path_loop.DeltaScene.kind, per material index)
CONSTANT_MIRROR, MEASURED_MIRROR, DIELECTRIC = 1, 2, 3
#: The samplers the loop draws (RenderSettings.sampler): their numbers per vertex
INDEPENDENT, STRATIFIED, SOBOL = 0, 1, 2
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


#: Paths traced together (the delta steps' chunk: their scratch buffers hold one value per path)
CHUNK = _CHUNK


@jit_inner
def _start_chunk(c0, m, o0, d0, x_T0, lam, Le, t_max0, has_t, pixel, sample, s, T, rad, o, d, x_T, lam_c, Le_c, t_c,
                 eta_sq, base, rev, live):
    """The chunk's paths c0 … c0 + m − 1 at the camera: T = identity, no light yet, their columns of the batch's
    arrays copied in a row at a time (reading a path's column directly touches rows n·8 bytes apart, which share
    cache sets), their Sobol' keys, all live."""
    P, Lm = T.shape[0], T.shape[2]
    for a in range(P):
        for b in range(P):
            for k in range(Lm):
                one = 1.0 if a == b else 0.0
                for j in range(m):
                    T[a, b, k, j] = one
        for k in range(Le.shape[0]):
            for j in range(m):
                rad[a, k, j] = 0.0
    for c in range(3):
        for j in range(m):
            o[c, j] = o0[c, c0 + j]
        for j in range(m):
            d[c, j] = d0[c, c0 + j]
        for j in range(m):
            x_T[c, j] = x_T0[c, c0 + j]
    for q in range(Lm):
        for j in range(m):
            lam_c[q, j] = lam[q, c0 + j]
    for k in range(Le.shape[0]):
        for j in range(m):
            Le_c[k, j] = Le[k, c0 + j]
    for j in range(m):
        t_c[j] = t_max0[c0 + j] if has_t else 0.0
        eta_sq[j] = 1.0
        base[j], rev[j] = owen_path_at(s, pixel[c0 + j], sample[c0 + j])
        live[j] = j


@jit_inner
def _closest_hits(query, scene, rh, ri, valid16, addr, vaddr, aaddr, live, count, o, d, t_c, has_t, no_prims, prim, u,
                  v, t):
    """Closest hits of the live paths' segments, 16 at a time (engine.kernels.rays.packet_queries' set-up and
    reading)."""
    for k0 in range(0, count, 16):
        w16 = min(16, count - k0)
        for k in range(16):
            valid16[k] = -1 if k < w16 else 0
            if k < w16:
                _ray_setup(rh, ri, 16, k, o, d, t_c, has_t, live[k0 + k])
        query(vaddr, scene, addr, aaddr)
        for k in range(w16):
            _read_hit(rh, ri, 16, k, live[k0 + k], no_prims, False, prim, u, v, t)


@jit_inner
def _hit_points(live, count, prim, u, v, faces, V, N, has_vn, tri_normal, any_vn, tri_material, two_sided, d, wo, p,
                n_g, n_s):
    """The live paths' hit points, geometric and shading normals (a two-sided material's back face: the shading
    normal flipped, PathTracer._back_faces) and wo = −d, where they hit."""
    for a in range(count):
        j = live[a]
        tri = prim[j]
        if tri < 0:
            continue
        for c in range(3):
            wo[c, j] = -d[c, j]
        surface_at(faces, V, N, has_vn, tri_normal, any_vn, tri, u[j], v[j], j, p, n_g, n_s)
        flip = two_sided[tri_material[tri]] and (n_g[0, j] * wo[0, j] + n_g[1, j] * wo[1, j]) + n_g[2, j] * wo[2, j] < 0
        for c in range(3):
            ns = n_s[c, j] if any_vn else n_g[c, j]
            n_s[c, j] = -ns if flip else ns


@jit_inner
def _survivors(rows, nr, Tn, eta_step, scaled, mat_of, eta_sq, valid, roulette, u_rr, p, n_g, d, epsilon, o, x_T,
               x_out, live_next, count):
    """The paths ``rows[:nr]`` after their vertex: the 1/η² taken back where the material is not ``scaled`` (Cycles'
    convention), η² ← η²·step, Russian roulette, non-finite and black paths (transport._roulette_loop's arithmetic,
    Tn divided in place); the survivors' next origins and frames, appended to ``live_next`` from ``count``.
    Returns (live paths, non-finite paths)."""
    P, Lm = Tn.shape[0], Tn.shape[2]
    nonfinite = 0
    for r in range(nr):
        j = rows[r]
        step = eta_step[j]
        if not scaled[mat_of[j]]:
            for a in range(P):
                for b in range(P):
                    for k in range(Lm):
                        Tn[a, b, k, j] *= step
            step = 1.0
        eta_sq[j] = eta_sq[j] * step
        ok = valid[j]
        scale = 1.0
        if roulette:
            q = roulette_probability(Tn, j, eta_sq[j])
            if u_rr[j] < q:
                scale = q
            else:
                ok = False
        finite = True
        for a in range(P):
            for b in range(P):
                for k in range(Lm):
                    x = Tn[a, b, k, j]
                    if roulette:
                        x = x / scale
                        Tn[a, b, k, j] = x
                    if not np.isfinite(x):
                        finite = False
        if ok and not finite:
            nonfinite += 1
        if not ok or not finite or is_black(Tn, j):
            continue
        offset_origin_at(p, n_g, d, epsilon, j, o)
        for c in range(3):
            x_T[c, j] = x_out[c, j]
        live_next[count] = j
        count += 1
    return count, nonfinite


@jit_inner
def _vertex_numbers(sampler, bounce, lobe, roulette, base, rev, key, dims, pix, smp, s, choice_vx, choice_vy,
                    choice_key, owen_table):
    """(lobe number, roulette number) of a path's vertex ``bounce`` (each only where asked; PathTracer._vertex_numbers
    and _sobol_vertex_numbers: the first vertex's hashed dimensions ``dims`` + 5 and + 8, the lobe stratified by the
    (light choice, lobe) pair; deeper "sobol" vertices their SOBOL_CHOICES and SOBOL_ROULETTE pairs)."""
    u_lobe = u_rr = 0.0
    pairs = sampler == SOBOL and bounce > 0
    if roulette:
        if pairs:
            u_rr, _ = owen_pair_at(base, rev, np.int64(4 * (bounce - 1) + 3), True, owen_table)
        else:
            u_rr = uniform_at(key, np.uint64(dims + 8) * _GOLDEN)
    if lobe and pairs:
        _, u_lobe = owen_pair_at(base, rev, np.int64(4 * (bounce - 1) + 2), True, owen_table)
    elif lobe:
        u_lobe = uniform_at(key, np.uint64(dims + 5) * _GOLDEN)
        if bounce == 0 and sampler != INDEPENDENT:
            _, u_lobe = sobol_pair_at(s, choice_key, pix, smp, choice_vx, choice_vy, u_lobe, u_lobe)
    return u_lobe, u_rr


@jit
def trace_delta_paths(query, scene, valid16, rh, args, o0, d0, t_max0, has_t, x_T0, lam, keys, pixel, sample,
                      faces, V, N, has_vn, tri_normal, any_vn, tri_material,
                      kind, eta_c, eta_front, eta_back, scaling, two_sided,
                      wl_n, tab_n, wl_k, tab_k, tab_scale, tab_shared, tab_first, tab_hints,
                      env_on, Le, P, max_depth, rr_depth, epsilon,
                      sampler, seed_key, k_camera, choice_vx, choice_vy, choice_key, owen_table,
                      radiance, cost, vertex_cost):
    """Trace the paths of camera rays o0, d0 (3, n) (lengths t_max0 where ``has_t``; frames x_T0 (3, n);
    wavelengths ``lam`` (Lm, n) as the materials see them; sampler ``keys``, ``pixel``, ``sample`` (n,)) and add
    their light into ``radiance`` (P, L, n) (zeroed) and each surface hit's ``vertex_cost`` into ``cost`` (n,;
    empty: not counted).  Returns (closest-hit rays cast, paths ended for a non-finite throughput).

    Embree: ``query`` (rtcIntersect16's ctypes pointer), ``scene`` (the RTCScene), ``valid16`` (int32 (16,)),
    ``rh`` (float32 RTCRayHit16) and ``args`` (RTCIntersectArguments), as engine.kernels.rays.packet_queries
    takes them.  Geometry: engine.kernels.geometry.surface_attributes' arrays and the triangles' materials.
    Materials (by index, engine.render.path_loop.DeltaScene): ``kind`` (CONSTANT_MIRROR, MEASURED_MIRROR,
    DIELECTRIC), the mirror's complex index ``eta_c``, the dielectric's relative indices ``eta_front``/``eta_back``,
    ``scaling`` (BSDF.radiance_scaling), ``two_sided``; the measured metal's tables (one: engine.kernels.
    delta_bounce.tabulated_mirror_loop's arguments).  Light: ``env_on`` and its radiance ``Le`` (L, n) per path.
    Numbers: ``sampler`` (INDEPENDENT, STRATIFIED, SOBOL), the mixed seed ``seed_key`` (uint64 (1,)), the camera's
    dimensions ``k_camera`` (the hashed dimensions before the first vertex's), the first vertex's stratified
    (light choice, lobe) pair (direction numbers ``choice_vx``, ``choice_vy``, key ``choice_key``) and the Sobol'
    pairs' table (engine.kernels.sobol.SOBOL2_REVERSED).
    """
    n = o0.shape[1]
    Lm = lam.shape[0]
    L = radiance.shape[1]
    C = CHUNK
    ri = rh.view(np.uint32)
    addr, vaddr, aaddr = rh.ctypes.data, valid16.ctypes.data, args.ctypes.data
    no_prims = np.empty(0, np.int64)
    # the chunk's paths: throughput before and after the vertex, segments, frames, hits (a column per path)
    T, Tn = np.empty((P, P, Lm, C)), np.empty((P, P, Lm, C))
    o, d, wo, x_T, x_out = np.empty((3, C)), np.empty((3, C)), np.empty((3, C)), np.empty((3, C)), np.empty((3, C))
    p, n_g, n_s, lamC = np.empty((3, C)), np.empty((3, C)), np.empty((3, C)), np.empty((Lm, C))
    t_c, Le_c, rad = np.empty(C), np.empty((L, C)), np.empty((P, L, C))
    prim, u, v, t = np.empty(C, np.int64), np.empty(C), np.empty(C), np.empty(C)
    valid, eta_step, eta_sq, u_rr = np.empty(C, np.bool_), np.empty(C), np.empty(C), np.empty(C)
    base, rev = np.empty(C, np.uint64), np.empty(C, np.uint64)
    live, live_next, mat_of = np.empty(C, np.int64), np.empty(C, np.int64), np.empty(C, np.int64)
    # the bounce's vertices by step: constant mirrors, measured mirrors, dielectrics (each its lanes' buffers)
    rows_c, rows_m, rows_d = np.empty(C, np.int64), np.empty(C, np.int64), np.empty(C, np.int64)
    abcs_c, rot_c = _chunk_buffers(1)
    abcs_m, rot_m = _chunk_buffers(Lm)
    abcs_d, rot_d = _chunk_buffers(1)
    cos_c, w_c, e_c, fast = _fresnel_buffers(1)
    cos_m, w_m, e_m, _ = _fresnel_buffers(Lm)
    s = seed_key[0]
    rays = 0
    nonfinite = 0
    for c0 in range(0, n, C):
        m = min(C, n - c0)
        _start_chunk(c0, m, o0, d0, x_T0, lam, Le, t_max0, has_t, pixel, sample, s, T, rad, o, d, x_T, lamC, Le_c,
                     t_c, eta_sq, base, rev, live)
        count = m
        for bounce in range(max_depth):
            if count == 0:
                break
            _closest_hits(query, scene, rh, ri, valid16, addr, vaddr, aaddr, live, count, o, d, t_c,
                          has_t and bounce == 0, no_prims, prim, u, v, t)
            rays += count
            roulette = bounce + 1 >= rr_depth
            _hit_points(live, count, prim, u, v, faces, V, N, has_vn, tri_normal, any_vn, tri_material, two_sided, d,
                        wo, p, n_g, n_s)
            nc = nm = nd = 0
            complex_c = False       # some constant mirror of a complex index (else abcs_at alone: black glass)
            for a in range(count):
                j = live[a]
                i = c0 + j
                tri = prim[j]
                if tri < 0:
                    if env_on:      # the environment's light (MIS weight 1: every vertex is delta): add_light's
                        for b in range(P):
                            for k in range(L):
                                rad[b, k, j] += T[b, 0, min(k, Lm - 1), j] * (Le_c[k, j] * 1.0)
                    continue
                if cost.shape[0] > 0:
                    cost[i] += vertex_cost
                if bounce + 1 >= max_depth:
                    continue
                mat = mat_of[j] = tri_material[tri]
                # the vertex's numbers: the lobe (dielectrics only) and the roulette's
                kd = kind[mat]
                u_lobe = 0.0
                if kd == DIELECTRIC or roulette:
                    u_lobe, u_rr[j] = _vertex_numbers(sampler, bounce, kd == DIELECTRIC, roulette, base[j], rev[j],
                                                      keys[i], k_camera + 8 * bounce, pixel[i], sample[i], s,
                                                      choice_vx, choice_vy, choice_key, owen_table)
                # the material's step (engine.kernels.delta_bounce), its lanes in the step's buffers
                if kd == DIELECTRIC:
                    dielectric_at(j, nd, n_s, wo, x_T, P, u_lobe, eta_front[mat], eta_back[mat], d, x_out, valid,
                                  eta_step, abcs_d, rot_d)
                    rows_d[nd] = j
                    nd += 1
                elif kd == CONSTANT_MIRROR:
                    constant_mirror_at(j, nc, n_s, wo, x_T, P, d, x_out, valid, eta_step, cos_c, w_c, rot_c)
                    e_c[0, 0, nc] = eta_c[mat].real
                    e_c[0, 1, nc] = eta_c[mat].imag
                    complex_c = complex_c or eta_c[mat].imag != 0.0
                    rows_c[nc] = j
                    nc += 1
                else:
                    tabulated_mirror_at(j, nm, n_s, wo, x_T, P, lamC, wl_n, tab_n, wl_k, tab_k, tab_scale,
                                        tab_shared, tab_first, tab_hints, d, x_out, valid, eta_step, cos_m, w_m, e_m,
                                        rot_m)
                    rows_m[nm] = j
                    nm += 1
            # the Fresnel values of the mirrors' vertices, a wavelength at a time (SIMD), and the throughputs
            if nc > 0:
                _chunk_fresnel(cos_c, w_c, e_c, nc, abcs_c, fast, complex_c)
                _update_chunk(T, rows_c, Tn, rows_c, 0, nc, abcs_c, rot_c)
            if nm > 0:
                _chunk_fresnel(cos_m, w_m, e_m, nm, abcs_m, fast, True)
                _update_chunk(T, rows_m, Tn, rows_m, 0, nm, abcs_m, rot_m)
            if nd > 0:
                _update_chunk(T, rows_d, Tn, rows_d, 0, nd, abcs_d, rot_d)
            # roulette, non-finite and black paths (transport._roulette_loop's arithmetic); the survivors go on
            count = 0
            for rows, nr in ((rows_c, nc), (rows_m, nm), (rows_d, nd)):
                count, bad = _survivors(rows, nr, Tn, eta_step, scaling, mat_of, eta_sq, valid, roulette, u_rr, p, n_g,
                                        d, epsilon, o, x_T, x_out, live_next, count)
                nonfinite += bad
            T, Tn = Tn, T
            live, live_next = live_next, live
        for b in range(P):
            for k in range(L):
                radiance[b, k, c0:c0 + m] = rad[b, k, :m]
    return rays, nonfinite
