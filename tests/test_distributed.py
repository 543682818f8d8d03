"""Distributed rendering on a local Dask cluster of worker processes."""

import os
import signal

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

from engine.render.distributed import render_distributed  # noqa: E402
from engine.render.renderer import Renderer  # noqa: E402
from engine.scene.loader import load_scene  # noqa: E402
from tests.conftest import shared_path  # noqa: E402


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
    s.settings.spp = spp
    s.settings.batch_rays = res * res          # one pass per task: several tasks per worker
    return s


@pytest.mark.parametrize("name", ["fresnel_sphere", "cornell_lambert"])
def test_merged_image_equals_the_single_process_render(cluster, name):
    sc = scene(name)
    local = Renderer(sc).render()
    remote = render_distributed(sc, None, client=cluster)
    assert remote.stats["workers"] == 3
    np.testing.assert_array_equal(remote.stokes(), local.stokes())
    np.testing.assert_array_equal(remote.film.count, local.film.count)


def test_alpha_of_a_transparent_film_is_merged(cluster):
    sc = scene("fresnel_sphere")
    sc.camera.target = np.array([0.0, 0.0, sc.camera.origin[2]])     # level view: half of it is sky
    sc.camera.film_transparent = True
    local = Renderer(sc).render()
    remote = render_distributed(sc, None, client=cluster)
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

    remote = render_distributed(sc, None, client=cluster, progress=kill_one)
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
