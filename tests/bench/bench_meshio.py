"""Mesh-file reading speed (PLY through plyfile, OBJ): seconds per file, fastest of --repeats.

    python tests/bench/bench_meshio.py [--subdivisions 8] [--repeats 3]

Writes an icosphere (default 8 subdivisions: 655,362 vertices, 1,310,720 triangles) as binary PLY
(triangles only, and with every other pair of triangles merged into a quad), ASCII PLY and OBJ into
a temporary folder and reads each back with engine.scene.meshio.read_mesh.  Tests never time; this
is where mesh-reading speed is watched.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", ".."))

from engine.scene.meshio import read_mesh  # noqa: E402
from engine.scene.shapes import icosphere  # noqa: E402


def _ply_binary(path, v, faces_lists):
    with open(path, "wb") as fh:
        fh.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
                  "property float x\nproperty float y\nproperty float z\n"
                  f"element face {len(faces_lists)}\nproperty list uchar int vertex_indices\nend_header\n").encode())
        fh.write(v.astype("<f4").tobytes())
        if all(len(f) == 3 for f in faces_lists):
            rec = np.zeros(len(faces_lists), dtype=[("n", "u1"), ("i", "<i4", 3)])
            rec["n"] = 3
            rec["i"] = np.asarray(faces_lists)
            fh.write(rec.tobytes())
        else:
            fh.write(b"".join(np.uint8(len(f)).tobytes() + np.asarray(f, "<i4").tobytes() for f in faces_lists))


def _ply_ascii(path, v, faces):
    with open(path, "w") as fh:
        fh.write(f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty float x\nproperty float y\n"
                 f"property float z\nelement face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
        fh.write("\n".join(f"{x:.7g} {y:.7g} {z:.7g}" for x, y, z in v.tolist()) + "\n")
        fh.write("\n".join(f"3 {a} {b} {c}" for a, b, c in faces.tolist()) + "\n")


def _obj(path, v, faces):
    with open(path, "w") as fh:
        fh.write("\n".join(f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in v.tolist()) + "\n")
        fh.write("\n".join(f"f {a} {b} {c}" for a, b, c in (faces + 1).tolist()) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subdivisions", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args(argv)
    m = icosphere(a.subdivisions)
    v, f = m.vertices, m.faces
    # Quads: merge triangles 2i and 2i+1 where they share an edge (fan order), else keep triangles.
    mixed = []
    for i in range(0, len(f) - 1, 2):
        t, u = f[i].tolist(), f[i + 1].tolist()
        extra = [x for x in u if x not in t]
        mixed += [t + extra] if len(extra) == 1 and len(set(t) & set(u)) == 2 else [t, u]
    with tempfile.TemporaryDirectory() as d:
        files = {"binary PLY, triangles": os.path.join(d, "tri.ply"),
                 "binary PLY, tris + quads": os.path.join(d, "mixed.ply"),
                 "ASCII PLY": os.path.join(d, "ascii.ply"), "OBJ": os.path.join(d, "mesh.obj")}
        _ply_binary(files["binary PLY, triangles"], v, f.tolist())
        _ply_binary(files["binary PLY, tris + quads"], v, mixed)
        _ply_ascii(files["ASCII PLY"], v, f)
        _obj(files["OBJ"], v, f)
        print(f"{len(v):,} vertices, {len(f):,} triangles")
        for name, path in files.items():
            best = min(_timed(path) for _ in range(a.repeats))
            print(f"{name:28s} {best:8.3f} s   ({os.path.getsize(path) / 1e6:.0f} MB)")


def _timed(path):
    t0 = time.perf_counter()
    read_mesh(path)
    return time.perf_counter() - t0


if __name__ == "__main__":
    main()
