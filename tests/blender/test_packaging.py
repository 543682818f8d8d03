"""The extension packaging: every platform's zip carries numba, llvmlite, embreex and OpenEXR wheels
for each Python of the supported Blenders (3.11: 4.5 and 5.0; 3.13: 5.1 on).

No network: the download step is replaced by a fake that writes placeholder wheel files, and the
zips are built with Blender's own extension tool (from the bpy module) in a copy of the sources.
"""

import importlib.util
import os
import re
import shutil
import sys
import types
import zipfile

import pytest

from polar_addon import packaging
from tests.conftest import REPO

PLATFORMS = {"linux-x64", "windows-x64", "macos-arm64"}
PYTHONS = ("cp311", "cp313")


def blender_ext():
    """Blender's extension CLI module (the oracle for which wheel goes to which platform)."""
    pytest.importorskip("bpy")
    spec = importlib.util.spec_from_file_location("blender_ext", packaging.blender_ext_tool())
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def source_copy(tmp_path):
    """The files the zip is built from, without the wheels/ folder of this checkout."""
    src = tmp_path / "src"
    src.mkdir()
    for name in ("blender_manifest.toml", "__init__.py"):
        shutil.copy(os.path.join(REPO, name), src / name)
    for name in ("engine", "polar_addon"):
        shutil.copytree(os.path.join(REPO, name), src / name, ignore=shutil.ignore_patterns("__pycache__"))
    return src


class FakeIndex:
    """Stands in for pip: writes a placeholder wheel named from the requested tags and records the call."""

    def __init__(self):
        self.calls = []

    def __call__(self, name, version, python_version, platform_tags, dest):
        self.calls.append((name, version, python_version, tuple(platform_tags)))
        tags = ("py3-none" if platform_tags == ["any"] else f"cp{python_version}-cp{python_version}")
        filename = f"{name}-{version}-{tags}-{'.'.join(platform_tags)}.whl"
        with zipfile.ZipFile(os.path.join(dest, filename), "w") as zf:
            zf.writestr(f"{name}/__init__.py", f"# placeholder {filename}\n")


def test_manifest_bundles_numba_llvmlite_embreex_openexr_threadpoolctl_for_each_platform_and_python():
    assert set(packaging.manifest_platforms()) == PLATFORMS
    assert sorted(set(packaging.BLENDER_PYTHONS.values())) == list(PYTHONS)
    wheels = packaging.manifest_wheels()
    for plat in PLATFORMS:
        for python in PYTHONS:
            mine = [os.path.basename(w) for w in wheels if plat in packaging.wheel_platforms(w)
                    and (w.split("-")[2] == python or w.endswith("-py3-none-any.whl"))]
            names = sorted(w.split("-")[0] for w in mine)
            assert names == sorted(packaging.BUNDLED), (plat, python, mine)
            versions = {w.split("-")[0]: w.split("-")[1] for w in mine}
            # numba 0.N pins llvmlite 0.(N-18) (numba 0.68 requires llvmlite >=0.50,<0.51)
            assert int(versions["numba"].split(".")[1]) - 18 == int(versions["llvmlite"].split(".")[1])
        # one version of each package for both Pythons: the same engine code runs on every Blender
        versions = {}
        for w in wheels:
            if plat in packaging.wheel_platforms(w):
                versions.setdefault(os.path.basename(w).split("-")[0], set()).add(os.path.basename(w).split("-")[1])
        assert all(len(v) == 1 for v in versions.values()), versions
    assert re.search(r'^blender_version_min = "4\.5\.0"$', packaging.manifest_text(), re.M)
    packaging.check_manifest()


def test_wheel_platforms_agree_with_blender_split():
    ext = blender_ext()
    for wheel in packaging.manifest_wheels():
        for plat in PLATFORMS | {"linux-arm64", "macos-x64", "windows-arm64"}:
            ours = plat in packaging.wheel_platforms(wheel)
            theirs = ext.blender_platform_compatible_with_wheel_platform_from_filepath(plat, wheel)
            assert ours == theirs, (wheel, plat)


def test_build_one_zip_per_platform_with_its_wheels(tmp_path):
    blender_ext()
    src = source_copy(tmp_path)
    fetch = FakeIndex()
    zips = packaging.build_all(str(tmp_path / "dist"), source_dir=str(src), fetch=fetch)
    wheels = packaging.manifest_wheels(str(src))
    assert len(fetch.calls) == len(wheels) == 25
    assert ("numba", "0.68.1", "311", ("win_amd64",)) in fetch.calls
    assert ("numba", "0.68.1", "313", ("win_amd64",)) in fetch.calls
    assert ("threadpoolctl", "3.7.0", "311", ("any",)) in fetch.calls
    assert set(zips) == PLATFORMS
    for plat, path in zips.items():
        assert os.path.basename(path) == f"polar_render-0.1.0-{plat.replace('-', '_')}.zip"
        with zipfile.ZipFile(path) as zf:
            names = zf.namelist()
            manifest = zf.read("blender_manifest.toml").decode()
        expected = sorted(w[2:] for w in wheels if plat in packaging.wheel_platforms(w))
        assert sorted(n for n in names if n.startswith("wheels/")) == expected
        assert {n.split("/")[0] for n in expected} == {"wheels"} and len(expected) == 9   # 4 per Python + 1
        assert "engine/kernels/__init__.py" in names and "polar_addon/kernel_cache.py" in names
        assert not any(n.startswith(("tests/", "examples/")) for n in names)
        generated = manifest.split("[build.generated]", 1)[1]        # what Blender installs on this platform
        assert re.search(r'^platforms = \["' + plat + r'"\]', generated, re.M)
        assert sorted(re.findall(r'"\./(wheels/[^"]+)"', generated)) == expected
    # wheels already downloaded are not fetched again
    packaging.build_all(str(tmp_path / "dist2"), source_dir=str(src), fetch=fetch)
    assert len(fetch.calls) == 25


def test_manifest_missing_a_platform_wheel_is_refused(tmp_path):
    src = source_copy(tmp_path)
    manifest = src / "blender_manifest.toml"
    text = manifest.read_text()
    manifest.write_text(re.sub(r'\s*"\./wheels/numba-[^"]+cp313-[^"]+win_amd64\.whl",', "", text))
    with pytest.raises(SystemExit, match="windows-x64 needs exactly one numba wheel for cp313"):
        packaging.check_manifest(str(src))
    manifest.write_text(text.replace('"./wheels/llvmlite-0.50.0-cp311-cp311-macosx_12_0_arm64.whl",',
                                     '"./wheels/llvmlite-0.50.0-cp311-cp311-macosx_12_0_arm64.whl",\n'
                                     '  "./wheels/llvmlite-0.49.0-cp311-cp311-macosx_12_0_arm64.whl",'))
    with pytest.raises(SystemExit, match="macos-arm64 needs exactly one llvmlite wheel for cp311 .* found 2"):
        packaging.check_manifest(str(src))


def test_manifest_minimum_is_the_oldest_supported_blender(tmp_path):
    src = source_copy(tmp_path)
    manifest = src / "blender_manifest.toml"
    manifest.write_text(manifest.read_text().replace('blender_version_min = "4.5.0"', 'blender_version_min = "5.0.0"'))
    with pytest.raises(SystemExit, match=r'blender_version_min must be "4\.5\.0".*found 5\.0\.0'):
        packaging.check_manifest(str(src))


def test_download_that_produces_no_wheel_names_it(tmp_path):
    src = source_copy(tmp_path)
    with pytest.raises(SystemExit, match=r"did not produce \./wheels/embreex-4\.4\.0\.post1-cp311"):
        packaging.download_wheels(str(src), fetch=lambda *args: None)


# ------------------------------------------------------------------ the add-on's side of the bundle

def fake_bpy(monkeypatch, user_folder):
    """A stand-in for bpy whose extension user folder is ``user_folder`` (Blender creates it on request)."""
    def extension_path_user(package, path="", create=False):
        if package != "bl_ext.user_default.polar_render":
            raise ValueError('The "package" does not name an extension')
        folder = os.path.join(user_folder, path)
        if create:
            os.makedirs(folder, exist_ok=True)
        return folder
    monkeypatch.setitem(sys.modules, "bpy",
                        types.SimpleNamespace(utils=types.SimpleNamespace(extension_path_user=extension_path_user)))


def test_kernel_cache_goes_to_the_extension_user_folder_per_version(tmp_path, monkeypatch):
    from polar_addon import kernel_cache
    fake_bpy(monkeypatch, str(tmp_path / "user"))
    monkeypatch.delenv("POLAR_KERNEL_CACHE", raising=False)
    (tmp_path / "user" / "numba" / "0.0.9" / "engine").mkdir(parents=True)       # an earlier version's cache
    folder = kernel_cache.configure("bl_ext.user_default.polar_render")
    assert folder == str(tmp_path / "user" / "numba" / "0.1.0")
    assert os.environ["POLAR_KERNEL_CACHE"] == folder and os.path.isdir(folder)
    assert os.listdir(tmp_path / "user" / "numba") == ["0.1.0"]
    assert kernel_cache.configure("bl_ext.user_default.polar_render") == folder     # re-enabling: same folder


def test_kernel_cache_set_outside_blender_is_kept(tmp_path, monkeypatch):
    from polar_addon import kernel_cache
    fake_bpy(monkeypatch, str(tmp_path / "user"))
    monkeypatch.setenv("POLAR_KERNEL_CACHE", str(tmp_path / "farm"))
    assert kernel_cache.configure("bl_ext.user_default.polar_render") == str(tmp_path / "farm")
    assert os.environ["POLAR_KERNEL_CACHE"] == str(tmp_path / "farm")
    # a checkout loaded as a package (not an installed extension) has no user folder: unchanged
    monkeypatch.delenv("POLAR_KERNEL_CACHE")
    assert kernel_cache.configure("polar_render") is None and "POLAR_KERNEL_CACHE" not in os.environ


def test_first_compile_pending_on_an_empty_cache_only(tmp_path):
    from polar_addon import kernel_cache
    cache = tmp_path / "cache"
    kernels = types.SimpleNamespace(COMPILED=True, cache_dir=lambda: str(cache))
    assert kernel_cache.first_compile_pending(kernels)                  # folder not even created yet
    (cache / "engine_kernels").mkdir(parents=True)
    assert kernel_cache.first_compile_pending(kernels)
    (cache / "engine_kernels" / "transport.update_abcs-40.py311.nbi").write_bytes(b"")
    assert not kernel_cache.first_compile_pending(kernels)
    cold_numpy = types.SimpleNamespace(COMPILED=False, cache_dir=lambda: str(tmp_path / "none"))
    assert not kernel_cache.first_compile_pending(cold_numpy)          # NumPy kernels never compile


def test_one_warning_when_numba_is_missing(caplog, monkeypatch):
    from polar_addon import kernel_cache
    monkeypatch.delenv("POLAR_KERNELS", raising=False)
    with caplog.at_level("WARNING"):
        kernel_cache.warn_if_numpy_fallback(types.SimpleNamespace(COMPILED=True))
        assert not caplog.records
        kernel_cache.warn_if_numpy_fallback(types.SimpleNamespace(COMPILED=False))
        assert len(caplog.records) == 1 and "NumPy kernels" in caplog.records[0].getMessage()
        monkeypatch.setenv("POLAR_KERNELS", "numpy")                    # asked for: no warning
        kernel_cache.warn_if_numpy_fallback(types.SimpleNamespace(COMPILED=False))
        assert len(caplog.records) == 1


def test_tested_blender_releases_are_the_supported_series():
    """tests/support/blender_envs.py tests one bpy release of each supported series, on its Python."""
    from tests.support import blender_envs
    assert set(blender_envs.RELEASES) == set(packaging.BLENDER_PYTHONS)
    for series, (release, python) in blender_envs.RELEASES.items():
        assert release.startswith(series + ".")
        assert packaging.BLENDER_PYTHONS[series] == "cp" + python.replace(".", "")
    def version(series):
        return tuple(map(int, series.split(".")))
    assert set(blender_envs.CI_SERIES) == {min(packaging.BLENDER_PYTHONS, key=version),
                                           max(packaging.BLENDER_PYTHONS, key=version)}


def test_blender_environment_setup_names_what_is_missing(monkeypatch):
    from tests.support import blender_envs
    monkeypatch.setenv("PATH", "")
    monkeypatch.setenv("PYENV_ROOT", "/nonexistent")
    with pytest.raises(blender_envs.SetupError, match=r"no Python 3\.13 found .*pyenv install 3\.13"):
        blender_envs.find_python("3.13")
    with pytest.raises(blender_envs.SetupError, match="series '6.9' unknown"):
        blender_envs.ensure("6.9")
