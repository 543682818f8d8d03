"""Distributed rendering on a local Dask cluster of worker processes."""

import dataclasses
import os
import signal

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

from engine.render.renderer import Renderer, RenderRequest  # noqa: E402
from engine.scene.loader import load_scene  # noqa: E402
from tests.conftest import shared_path  # noqa: E402

pytestmark = [pytest.mark.cluster, pytest.mark.subprocess]


@pytest.fixture(scope="module")
def cluster():
    cluster = distributed.LocalCluster(n_workers=3, threads_per_worker=1, processes=True, dashboard_address=None,
                                       silence_logs=40)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


def scene(name="fresnel_sphere", res=32, spp=6):
    s = load_scene(shared_path("peers", "scenes", f"{name}.json"))
    s.camera.width = s.camera.height = res
    # one pass per task: several tasks per worker
    s.settings = dataclasses.replace(s.settings, spp=spp, batch_rays=res * res)
    return s


@pytest.mark.parametrize("name, halves", [("fresnel_sphere", "auto"), ("cornell_lambert", "auto"),
                                          ("cornell_lambert", "independent")])
def test_merged_image_equals_the_single_process_render(cluster, name, halves):
    sc = scene(name)
    sc.settings = dataclasses.replace(sc.settings, halves=halves)       # "auto": one sequence (a uniform render)
    local = Renderer(sc).render()
    remote = Renderer(sc).render(RenderRequest(scheduler=cluster))
    assert remote.stats["workers"] == 3
    assert remote.settings.halves == local.settings.halves == ("independent" if halves == "independent"
                                                                else "one_sequence")
    np.testing.assert_array_equal(remote.stokes(), local.stokes())
    np.testing.assert_array_equal(remote.film.count, local.film.count)
    # the class sums: even/odd, or one sequence's octave classes folded unit by unit (engine.render.halves)
    np.testing.assert_array_equal(remote.film.half_y, local.film.half_y)


def test_alpha_of_a_transparent_film_is_merged(cluster):
    sc = scene("fresnel_sphere")
    sc.camera.target = np.array([0.0, 0.0, sc.camera.origin[2]])     # level view: half of it is sky
    sc.camera.film_transparent = True
    local = Renderer(sc).render()
    remote = Renderer(sc).render(RenderRequest(scheduler=cluster))
    assert local.film.alpha().min() < 1
    np.testing.assert_array_equal(remote.film.alpha(), local.film.alpha())
    np.testing.assert_array_equal(remote.stokes(), local.stokes())


def test_a_worker_dying_mid_render_does_not_change_the_image(cluster):
    sc = scene(spp=12)
    local = Renderer(sc).render()
    killed = {"done": False}
    pids = cluster.run(os.getpid)               # worker address → process id

    def kill_one(fraction, stats):
        if not killed["done"]:
            killed["done"] = True
            os.kill(sorted(pids.items())[0][1], signal.SIGKILL)   # no goodbye: the process just vanishes

    remote = Renderer(sc).render(RenderRequest(scheduler=cluster, progress=kill_one))
    assert killed["done"]
    np.testing.assert_array_equal(remote.stokes(), local.stokes())


def test_cli_scheduler_option_gives_the_local_image(cluster, tmp_path):
    import subprocess
    import sys
    from engine.output.exr import read_stokes_exr
    from tests.conftest import REPO
    path = shared_path("peers", "scenes", "conv_s3_check.json")
    common = ["--spp", "8", "--seed", "3", "--no-previews", "-q"]
    local, remote = str(tmp_path / "local.exr"), str(tmp_path / "remote.exr")
    subprocess.run([sys.executable, "-m", "engine", "render", path, "-o", local, *common], cwd=REPO, check=True,
                   capture_output=True)
    proc = subprocess.run([sys.executable, "-m", "engine", "render", path, "-o", remote, *common,
                           "--scheduler", cluster.scheduler.address], cwd=REPO, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    np.testing.assert_array_equal(read_stokes_exr(remote)[0], read_stokes_exr(local)[0])
    bad = subprocess.run([sys.executable, "-m", "engine", "render", path, "-o", str(tmp_path / "x.exr"),
                          "--scheduler", "tcp://127.0.0.1:9"], cwd=REPO, capture_output=True, text=True, timeout=120,
                         env={**os.environ, "POLAR_DASK_TIMEOUT": "2"})
    assert bad.returncode == 2 and "--scheduler" in bad.stderr and "Traceback" not in bad.stderr
    # malformed settings of the cluster: one line naming the variable, before any work is sent
    for name, value in (("POLAR_DASK_RETRIES", "3.0"), ("POLAR_DASK_TIMEOUT", "soon")):
        bad = subprocess.run([sys.executable, "-m", "engine", "render", path, "-o", str(tmp_path / "y.exr"),
                              "--scheduler", cluster.scheduler.address], cwd=REPO, capture_output=True, text=True,
                             timeout=120, env={**os.environ, name: value})
        errors = [line for line in bad.stderr.splitlines() if line.startswith("error:")]
        assert bad.returncode == 2 and len(errors) == 1 and name in errors[0], bad.stderr
        assert "Traceback" not in bad.stderr and not os.path.exists(tmp_path / "y.exr")


def _raise_on_unit_one(unit):
    if unit == 1:
        raise ValueError("unit 1 is broken")
    return unit


def test_a_unit_that_raises_is_not_submitted_again_and_a_lost_one_is(cluster):
    from distributed import KilledWorker
    from distributed.client import FutureCancelledError
    from engine.render.distributed import _ordered_on_cluster, retryable
    submitted, added = [], []

    def submit(unit, again):
        submitted.append(unit)
        return cluster.submit(_raise_on_unit_one, unit, pure=False)

    stopped, error = _ordered_on_cluster(cluster, submit, [0, 1, 2], added.append, lambda: False, retries=3)
    # the unit's own exception would repeat: the render stops with it at once (keeping unit 0 if it was back first)
    assert stopped and "ValueError: unit 1 is broken" in error
    assert submitted.count(1) == 1 and added in ([], [0])
    # lost tasks (Dask cancels those whose worker or scattered data it lost) are retried; KilledWorker (the unit
    # already killed Dask's allowed number of workers) and a unit's own exception are not
    assert retryable(FutureCancelledError("k", "lost"))
    assert not retryable(KilledWorker("k", "worker", 3)) and not retryable(ValueError())


# --- a cluster that fails mid-render -------------------------------------------------------------

@pytest.fixture
def fragile_cluster():
    """A separate one-worker cluster (its worker gets killed): (client, cluster)."""
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                                       silence_logs=50)
    client = distributed.Client(cluster)
    yield client, cluster
    client.close()
    cluster.close()


def _kill_workers(client):
    for pid in client.run(os.getpid).values():
        os.kill(pid, signal.SIGKILL)


def _render_killing_every_worker(client, sc):
    """(result, killed): ``sc`` rendered on ``client``, every worker killed once the first samples are in
    (``killed["samples"]``: how many)."""
    killed = {}

    def kill_all(fraction, stats):
        if stats["samples"] and not killed:
            killed["samples"] = stats["samples"]
            _kill_workers(client)

    return Renderer(sc).render(RenderRequest(scheduler=client, progress=kill_all)), killed


def test_a_lost_scene_is_sent_again_and_the_image_is_unchanged(fragile_cluster):
    """The one worker holds the only copy of the scene (as Dask's memory manager may leave it on a big
    cluster): killing it loses the scene; the units are submitted again with the scene sent again to the
    restarted worker, and the image is the local one.  Before the retry the render ended with an error."""
    client, _ = fragile_cluster
    sc = scene(res=16, spp=40)
    sc.settings = dataclasses.replace(sc.settings, batch_rays=1024)   # 4 passes per unit: 10 units
    result, killed = _render_killing_every_worker(client, sc)
    assert killed and killed["samples"] < 16 * 16 * 40
    assert not result.cancelled and "error" not in result.stats
    np.testing.assert_array_equal(result.stokes(), Renderer(sc).render().stokes())


def test_losing_every_worker_returns_the_finished_units_and_an_error(fragile_cluster, monkeypatch):
    from engine.render import distributed as dask_executor
    monkeypatch.setattr(dask_executor, "UNIT_RETRIES", 0)          # the workers do not come back in time
    client, _ = fragile_cluster
    sc = scene(res=16, spp=800)
    sc.settings = dataclasses.replace(sc.settings, batch_rays=1024)   # 8 rows × 8 passes per unit: 200 units
    result, killed = _render_killing_every_worker(client, sc)
    assert killed and result.cancelled and "Dask cluster failed" in result.stats["error"]
    count = result.film.count
    assert 0 < count.sum() < 16 * 16 * 800 and count.sum() == result.stats["samples"]
    # the finished units are exactly those of the local render (unit order is kept)
    done = count > 0
    np.testing.assert_array_equal(result.film.sums[:, :, done] / count[done],
                                  _partial_means(sc, count)[:, :, done])


def _partial_means(sc, count):
    """Means of the first count[p] sample passes per pixel, rendered locally (passes are stateless): one local
    render per distinct count (a prefix of units may end between the two bands of a pass group)."""
    means = np.zeros((*Renderer(sc).render(dataclasses.replace(sc.settings, spp=1)).film.sums.shape[:2], count.size))
    for c in np.unique(count[count > 0]):
        film = Renderer(sc).render(dataclasses.replace(sc.settings, spp=int(c))).film
        assert np.all(film.count == c)
        means[:, :, count == c] = (film.sums / film.count)[:, :, count == c]
    return means


def test_a_cluster_without_workers_is_an_error_not_a_hang(monkeypatch):
    cluster = distributed.LocalCluster(n_workers=0, processes=False, dashboard_address=None, silence_logs=50)
    client = distributed.Client(cluster)
    try:
        monkeypatch.setenv("POLAR_DASK_TIMEOUT", "1")
        with pytest.raises(RuntimeError, match="no Dask worker joined the scheduler within 1 s"):
            Renderer(scene(res=8, spp=1)).render(RenderRequest(scheduler=client))
    finally:
        client.close()
        cluster.close()


def test_cli_writes_the_finished_units_when_the_cluster_dies(fragile_cluster, tmp_path):
    import re
    import subprocess
    import sys
    import time
    from engine.output.exr import read_stokes_exr
    from tests.conftest import REPO
    from tests.cli.test_robustness_cli import small_demo
    client, cluster = fragile_cluster
    out = str(tmp_path / "part.exr")
    proc = subprocess.Popen([sys.executable, "-m", "engine", "render", small_demo(tmp_path, spp=4000), "-o", out,
                             "--no-previews", "--scheduler", cluster.scheduler.address], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "POLAR_DASK_RETRIES": "0"})   # the restarted worker is not used
    buf, deadline = "", time.time() + 120
    while time.time() < deadline and not any(float(p) > 0 for p in re.findall(r"(\d+\.\d)%", buf)):
        c = proc.stderr.read(1)
        if not c:
            break
        buf += c
    _kill_workers(client)
    _, err = proc.communicate(timeout=120)
    err = buf + err
    assert proc.returncode == 1, err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and lines[0].startswith("error: --scheduler: the Dask cluster failed")
    assert "Traceback" not in err
    _, channels, header = read_stokes_exr(out)
    assert header["polar.complete"] == 0 and channels["spp"].max() > 0 and channels["spp"].min() < 4000
