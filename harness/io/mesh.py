"""Mesh files <-> TriangleMesh, face order preserved (trimesh with ``process=False``)."""
from __future__ import annotations

import os

import numpy as np
import trimesh

from estimator import InputError, TriangleMesh


def load_mesh_file(path: str | os.PathLike) -> TriangleMesh:
    """Load a triangle mesh file without merging, dropping or reordering faces."""
    return load_mesh_with_uv(path)[0]


def load_mesh_with_uv(path: str | os.PathLike) -> tuple[TriangleMesh, np.ndarray | None]:
    """(mesh, per-vertex texture coordinates (V, 2) or None) of a mesh file, face order kept."""
    path = str(path)
    if not os.path.isfile(path):
        raise InputError(f"mesh file not found: {path}")
    try:
        loaded = trimesh.load(path, process=False, force="mesh")
    except ModuleNotFoundError as exc:
        if exc.name in ("charset_normalizer", "chardet"):   # trimesh's guess at a text's encoding, when not UTF-8
            raise InputError(f"cannot read mesh file {path}: its text is not UTF-8 (a binary or corrupted file?)") \
                from None
        raise InputError(f"cannot read mesh file {path}: its format needs the module {exc.name}") from None
    except Exception as exc:
        raise InputError(f"cannot read mesh file {path}: {exc}") from exc
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))))
    if faces.size == 0:
        raise InputError(f"mesh file {path} has no faces")
    uv = getattr(getattr(loaded, "visual", None), "uv", None)
    uv = None if uv is None or len(uv) != len(loaded.vertices) else np.asarray(uv, dtype=np.float64)
    if uv is not None and not np.all(np.isfinite(uv)):
        raise InputError(f"mesh file {path}: its texture coordinates hold NaN or Inf")
    try:
        return TriangleMesh(np.asarray(loaded.vertices), faces), uv
    except InputError as exc:   # the mesh's own checks (indices, finite vertices) do not know its file
        raise InputError(f"mesh file {path}: {exc}") from None


def polygon_count(path: str | os.PathLike) -> int | None:
    """The number of faces a PLY's header or an OBJ's ``f`` lines declare, whatever their
    sides (None for other formats). Loading triangulates polygons, so a count above the
    loaded triangles' means the file holds polygons of more than three sides."""
    path = str(path)
    ext = os.path.splitext(path)[1].lower()
    if ext == ".ply":
        with open(path, "rb") as f:
            for raw in f:
                words = raw.split()
                if words[:2] == [b"element", b"face"] and len(words) == 3 and words[2].isdigit():
                    return int(words[2])
                if raw.strip() == b"end_header":
                    return None
        return None
    if ext == ".obj":
        with open(path, "rb") as f:
            data = b"\n" + f.read()
        return data.count(b"\nf ") + data.count(b"\nf\t")
    return None


def save_mesh_ply(mesh: TriangleMesh, path: str | os.PathLike) -> None:
    """Write a binary PLY in the mesh's exact vertex and face order."""
    t = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    t.export(str(path), file_type="ply")


def write_uv_ply(path: str, corners: np.ndarray, uv: np.ndarray) -> None:
    """Binary PLY with unshared vertices, which Mitsuba's ``ply`` shape reads: face i is
    vertices 3i..3i+2 (``corners`` (F, 3, 3)) with UVs (u, v) (``uv`` (F, 3, 2))."""
    f = len(corners)
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {3 * f}\n"
              "property float x\nproperty float y\nproperty float z\nproperty float u\nproperty float v\n"
              f"element face {f}\nproperty list uchar int vertex_indices\nend_header\n")
    vertices = np.concatenate([corners.reshape(-1, 3), uv.reshape(-1, 2)], axis=1).astype("<f4")
    faces = np.empty(f, dtype=np.dtype([("n", "u1"), ("v", "<i4", 3)]))
    faces["n"] = 3
    faces["v"] = np.arange(3 * f, dtype=np.int32).reshape(f, 3)
    with open(path, "wb") as out:
        out.write(header.encode("ascii"))
        out.write(vertices.tobytes())
        out.write(faces.tobytes())
