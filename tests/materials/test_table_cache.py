"""Precomputed material tables on disk (engine.materials.table_cache): read back bit for bit in a
later process, rebuilt when damaged, keyed by parameters and engine source, never fatal."""

import os
import subprocess
import sys

import numpy as np
import pytest

from engine.materials import table_cache
from engine.materials import weidlich_wilkie as ww
from engine.materials.microfacet import BlinnPhong

#: a cheap table (Blinn–Phong coat, one index): ≈ 0.1 s to build
ARGS = ("blinn", 20.0, 0.0, "ts", 1.5, 1.5)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("POLAR_KERNEL_CACHE", str(tmp_path))
    monkeypatch.delenv("POLAR_TABLE_CACHE", raising=False)
    ww._albedo_table.cache_clear()
    yield tmp_path
    ww._albedo_table.cache_clear()


def files(root):
    return sorted(os.path.join(d, f) for d, _, fs in os.walk(root) for f in fs)


def test_a_table_is_built_once_and_read_back_bit_for_bit(cache, monkeypatch):
    built = ww._albedo_table(*ARGS).E
    mu = np.cos(np.linspace(0.0, 0.5 * np.pi, ww._TABLE_THETA_STEPS + 1))
    assert np.array_equal(built[0], np.clip(ww.top_albedo(mu, 1.5, BlinnPhong(20.0), "ts"), 0.0, 1.0))
    (path,) = files(cache)
    assert path.startswith(table_cache.table_dir()) and path.endswith(".npy")
    ww._albedo_table.cache_clear()

    def no_quadrature(*a, **k):
        raise AssertionError("built again")
    monkeypatch.setattr(ww, "top_albedo", no_quadrature)
    assert np.array_equal(ww._albedo_table(*ARGS).E, built)


@pytest.mark.subprocess
def test_a_later_process_reads_the_table_instead_of_building_it(cache):
    """Two interpreters: the first builds and stores, the second has no quadrature and still gets it."""
    child = ("import sys, numpy as np\n"
             "from engine.materials import weidlich_wilkie as ww\n"
             "if sys.argv[1] == 'read':\n"
             "    ww.top_albedo = None\n"
             f"np.save(sys.argv[2], ww._albedo_table(*{ARGS!r}).E)\n")
    from tests.conftest import REPO as root
    env = {**os.environ, "PYTHONPATH": root}
    for mode in ("build", "read"):
        subprocess.run([sys.executable, "-c", child, mode, str(cache / f"{mode}.npy")], check=True, env=env, cwd=root)
    assert np.array_equal(np.load(cache / "build.npy"), np.load(cache / "read.npy"))


@pytest.mark.parametrize("damage", ["truncated", "garbage", "wrong shape", "wrong dtype"])
def test_a_damaged_file_is_built_again_and_replaced(cache, damage):
    fresh = ww._albedo_table(*ARGS).E
    (path,) = files(cache)
    if damage == "truncated":
        with open(path, "rb") as fh:
            data = fh.read()
        with open(path, "wb") as fh:
            fh.write(data[: len(data) // 2])
    elif damage == "garbage":
        with open(path, "wb") as fh:
            fh.write(b"not a table")
    else:
        np.save(path, np.zeros((2, 3)) if damage == "wrong shape" else fresh.astype(np.float32))
    ww._albedo_table.cache_clear()
    assert np.array_equal(ww._albedo_table(*ARGS).E, fresh)
    assert np.array_equal(np.load(path), fresh)          # replaced by the good table
    assert files(cache) == [path]                         # no temporary file left behind


def test_the_key_separates_parameters_and_engine_sources(cache, monkeypatch):
    a = table_cache.table_path("t", ("blinn", 20.0, 0.0))
    assert a == table_cache.table_path("t", ("blinn", 20.0, 0.0))
    assert a != table_cache.table_path("t", ("blinn", 20.000000000000004, 0.0))    # the next float
    assert a != table_cache.table_path("u", ("blinn", 20.0, 0.0))
    monkeypatch.setattr(table_cache, "_sources_digest", lambda: "edited")
    assert table_cache.table_path("t", ("blinn", 20.0, 0.0)) != a


def test_an_unwritable_cache_still_gives_the_table(tmp_path, monkeypatch):
    blocker = tmp_path / "a file"
    blocker.write_text("")
    monkeypatch.setenv("POLAR_KERNEL_CACHE", str(blocker))     # its "tables" folder cannot be made
    ww._albedo_table.cache_clear()
    try:
        got = ww._albedo_table(*ARGS).E
    finally:
        ww._albedo_table.cache_clear()
    monkeypatch.setenv("POLAR_TABLE_CACHE", "0")
    assert np.array_equal(got, ww._albedo_table(*ARGS).E)


def test_the_cache_can_be_turned_off(cache, monkeypatch):
    monkeypatch.setenv("POLAR_TABLE_CACHE", "0")
    ww._albedo_table(*ARGS)
    assert files(cache) == []


def test_threads_read_a_table_one_at_a_time(cache, monkeypatch):
    """np.load parses the header with ast.literal_eval, which CPython 3.11 breaks on two threads at once
    ("AST constructor recursion depth mismatch" in a two-thread render's first use of a table): reads are
    serialised.  Two threads meet at a barrier inside the read; with the lock the second waits instead."""
    import threading
    table_cache.cached_table("t", (1,), (3,), lambda: np.arange(3.0))
    inside, most, barrier = [0], [0], threading.Barrier(2, timeout=0.5)
    real_load = np.load

    def load(*a, **k):
        inside[0] += 1
        most[0] = max(most[0], inside[0])
        try:
            barrier.wait()              # the other thread inside too: two readers at once
        except threading.BrokenBarrierError:
            pass
        inside[0] -= 1
        return real_load(*a, **k)
    monkeypatch.setattr(table_cache.np, "load", load)
    got = []
    threads = [threading.Thread(target=lambda: got.append(table_cache.cached_table("t", (1,), (3,), None)))
               for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert most[0] == 1 and len(got) == 2 and all(np.array_equal(g, np.arange(3.0)) for g in got)
