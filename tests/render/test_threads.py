"""Work units on worker threads: film sums computed per unit, added in order, and the scheduling.

The film's sums must be the same numbers as adding every unit's samples over the whole film in
unit order (the image does not depend on the number of threads or on where the sums are made)."""

import threading
import time

import numpy as np

from engine.render.film import Film, SampleSums
from engine.render.driver import trace_in_order
from engine.spectral.cie import LUMINANCE_WEIGHTS


def whole_film_sums(film, pixel, values, alpha=None, denoise=None):
    """The reference: bincounts over the whole film, added in place (the former Film.add_samples)."""
    n = film.count.shape[0]
    if alpha is not None or film.alpha_sums is not None:
        if film.alpha_sums is None:
            film.alpha_sums = film.count.astype(np.float64)
        w = np.ones(pixel.shape[0]) if alpha is None else alpha
        film.alpha_sums += np.bincount(pixel, weights=w, minlength=n)
    for s in range(4):
        for c in range(3):
            film.sums[s, c] += np.bincount(pixel, weights=values[s, c], minlength=n)
    y = np.einsum("c,scn->sn", LUMINANCE_WEIGHTS, values)
    for s in range(4):
        film.sumsq_y[s] += np.bincount(pixel, weights=y[s] * y[s], minlength=n)
    film.count += np.bincount(pixel, minlength=n)
    if denoise is not None:
        if film.denoise_sums is None:
            film.denoise_sums = np.zeros((6, n))
        for i, v in enumerate((*denoise[0], *denoise[1])):
            film.denoise_sums[i] += np.bincount(pixel, weights=v, minlength=n)


def test_unit_sums_added_in_order_equal_whole_film_sums_bitwise():
    rng = np.random.default_rng(3)
    W, H = 13, 11
    ref, film = Film(W, H), Film(W, H)
    # a resumed film may hold −0.0 (float32 means that underflowed): adding turns it into +0.0
    for f in (ref, film):
        f.sums[1, 0, 5] = -0.0
    for k in range(6):
        r0, r1 = sorted(rng.choice(H + 1, 2, replace=False))
        pix = (np.arange(r0, r1)[:, None] * W + np.arange(2, W)[None, :]).ravel()
        pixel = np.tile(pix, 3)[rng.random(3 * pix.size) < 0.8]         # some samples already done
        values = rng.normal(size=(4, 3, pixel.size)) * 10.0 ** rng.integers(-8, 8, pixel.size)
        alpha = rng.random(pixel.size) if k in (2, 4) else None
        denoise = (rng.random((3, pixel.size)), rng.normal(size=(3, pixel.size))) if k >= 3 else None
        whole_film_sums(ref, pixel, values, alpha, denoise)
        part = SampleSums.of(pixel, values, alpha, denoise)
        assert part.n_samples == pixel.size and part.sums.shape[-1] == part.hi - part.lo
        film.add(part)
    for name in ("sums", "sumsq_y", "count", "alpha_sums", "denoise_sums"):
        assert getattr(film, name).tobytes() == getattr(ref, name).tobytes(), name
    empty = SampleSums.of(np.zeros(0, np.int64), np.zeros((4, 3, 0)))
    film.add(empty)
    assert film.sums.tobytes() == ref.sums.tobytes()


def test_units_are_added_in_order_while_workers_run_ahead():
    # unit k sleeps longer the earlier it is: they finish out of order, are added in order, and
    # with one unit queued per worker a finished worker starts the next unit before this thread
    # has added the previous one (at most 2 units per worker submitted at once)
    added, running, most = [], [0], [0]
    lock = threading.Lock()

    def trace(k):
        with lock:
            running[0] += 1
            most[0] = max(most[0], running[0])
        time.sleep(0.002 * (8 - k))
        with lock:
            running[0] -= 1
        return k

    def add(k):
        added.append(k)

    stopped = trace_in_order(list(range(8)), trace, add, 2, lambda: False, threading.Event())
    assert not stopped and added == list(range(8)) and most[0] <= 2


def test_a_stop_discards_queued_units_without_tracing_them():
    traced, polls = [], {"n": 0}
    release = threading.Event()

    def trace(k):
        traced.append(k)
        release.wait(2.0)
        return k

    def stop():
        polls["n"] += 1
        if polls["n"] > 3:              # the first units are submitted, then the stop comes
            release.set()
            return True
        return False

    abort = threading.Event()
    added = []
    assert trace_in_order(list(range(10)), trace, added.append, 1, stop, abort)
    assert abort.is_set() and len(traced) == 1 and added == [0]


def test_workers_run_with_one_blas_thread_and_the_limit_is_restored_after():
    threadpoolctl = __import__("pytest").importorskip("threadpoolctl")

    def blas_threads():
        return [p["num_threads"] for p in threadpoolctl.threadpool_info() if p["user_api"] == "blas"]

    before = blas_threads()
    if not before:
        __import__("pytest").skip("NumPy has no BLAS library threadpoolctl can see")
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        seen = []
        trace_in_order(list(range(4)), lambda u: blas_threads(), seen.append, 2, lambda: False,
                       threading.Event())
        assert seen and all(n == [1] * len(before) for n in seen)
        assert blas_threads() == [2] * len(before)          # the caller's own setting comes back
    assert blas_threads() == before


def test_a_unit_finished_after_an_ended_one_is_not_added():
    """Only a prefix of the units reaches the film: unit 2 finishes while unit 1 (on the other worker)
    is ended by the stop, so 2 must go too, or the film would hold passes 0 and 2 of a pixel and count
    them as 0 and 1 (a resume then traced pass 2 twice and pass 1 never: found in CI under load)."""
    done2 = threading.Event()

    def trace(k, abort):
        if k == 1:
            abort.wait(10.0)
            return None                 # ended between two bounces, as PathTracer.trace does
        if k == 2:
            done2.set()
        return k

    abort = threading.Event()
    added = []
    assert trace_in_order(list(range(4)), lambda k: trace(k, abort), added.append, 2, done2.is_set, abort)
    assert added == [0]


def test_threads_not_set_one_worker_where_many_materials_are_shaded_by_python_calls(tmp_path):
    """The thread policy (driver.local_workers): with threads 0, a scene whose used materials are shaded by
    CONVOY_MATERIALS or more separate calls per bounce (two threads convoy on the GIL) gets one worker, a scene of
    Lambert materials (one LambertSet), of smooth (delta-only) materials or of fewer others one per core; set threads
    are kept; the image is the same with one worker as with two (added in the same order); an automatic choice is
    reported in the stats."""
    import dataclasses
    import os

    from engine.render.driver import CONVOY_MATERIALS
    from engine.render.renderer import Renderer
    from engine.scene.loader import parse_scene

    def scene(materials):
        names = list(materials)
        objects = [{"shape": "quad", "material": name,
                    "vertices": [[k - 2.0, -1, 0], [k - 1.0, -1, 0], [k - 1.0, 1, 0], [k - 2.0, 1, 0]]}
                   for k, name in enumerate(names)]
        return parse_scene({"format": "polar-scene/1",
                            "camera": {"origin": [0, -4, 3], "target": [0, 0, 0], "up": [0, 0, 1], "width": 12,
                                       "height": 8, "fov_deg": 50},
                            "render": {"spp": 2, "max_depth": 3}, "materials": materials, "objects": objects,
                            "lights": [{"type": "point", "position": [0, 0, 2], "intensity": 10}]}, str(tmp_path))
    cores = os.cpu_count() or 1
    metals = {f"m{k}": {"type": "principled", "base_color": [0.8, 0.5, 0.2], "metallic": 1.0, "roughness": 0.2 + k / 10}
              for k in range(CONVOY_MATERIALS)}
    lamberts = {f"d{k}": {"type": "lambert", "albedo": 0.2 + k / 10} for k in range(4)}
    many = Renderer(scene(metals))
    assert many.plan().workers == 1
    assert "contend" in many.plan().stats()["threads_reason"]          # reported (the stats line shows it)
    assert "threads_reason" not in many.plan(dataclasses.replace(many.scene.settings, threads=2)).stats()
    assert many.plan(dataclasses.replace(many.scene.settings, threads=2)).workers == 2
    assert Renderer(scene(lamberts)).plan().workers == cores
    fewer = dict(list(metals.items())[:CONVOY_MATERIALS - 1], **lamberts)
    assert Renderer(scene(fewer)).plan().workers == cores
    # smooth glasses and mirrors: a few calls around compiled steps, no light sampling; they do not count
    glasses = {f"g{k}": {"type": "dielectric", "n": 1.3 + k / 10} for k in range(CONVOY_MATERIALS + 2)}
    glasses.update({f"c{k}": {"type": "conductor", "n": 0.2 + k / 10, "k": 3.0} for k in range(CONVOY_MATERIALS)})
    assert Renderer(scene(dict(list(metals.items())[:CONVOY_MATERIALS - 1], **glasses))).plan().workers == cores
    one = many.render().stokes()
    two = many.render(dataclasses.replace(many.scene.settings, threads=2)).stokes()
    assert one.max() > 0
    np.testing.assert_array_equal(one, two)


def test_the_blas_libraries_are_looked_up_once_per_process(monkeypatch):
    """one_blas_thread finds the process's BLAS pools once (reading the memory map costs 2.4 ms a render in
    Blender), then sets and restores the limit through that controller at every render."""
    pytest = __import__("pytest")
    pytest.importorskip("threadpoolctl")
    from engine.render import blas_threads
    made = []
    real = blas_threads.ThreadpoolController

    def counted():
        made.append(1)
        return real()
    monkeypatch.setattr(blas_threads, "ThreadpoolController", counted)
    monkeypatch.setattr(blas_threads, "_controller", None)
    for _ in range(3):
        with blas_threads.one_blas_thread():
            pass
    assert made == [1]
