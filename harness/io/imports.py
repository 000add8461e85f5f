"""Other tools' results as pseudolight estimates, so ``report`` and ``compare`` score them
like any run: per-face arrays (``.npz`` or ``.csv``) or UV textures on a mesh with UVs
plus a lat-long environment map (what nvdiffrec-like tools write).

Per-face albedo from a texture is its area average over each face's UV triangle. When the
textured mesh is not the dataset's (another face count, or faces elsewhere), each dataset
face takes the texture at the nearest point of the other mesh's surface to its centroid.
The light becomes the estimate's pseudo illumination: the envmap's radiance SH filtered by
the Phong lobe of ``exponent`` (a mirror: 10000), in the unit-DC gauge.
"""
from __future__ import annotations

import csv
import os
import zipfile

import numpy as np

from estimator import sh
from estimator.config import EstimatorConfig
from estimator.data import Estimate, TriangleMesh
from estimator.errors import InputError

from harness.io.images import read_linear_rgb
from harness.io.mesh import load_mesh_with_uv

FORMATS = ("per-face", "uv-textures")
CHANNELS = ("r", "g", "b")


def _floats(where: str, value) -> np.ndarray:
    try:
        array = np.asarray(value)
        if not (np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)):
            raise TypeError(array.dtype)
        return array.astype(np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{where} must hold real numbers, got {np.asarray(value).dtype}") from None


def _per_face_array(where: str, value, num_faces: int) -> np.ndarray:
    array = _floats(where, value)
    if array.shape != (num_faces, 3):
        raise InputError(f"{where} must be ({num_faces}, 3) for the dataset's {num_faces} faces, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"{where} contains NaN or Inf")
    return array


def read_per_face(path: str, num_faces: int) -> dict:
    """Per-face arrays of another method.

    ``.npz``: ``diffuse`` (F, 3); optional ``specular`` (F, 3), ``radiance_sh`` or
    ``pseudo_sh`` ((L+1)^2, 3). ``.csv``: a header with ``diffuse_r, diffuse_g, diffuse_b``
    and optionally ``specular_r, specular_g, specular_b``; one row per face, in mesh order.
    Returns a dict with those keys (absent ones None).
    """
    if not os.path.isfile(path):
        raise InputError(f"per-face file not found: {path}")
    out = {"diffuse": None, "specular": None, "radiance_sh": None, "pseudo_sh": None}
    if path.lower().endswith(".npz"):
        try:
            with np.load(path, allow_pickle=False) as archive:
                data = {k: archive[k] for k in archive.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile):
            raise InputError(f"{path}: unreadable (not a .npz archive)") from None
        if "diffuse" not in data:
            raise InputError(f"{path}: key 'diffuse' missing (per-face (F, 3) albedo)")
        for key in ("diffuse", "specular"):
            if key in data:
                out[key] = _per_face_array(f"{path}: {key}", data[key], num_faces)
        for key in ("radiance_sh", "pseudo_sh"):
            if key in data:
                coeffs = _floats(f"{path}: {key}", data[key])
                if coeffs.ndim != 2 or len(coeffs) == 0 or coeffs.shape[1] != 3 or int(np.sqrt(len(coeffs))) ** 2 != len(coeffs) \
                        or not np.all(np.isfinite(coeffs)):
                    raise InputError(f"{path}: {key} must be finite ((L+1)^2, 3), got {coeffs.shape}")
                out[key] = coeffs
        return out
    if path.lower().endswith(".csv"):
        try:
            with open(path, newline="", encoding="utf-8-sig") as f:
                rows = list(csv.DictReader(f))
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise InputError(f"{path}: unreadable CSV ({exc})") from None
        for component in ("diffuse", "specular"):
            columns = [f"{component}_{c}" for c in CHANNELS]
            if rows and all(c in rows[0] for c in columns):
                try:
                    values = [[float(r[c]) for c in columns] for r in rows]
                except (TypeError, ValueError):
                    raise InputError(f"{path}: {component} columns must hold numbers") from None
                out[component] = _per_face_array(f"{path}: {component}", values, num_faces)
            elif component == "diffuse":
                raise InputError(f"{path}: columns {', '.join(columns)} missing")
        return out
    raise InputError(f"{path}: per-face results must be .npz or .csv")


def face_values_from_texture(mesh: TriangleMesh, textured: TriangleMesh, uv: np.ndarray, texture: np.ndarray
                             ) -> np.ndarray:
    """(F, C) per-face values of ``texture`` (H, W, C) on ``textured`` (with per-vertex ``uv``)
    for the faces of ``mesh``: the area average over each face when the two meshes have the
    same faces (count and centroids), else the value at the UV centroid of the other mesh's face
    whose centroid is nearest (a point sample, not an area average)."""
    from harness.scene.textures import sample_uv, uv_texture_average

    if textured.num_faces == mesh.num_faces:
        scale = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
        if np.max(np.linalg.norm(textured.centroids - mesh.centroids, axis=1)) <= 1e-6 * max(scale, 1e-300):
            return uv_texture_average(textured, uv, texture)
    from scipy.spatial import cKDTree

    nearest = cKDTree(textured.centroids).query(mesh.centroids)[1]
    return sample_uv(texture, uv[textured.faces[nearest]].mean(axis=1))


def read_uv_textures(mesh: TriangleMesh, mesh_path: str, diffuse_path: str, specular_path: str | None = None,
                     envmap_path: str | None = None, order: int = 10) -> dict:
    """Per-face albedos from UV textures (PNG/JPEG taken as sRGB, EXR/HDR linear) on a mesh
    file with texture coordinates, and the radiance SH of a lat-long envmap (Mitsuba's
    orientation), for the dataset's ``mesh``."""
    textured, uv = load_mesh_with_uv(mesh_path)
    if uv is None:
        raise InputError(f"{mesh_path}: the mesh has no per-vertex texture coordinates")
    out = {"diffuse": None, "specular": None, "radiance_sh": None, "pseudo_sh": None}
    for key, path in (("diffuse", diffuse_path), ("specular", specular_path)):
        if path:
            values = face_values_from_texture(mesh, textured, uv, read_linear_rgb(path))
            if not np.all(np.isfinite(values)):
                raise InputError(f"{path}: the texture (or the mesh's UVs) gives NaN or Inf albedos")
            out[key] = values
    if envmap_path:
        image = read_linear_rgb(envmap_path)
        if not np.all(np.isfinite(image)):
            raise InputError(f"{envmap_path}: the environment map holds NaN or Inf")
        if image.shape[0] < 3 or image.shape[1] != 2 * image.shape[0]:
            raise InputError(f"{envmap_path}: a lat-long map is twice as wide as high and at least 3 rows, got "
                             f"{image.shape[1]}x{image.shape[0]}")
        out["radiance_sh"] = sh.project_latlong(order, image)
    return out


def imported_estimate(arrays: dict, num_faces: int, source: str, exponent: float = 10000.0,
                      config: EstimatorConfig | None = None) -> Estimate:
    """An :class:`Estimate` of imported arrays (see :func:`read_per_face`), in the estimator's
    gauge: the pseudo illumination (given, or the radiance filtered by the Phong lobe of
    ``exponent``; a constant light when neither is given) has unit DC per channel, and the
    albedos carry its scale."""
    config = config or EstimatorConfig()
    if not 0 < exponent <= 1e6:
        raise InputError(f"--exponent must lie in (0, 1e6], got {exponent}")
    diffuse = arrays["diffuse"]
    specular = arrays["specular"] if arrays["specular"] is not None else np.zeros_like(diffuse)
    m = sh.num_coeffs(config.sh_order)
    pseudo = np.zeros((m, 3))
    if arrays.get("pseudo_sh") is not None:
        given = arrays["pseudo_sh"]
    elif arrays.get("radiance_sh") is not None:   # the DC is kept: the albedos take it below
        given = sh.phong_filtered(arrays["radiance_sh"][: m], exponent)
    else:
        given = np.array([[1.0, 1.0, 1.0]])
    k = min(m, len(given))
    pseudo[:k] = given[:k]
    dc = pseudo[0]
    if np.any(dc <= 0):
        raise InputError(f"{source}: the light's mean (DC) must be positive per channel, got {dc}")
    observed = np.isfinite(diffuse).all(axis=1)
    info = {"imported_from": source, "clusters": int(num_faces)}
    with np.errstate(over="ignore", invalid="ignore"):
        finite = all(np.all(np.isfinite(a)) for a in (diffuse * dc, specular * dc, pseudo / dc))
    if not finite:
        raise InputError(f"{source}: the albedos times the light's DC overflow (values too large)")
    return Estimate(diffuse * dc, specular * dc, pseudo / dc, np.where(observed, np.arange(num_faces), -1),
                    observed, f"imported-{source.split(':')[0]}", config, info)
