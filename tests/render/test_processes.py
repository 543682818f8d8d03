"""Local worker processes (engine.render.processes): the image is bit-for-bit the threaded render's; stops, dead
workers and a pool that cannot start; the setting and the automatic choice."""

import dataclasses
import os
import sys
import tempfile

import pytest

from engine.errors import SceneError
from engine.render import processes
from engine.render.adaptive import AdaptiveSettings
from engine.render.driver import BandJob
from engine.render.renderer import Renderer, RenderRequest
from engine.scene.loader import load_scene, parse_scene, parse_settings
from tests.conftest import shared_path

pytestmark = [pytest.mark.subprocess]


@pytest.fixture(scope="module", autouse=True)
def fresh_pool():
    processes.close_pool()
    yield
    processes.close_pool()


def peer(name="fresnel_sphere", res=32, spp=6):
    s = load_scene(shared_path("peers", "scenes", f"{name}.json"))
    s.camera.width = s.camera.height = res
    s.settings = dataclasses.replace(s.settings, spp=spp, batch_rays=res * res)     # one pass a unit: many units
    return s


@pytest.fixture(scope="module")
def many_materials():
    """The precompile cases' scene of every plain material (Principled ones hold lambdas: sent by their code)."""
    from engine.render import precompile
    folder = tempfile.mkdtemp(prefix="polar-test-processes-")
    sc = parse_scene(precompile.scenes(folder)["plain"], base_dir=folder, source="plain")
    sc.settings = dataclasses.replace(sc.settings, spp=4, batch_rays=48 * 8)
    return sc


def render(renderer, mode, settings=None, **request):
    st = dataclasses.replace(settings or renderer.scene.settings, parallel=mode)
    return renderer.render(RenderRequest(st, **request))


def same(a, b):
    for name in ("sums", "sumsq_y", "count", "half_y"):
        x, y = getattr(a.film, name), getattr(b.film, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert x.tobytes() == y.tobytes(), name


def children() -> set:
    """Process ids of this process's live children (Linux)."""
    out = set()
    for task in os.listdir(f"/proc/{os.getpid()}/task"):
        try:
            with open(f"/proc/{os.getpid()}/task/{task}/children") as f:
                out |= {int(p) for p in f.read().split()}
        except OSError:
            pass
    return out


def test_processes_give_the_threaded_image_uniform_and_seed_after_seed(many_materials):
    r = Renderer(many_materials)
    for seed in (0, 1):        # a second render's job (its seed) reaches the workers
        st = dataclasses.replace(many_materials.settings, seed=seed)
        threads, procs = render(r, "threads", st), render(r, "processes", st)
        same(procs, threads)
    assert procs.stats["parallel"] == "processes" and "2 processes" in procs.stats_line() or os.cpu_count() == 1
    assert processes.pool_running() >= 2
    # auto with the pool running: processes where the materials convoy (this scene), threads where not
    auto = render(r, "auto", st)
    same(auto, threads)
    assert auto.stats.get("parallel") == "processes" and "processes (automatic: " in auto.stats_line() \
        or os.cpu_count() == 1
    assert render(Renderer(peer(res=8, spp=1)), "auto").stats.get("parallel") is None


def test_processes_give_the_threaded_image_adaptive_resume_window():
    sc = peer()
    r = Renderer(sc)
    adaptive = AdaptiveSettings(threshold=0.05, min_spp=2)
    same(render(r, "processes", adaptive=adaptive), render(r, "threads", adaptive=adaptive))
    window = (5, 3, 27, 20)
    same(render(r, "processes", window=window), render(r, "threads", window=window))
    first = render(r, "threads", dataclasses.replace(sc.settings, spp=3)).film
    same(render(r, "processes", resume=first), render(r, "threads", resume=first))


def test_stop_keeps_the_finished_prefix_and_leaves_the_pool_usable():
    sc = peer(spp=12)
    r = Renderer(sc)
    threads = render(r, "threads")
    render(r, "processes")                  # the pool runs
    before = children()
    added = []

    def stop_after_two():
        return len(added) >= 2

    out = render(r, "processes", progress=lambda f, s: added.append(f), should_stop=stop_after_two)
    assert out.cancelled and 0 < out.film.count.sum() < threads.film.count.sum()
    # the finished prefix: the same units of the threaded render, added in the same order
    plan = r.plan(dataclasses.replace(sc.settings, parallel="processes"), workers=out.stats["threads"])
    job = BandJob(plan.settings, plan.width, None, plan.split_halves)
    tracer = r.tracer(plan)
    ref = type(out.film)(plan.width, plan.height)
    for unit in plan.units():
        if ref.count.sum() == out.film.count.sum():
            break
        ref.add(job(tracer, unit)[0])
    assert ref.sums.tobytes() == out.film.sums.tobytes()
    same(render(r, "processes"), threads)         # usable again
    assert children() == before                     # no orphans, no new workers


def test_a_worker_killed_mid_render_does_not_change_the_image():
    sc = peer(spp=12)
    r = Renderer(sc)
    threads = render(r, "threads")
    render(r, "processes")
    victim = processes.pool().workers[0].proc
    calls = []

    def kill_once(fraction, stats):
        if not calls:
            victim.kill()
        calls.append(fraction)

    out = render(r, "processes", progress=kill_once)
    same(out, threads)
    assert victim.wait(5) is not None
    assert "a worker process died" in out.stats_line()
    again = render(r, "processes")              # the pool is whole again
    same(again, threads)
    assert processes.pool_running() >= 2 and "died" not in again.stats_line()


@pytest.mark.parametrize("command, why", [([sys.executable, "-c", "raise ImportError('no engine here')"],
                                           "ImportError: no engine here"),
                                          (["/nonexistent/python"], "cannot start")])
def test_processes_that_cannot_start_fall_back_to_threads_with_one_warning(command, why):
    processes.close_pool()
    processes.pool().command = command
    try:
        sc = peer()
        r = Renderer(sc)
        out = render(r, "processes")
        same(out, render(r, "threads"))
        line = out.stats_line()
        assert line.count("worker processes could not start") == 1 and why in line and "rendered on threads" in line
        assert processes.pool_running() == 0
    finally:
        processes.close_pool()


def test_no_python_or_a_worker_that_never_answers_falls_back_to_threads(monkeypatch):
    processes.close_pool()
    r = Renderer(peer(res=16, spp=2))
    try:
        monkeypatch.setattr(sys, "executable", "")
        assert "no Python executable" in render(r, "processes").stats_line()
        monkeypatch.undo()
        processes.pool().command = [sys.executable, "-c", "import time; time.sleep(60)"]
        monkeypatch.setenv("POLAR_WORKER_START_TIMEOUT", "1")
        out = render(r, "processes")
        assert "no worker answered within 1 s" in out.stats_line() and out.stats.get("parallel") is None
        assert not processes.pool().workers
    finally:
        processes.close_pool()


def test_bad_parallel_value_is_one_line_naming_the_field():
    with pytest.raises(SceneError) as e:
        parse_settings({"parallel": "gpu"})
    assert e.value.field == "render.parallel" and "'auto', 'threads', 'processes'" in str(e.value)
    assert "\n" not in str(e.value)
    assert parse_settings({"parallel": "processes"}).parallel == "processes"


def test_auto_takes_processes_where_python_shades_and_the_start_pays(monkeypatch):
    choose = processes.choose_parallel
    monkeypatch.setattr(processes, "pool_running", lambda: 0)
    monkeypatch.setattr(processes, "kernels_ready", lambda: True)
    big, small = processes.AMORTISED_PATHS, processes.AMORTISED_PATHS // 8
    assert choose("auto", 2, True, big)[0] == "processes"
    assert "automatic" in choose("auto", 2, True, big)[1]
    # not worth waiting for the pool: threads now, and where the host renders again (keep_pool_warm: Blender) the pool
    # starts in the background for the next renders; not for a command-line render (one render, then the exit)
    assert choose("auto", 2, True, small) == ("threads", "", False)
    monkeypatch.setattr(processes, "_WARM", True)
    assert choose("auto", 2, True, small) == ("threads", "", True)
    assert choose("auto", 2, False, big) == ("threads", "", False)     # delta/Lambert only: threads scale
    assert choose("auto", 1, True, big)[0] == "threads"                # one worker
    assert choose("threads", 2, True, big) == ("threads", "set by render.parallel", False)
    assert choose("processes", 2, False, 1)[0] == "processes"
    monkeypatch.setattr(processes, "kernels_ready", lambda: False)
    assert choose("auto", 2, True, big) == ("threads", "", False)      # each worker would compile the kernels
    monkeypatch.setattr(processes, "pool_running", lambda: 2)
    assert choose("auto", 2, True, small)[0] == "processes"            # running: always amortised


def test_a_small_auto_render_starts_the_pool_for_the_next_ones(monkeypatch, many_materials):
    """A render too small to wait for the workers runs on threads and starts them in the background; the next
    render of the scene finds them and runs on processes, with the same image."""
    import time
    processes.close_pool()
    monkeypatch.setattr(processes, "kernels_ready", lambda: True)
    monkeypatch.setattr(processes, "_WARM", True)           # (the Blender add-on's keep_pool_warm)
    settings = dataclasses.replace(many_materials.settings, spp=2, threads=2, parallel="auto")
    renderer = Renderer(many_materials)
    first = renderer.render(settings)
    assert first.stats.get("parallel", "threads") == "threads"
    deadline = time.time() + 120
    while processes.pool().starting and time.time() < deadline:
        time.sleep(0.1)
    assert processes.pool_running() == 2 and processes.pool().unavailable is None
    second = renderer.render(settings)
    assert second.stats["parallel"] == "processes" and "automatic" in second.stats["parallel_reason"]
    same(second, first)
    # threads asked for: the pool is neither used nor started
    processes.close_pool()
    renderer.render(dataclasses.replace(settings, parallel="threads"))
    assert not processes.pool().starting and processes.pool_running() == 0


def test_a_pool_closed_while_it_starts_in_the_background_leaves_no_workers():
    """close_pool (the extension disabled) during a background start: the workers it was starting end too."""
    import time
    processes.close_pool()
    before = children()
    started = processes.pool()
    assert processes.start_in_background(2)
    processes.close_pool()
    deadline = time.time() + 120
    while started.starting and time.time() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    assert not started.starting and started.running == 0
    assert children() - before == set()


def test_command_line_parallel_option_and_scene_field(tmp_path, capsys, monkeypatch):
    import json

    from engine import cli
    monkeypatch.setattr(cli.ProgressBar.__init__, "__defaults__", (sys.stderr, 30))    # this test's stderr
    processes.close_pool()
    from engine.render import precompile
    scene = precompile.scenes(str(tmp_path))["grey"]          # a native scene file (its textures in tmp_path)
    path = tmp_path / "s.json"
    path.write_text(json.dumps(scene))
    status = cli.main(["render", str(path), "--spp", "2", "--parallel", "processes", "-o", str(tmp_path / "a.exr"),
                       "--no-previews"])
    err = capsys.readouterr().err
    assert status == 0, err
    assert err.count("starting worker processes (first render only)") == 1 and "2 processes (set by" in err \
        or os.cpu_count() == 1
    scene["render"] = {**scene.get("render", {}), "parallel": "gpu"}
    path.write_text(json.dumps(scene))
    status = cli.main(["render", str(path), "-o", str(tmp_path / "b.exr")])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert status == 2 and len(lines) == 1 and lines[0].startswith("error: render.parallel: "), err


def test_a_worker_keeps_a_few_tracers_of_its_scene():
    from engine.render import renderer as module
    scenes = module._WorkerScenes()
    sc = peer(res=8, spp=1)
    for seed in range(module.WORKER_TRACERS + 3):       # e.g. one seed per frame of an animation
        scenes.tracer("k", sc, dataclasses.replace(sc.settings, seed=seed), False)
    assert len(scenes.tracers) == module.WORKER_TRACERS


def test_a_worker_reseeds_the_tracer_of_another_seed_and_traces_as_a_new_one(many_materials):
    """A worker's render of the next seed copies the tracer of the last (PathTracer.reseeded: the shading groups and
    light tables shared) and traces the numbers a tracer built for that seed traces; other settings build anew."""
    from engine.render import renderer as module
    sc = many_materials
    scenes = module._WorkerScenes()
    first = scenes.tracer("k", sc, dataclasses.replace(sc.settings, seed=1), False)
    second = scenes.tracer("k", sc, dataclasses.replace(sc.settings, seed=2), False)
    assert second is not first and second.shaders is first.shaders and second.settings.seed == 2
    other = scenes.tracer("k", sc, dataclasses.replace(sc.settings, seed=3, max_depth=3), False)
    assert other.shaders is not first.shaders
    r = Renderer(sc)
    plan = r.plan(dataclasses.replace(sc.settings, seed=2))
    fresh = r.tracer(plan)
    job = BandJob(plan.settings, plan.width, plan.window, plan.stratified)
    for unit in list(plan.units())[:2]:
        got, want = job(second, unit)[0], job(fresh, unit)[0]
        assert got.sums.tobytes() == want.sums.tobytes() and got.count.tobytes() == want.count.tobytes()
    with pytest.raises(ValueError, match="more than the seed"):
        first.reseeded(dataclasses.replace(first.settings, seed=5, spp=1))


def test_processes_whose_workers_all_died_build_the_tracer_here():
    """The renderer hands worker processes a functools.partial for its own tracer (built only if every worker dies,
    not before each render's units go out); the units then traced here are the threads' units."""
    import collections
    import functools
    import threading
    sc = peer(res=8, spp=2)
    r = Renderer(sc)
    plan = r.plan(sc.settings)
    job = BandJob(plan.settings, plan.width, plan.window, plan.stratified)
    units = list(plan.units())
    built = []

    def tracer():
        built.append(1)
        return r.tracer(plan)
    here = object.__new__(processes.LocalProcesses)
    results = {}
    todo = collections.deque(range(len(units)))
    here._trace_here(units, todo, results, job, functools.partial(tracer), lambda: False, threading.Event())
    assert built == [1] and sorted(results) == list(range(len(units)))
    want = r.tracer(plan)
    for i, unit in enumerate(units):
        assert results[i][0].sums.tobytes() == job(want, unit)[0].sums.tobytes()
    assert processes.LocalProcesses.traces_elsewhere


def test_memory_check_counts_the_workers_scene_copies(monkeypatch):
    from engine.render import renderer as module
    sc = peer(res=16, spp=2)
    r = Renderer(sc)
    plan = r.plan(sc.settings)
    threads_need = module.memory_estimate(plan.width, plan.height, plan.settings.batch_rays, plan.workers)
    monkeypatch.setattr(module, "available_memory", lambda: int((threads_need + (64 << 20)) / 0.8))
    out = render(r, "processes")            # 2 workers × (160 MB + the scene) do not fit in 64 MB more
    assert out.stats.get("parallel") is None and "copies of the scene do not fit" in out.stats_line()
    same(out, render(r, "threads"))
