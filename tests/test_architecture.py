"""Layering rules: the engine stands alone (no bpy, no add-on imports, relative imports only so it
works as a subpackage of the Blender extension)."""

import os
import re

from tests.conftest import REPO


def engine_sources():
    for dirpath, _, files in os.walk(os.path.join(REPO, "engine")):
        for f in files:
            if f.endswith(".py"):
                yield os.path.join(dirpath, f)


def test_engine_never_imports_bpy_or_the_addon_and_uses_relative_imports():
    bad = []
    pattern = re.compile(r"^\s*(import bpy|from bpy|import engine\b|from engine[. ]|.*polar_addon)", re.M)
    for path in engine_sources():
        src = open(path, encoding="utf-8").read()
        code = re.sub(r'("""|\'\'\')(.*?)\1', "", src, flags=re.S)        # ignore docstrings
        for m in pattern.finditer(code):
            bad.append(f"{os.path.relpath(path, REPO)}: {m.group(0).strip()}")
    assert not bad, "\n".join(bad)


def test_root_init_does_not_import_bpy():
    src = open(os.path.join(REPO, "__init__.py"), encoding="utf-8").read()
    assert not re.search(r"^(import|from) ", src, re.M)
