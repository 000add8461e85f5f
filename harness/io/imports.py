"""Other tools' results as pseudolight estimates, so ``report`` and ``compare`` score them
like any run: per-face arrays (``.npz`` or ``.csv``) or UV textures on a mesh with UVs
plus a lat-long environment map (what nvdiffrec-like tools write), or a Mitsuba 3 scene XML
whose mesh shape has a ``diffuse``, ``plastic``, ``roughplastic`` or ``principled`` BSDF
(or a ``blendbsdf`` of those with a ``conductor``) with bitmap textures, and an ``envmap``.

Per-face albedo from a texture is its area average over each face's UV triangle. When the
textured mesh is not the dataset's (another face count, or faces elsewhere), each dataset
face takes the texture at the nearest point of the other mesh's surface to its centroid.
The light becomes the estimate's pseudo illumination: the envmap's radiance SH filtered by
the Phong lobe of ``exponent`` (a mirror: 10000), in the unit-DC gauge.
"""
from __future__ import annotations

import csv
import os
import xml.etree.ElementTree as ET

import numpy as np

from estimator import Estimate, EstimatorConfig, InputError, TriangleMesh, fresnel_dielectric, sh
from harness.io.arrays import read_npz, real_array
from harness.io.images import read_linear_rgb
from harness.io.mesh import load_mesh_with_uv

FORMATS = ("per-face", "uv-textures", "mitsuba-xml")
CHANNELS = ("r", "g", "b")


def _per_face_array(where: str, value, num_faces: int) -> np.ndarray:
    array = real_array(where, value)
    if array.shape != (num_faces, 3):
        raise InputError(f"{where} must be ({num_faces}, 3) for the dataset's {num_faces} faces, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"{where} contains NaN or Inf")
    return array


def read_per_face(path: str, num_faces: int) -> dict:  # noqa: C901  (one check per key of the format)
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
        data = read_npz(path)
        if "diffuse" not in data:
            raise InputError(f"{path}: key 'diffuse' missing (per-face (F, 3) albedo)")
        for key in ("diffuse", "specular"):
            if key in data:
                out[key] = _per_face_array(f"{path}: {key}", data[key], num_faces)
        for key in ("radiance_sh", "pseudo_sh"):
            if key in data:
                coeffs = real_array(f"{path}: {key}", data[key])
                if (
                    coeffs.ndim != 2
                    or len(coeffs) == 0
                    or coeffs.shape[1] != 3
                    or int(np.sqrt(len(coeffs))) ** 2 != len(coeffs)
                    or not np.all(np.isfinite(coeffs))
                ):
                    raise InputError(f"{path}: {key} must be finite ((L+1)^2, 3), got {coeffs.shape}")
                out[key] = coeffs
        return out
    if path.lower().endswith(".csv"):
        rows, ragged = [], None
        try:
            with open(path, newline="", encoding="utf-8-sig") as f:
                reader = csv.DictReader(f)
                for row in reader:
                    rows.append(row)
                    # DictReader files a row's cells beyond the header under the key None: a shifted row
                    if None in row and ragged is None:
                        ragged = reader.line_num
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise InputError(f"{path}: unreadable CSV ({exc})") from None
        if ragged is not None:
            raise InputError(f"{path}: line {ragged} has more cells than the header names")
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


def face_values_from_texture(mesh: TriangleMesh, textured: TriangleMesh, uv: np.ndarray, texture: np.ndarray,
                             nearest: bool = False) -> np.ndarray:
    """(F, C) per-face values of ``texture`` (H, W, C) on ``textured`` (with per-vertex ``uv``)
    for the faces of ``mesh``: the area average over each face when the two meshes have the
    same faces (count and centroids), else the value at the UV centroid of the other mesh's face
    whose centroid is nearest (a point sample, not an area average). ``nearest``: texel
    lookup without bilinear blending (a texture meant for nearest filtering)."""
    from harness.scene.textures import sample_uv, uv_texture_average

    if textured.num_faces == mesh.num_faces:
        scale = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
        if np.max(np.linalg.norm(textured.centroids - mesh.centroids, axis=1)) <= 1e-6 * max(scale, 1e-300):
            return uv_texture_average(textured, uv, texture, nearest=nearest)
    from scipy.spatial import cKDTree

    closest = cKDTree(textured.centroids).query(mesh.centroids)[1]
    return sample_uv(texture, uv[textured.faces[closest]].mean(axis=1), nearest)


MAX_OFFSET = 0.1   # share of the object's bounding diagonal: farther, the textured mesh is somewhere else


def check_overlap(mesh: TriangleMesh, textured: TriangleMesh, path: str) -> None:
    """Refuse a textured mesh that does not lie on the dataset's: the median distance from a
    face's centroid to the nearest of its centroids must be within :data:`MAX_OFFSET` of the
    object's size (another tessellation of the same surface stays within a face's size)."""
    from scipy.spatial import cKDTree

    diagonal = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    offset = float(np.median(cKDTree(textured.centroids).query(mesh.centroids)[0]))
    if offset > MAX_OFFSET * diagonal:
        raise InputError(f"{path}: the textured mesh does not lie on the dataset's mesh (its faces are a median "
                         f"{offset:.3g} away, {100 * offset / max(diagonal, 1e-300):.0f} % of the object's size); "
                         "check its scale, placement and axes")


def _texture_faces(mesh: TriangleMesh, textured: TriangleMesh, uv: np.ndarray, path: str, raw: bool = False,
                   nearest: bool = False, alpha: bool = False) -> np.ndarray:
    """(F, 3) per-face values of the texture at ``path``. With ``alpha``, NaN (unestimated) for
    a face whose texels are mostly transparent: ``export-texture`` marks the faces an estimate
    left unestimated with alpha 0 (a Mitsuba bitmap's alpha is no part of an albedo)."""
    values = face_values_from_texture(mesh, textured, uv, read_linear_rgb(path, raw, alpha=alpha), nearest)
    if not np.all(np.isfinite(values)):
        raise InputError(f"{path}: the texture (or the mesh's UVs) gives NaN or Inf albedos")
    if values.shape[1] == 4:
        values = np.where(values[:, 3:] >= 0.5, values[:, :3], np.nan)
    return values


def _envmap_sh(path: str, order: int) -> np.ndarray:
    """(M, 3) radiance SH of a lat-long map in Mitsuba's envmap orientation."""
    image = read_linear_rgb(path)
    if not np.all(np.isfinite(image)):
        raise InputError(f"{path}: the environment map holds NaN or Inf")
    if image.shape[0] < 3 or image.shape[1] != 2 * image.shape[0]:
        raise InputError(f"{path}: a lat-long map is twice as wide as high and at least 3 rows, got "
                         f"{image.shape[1]}x{image.shape[0]}")
    return sh.project_latlong(order, image)


def read_uv_textures(mesh: TriangleMesh, mesh_path: str, diffuse_path: str, specular_path: str | None = None,
                     envmap_path: str | None = None, order: int = 10) -> dict:
    """Per-face albedos from UV textures (PNG/JPEG taken as sRGB, EXR/HDR linear) on a mesh
    file with texture coordinates, and the radiance SH of a lat-long envmap (Mitsuba's
    orientation), for the dataset's ``mesh``."""
    textured, uv = load_mesh_with_uv(mesh_path)
    if uv is None:
        raise InputError(f"{mesh_path}: the mesh has no per-vertex texture coordinates")
    check_overlap(mesh, textured, mesh_path)
    out = {"diffuse": None, "specular": None, "radiance_sh": None, "pseudo_sh": None}
    for key, path in (("diffuse", diffuse_path), ("specular", specular_path)):
        if path:
            out[key] = _texture_faces(mesh, textured, uv, path, alpha=True)
    if out["diffuse"] is not None and out["specular"] is not None:   # unestimated in either map: in both
        missing = np.isnan(out["diffuse"]).any(axis=1) | np.isnan(out["specular"]).any(axis=1)
        out["diffuse"][missing] = out["specular"][missing] = np.nan
    if envmap_path:
        out["radiance_sh"] = _envmap_sh(envmap_path, order)
    return out


# Mitsuba BSDFs and the property that holds their diffuse albedo
DIFFUSE_PROPERTY = {"diffuse": "reflectance", "plastic": "diffuse_reflectance",
                    "roughplastic": "diffuse_reflectance", "principled": "base_color"}
MIRRORS = ("conductor", "roughconductor")
COATED = ("plastic", "roughplastic")


def xml_referenced_files(path: str) -> list[str]:
    """Every file a Mitsuba scene XML names (``<string name="filename">``), resolved from its
    folder: inputs of an import, which its output must never replace. [] when the XML cannot be
    parsed (reading it then fails with its own message, before anything is written)."""
    folder = os.path.dirname(os.path.abspath(path))
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError):
        return []
    return [os.path.join(folder, e.get("value")) for e in root.iter("string")
            if e.get("name") == "filename" and e.get("value")]


def read_mitsuba_xml(mesh: TriangleMesh, path: str, order: int = 10) -> dict:  # noqa: C901  (one check per element)
    """Per-face albedos and the radiance SH of a Mitsuba 3 scene XML, for the dataset's ``mesh``.

    The scene's first ``ply``/``obj`` shape with a BSDF is read (its ``to_world`` matrix
    applied): ``diffuse``, ``plastic``, ``roughplastic`` (the specular albedo the coat's
    Fresnel reflectance at normal incidence times its ``specular_reflectance``, the ground
    truth's convention) or ``principled`` (``base_color``), inside ``twosided`` or as a
    ``blendbsdf`` of constant ``weight`` w whose first child contributes (1 - w) x its
    albedo and second w x its albedo (a ``conductor``/``roughconductor`` child is the
    specular albedo: its ``specular_reflectance``). Albedos are ``bitmap`` textures (relative
    paths from the XML's folder; 8-bit files are sRGB unless ``raw``; a PLY's v runs top-down
    as Mitsuba reads it, an OBJ's bottom-up) or constant ``rgb`` / ``float`` values. The light is
    the first ``envmap`` emitter (``scale`` and the rotation
    of ``to_world`` applied) or ``constant`` emitter.
    """
    folder = os.path.dirname(os.path.abspath(path))
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise InputError(f"{path}: not a readable XML file ({exc})") from None
    if root.tag != "scene":
        raise InputError(f"{path}: the root element is <{root.tag}>, not a Mitsuba <scene>")
    by_id = {e.get("id"): e for e in root.iter() if e.get("id")}

    def resolve(element):
        if element is not None and element.tag == "ref":
            target = by_id.get(element.get("id"))
            if target is None:
                raise InputError(f"{path}: <ref id={element.get('id')!r}> names no element")
            return target
        return element

    def child_bsdf(element):
        return resolve(next((c for c in element if c.tag in ("bsdf", "ref")), None))

    shape = next((s for s in root.findall("shape") if s.get("type") in ("ply", "obj") and child_bsdf(s) is not None),
                 None)
    if shape is None:
        raise InputError(f"{path}: no <shape type='ply'|'obj'> with a BSDF")
    filename = _xml_value(shape, "string", "filename", path)
    textured, uv = load_mesh_with_uv(os.path.join(folder, filename))
    if uv is None:
        raise InputError(f"{filename}: the mesh has no per-vertex texture coordinates")
    if shape.get("type") == "ply":   # Mitsuba uses a PLY's v as stored, top-down (its OBJ loader flips v)
        uv = np.column_stack([uv[:, 0], 1.0 - uv[:, 1]])
    matrix = _xml_matrix(shape, path)
    if matrix is not None:
        textured = TriangleMesh(textured.vertices @ matrix[:3, :3].T + matrix[:3, 3], textured.faces)
    check_overlap(mesh, textured, os.path.join(folder, filename))
    bsdf = child_bsdf(shape)
    parts = {"diffuse": np.zeros((mesh.num_faces, 3)), "specular": np.zeros((mesh.num_faces, 3))}
    from_bitmap = set()   # the parts a bitmap feeds (a constant part is one colour by right)

    def albedo(element, name, default, part):
        """(F, 3) per-face values of property ``name`` of ``element``, which feed ``part``."""
        for child in element:
            if child.get("name") != name:
                continue
            if child.tag == "texture" and child.get("type") == "bitmap":
                from_bitmap.add(part)
                raw = child.find("boolean[@name='raw']")
                nearest = child.find("string[@name='filter_type']")
                return _texture_faces(
                    mesh,
                    textured,
                    uv,
                    os.path.join(folder, _xml_value(child, "string", "filename", path)),
                    raw is not None and raw.get("value") == "true",
                    nearest is not None and nearest.get("value") == "nearest",
                )
            if child.tag in ("rgb", "float"):
                return np.tile(_xml_floats(child, path, 3), (mesh.num_faces, 1))
            raise InputError(f"{path}: {element.get('type')}.{name} is a <{child.tag} type={child.get('type')!r}>; "
                             "only bitmap textures and rgb/float values are read")
        return np.full((mesh.num_faces, 3), default)

    def coat_ior(element) -> float:
        """A plastic's relative index int_ior / ext_ior (Mitsuba's defaults 1.49 and air's,
        taken as 1 as the ground truth does), given as numbers."""
        values = []
        for name, default in (("int_ior", 1.49), ("ext_ior", 1.0)):
            if element.find(f"string[@name='{name}']") is not None:
                raise InputError(f"{path}: {element.get('type')}.{name} is a material name; give it as a <float>")
            found = element.find(f"float[@name='{name}']")
            values.append(default if found is None else float(_xml_floats(found, path, 1)[0]))
        if not (values[0] > 0 and values[1] > 0 and values[0] != values[1]):
            raise InputError(f"{path}: {element.get('type')} needs int_ior and ext_ior > 0 and unequal, got {values}")
        return values[0] / values[1]

    def add(element, weight):
        kind = element.get("type")
        if kind == "twosided":
            return add(child_bsdf(element), weight)
        if kind == "blendbsdf":
            _xml_value(element, "float", "weight", path)   # present, else named
            w = float(_xml_floats(element.find("float[@name='weight']"), path, 1)[0])
            children = [resolve(c) for c in element if c.tag in ("bsdf", "ref")]
            if len(children) != 2 or not 0 <= w <= 1:
                raise InputError(f"{path}: a blendbsdf needs two BSDFs and a constant weight in [0, 1]")
            add(children[0], weight * (1.0 - w))
            return add(children[1], weight * w)
        if kind in DIFFUSE_PROPERTY:
            parts["diffuse"] += weight * albedo(element, DIFFUSE_PROPERTY[kind], 0.5, "diffuse")
            if kind in COATED:   # the coat's reflectance at normal incidence, as the ground truth records it
                parts["specular"] += weight * float(fresnel_dielectric(1.0, coat_ior(element))) * albedo(
                    element, "specular_reflectance", 1.0, "specular")
        elif kind in MIRRORS:
            parts["specular"] += weight * albedo(element, "specular_reflectance", 1.0, "specular")
        else:
            raise InputError(f"{path}: BSDF type {kind!r} is not read; use diffuse, plastic, roughplastic, principled, "
                             "conductor or roughconductor (a specular albedo alone), or a blendbsdf of those")

    add(bsdf, 1.0)
    out = {**parts, "radiance_sh": None, "pseudo_sh": None, "textured": sorted(from_bitmap)}
    for emitter in root.findall("emitter"):
        if emitter.get("type") == "envmap":
            radiance = _envmap_sh(os.path.join(folder, _xml_value(emitter, "string", "filename", path)), order)
            scale = emitter.find("float[@name='scale']")
            factor = float(_xml_floats(scale, path, 1)[0]) if scale is not None else 1.0
            if not 0 <= factor <= MAX_XML_SCALE:
                raise InputError(f"{path}: <float name='scale'> of the envmap must lie in [0, {MAX_XML_SCALE:g}], "
                                 f"got {factor:g}")
            radiance = radiance * factor
            matrix = _xml_matrix(emitter, path)
            if matrix is not None:
                radiance = sh.rotation_matrix(order, matrix[:3, :3]) @ radiance
            out["radiance_sh"] = radiance
            break
        if emitter.get("type") == "constant":
            value = emitter.find("*[@name='radiance']")
            out["radiance_sh"] = np.zeros((sh.num_coeffs(order), 3))
            out["radiance_sh"][0] = 2.0 * np.sqrt(np.pi) * (_xml_floats(value, path, 3) if value is not None else 1.0)
            break
    return out


MAX_XML_SCALE = 1e12   # an envmap scale beyond it overflows the light's float64 SH products


def _xml_value(element, tag: str, name: str, path: str) -> str:
    found = element.find(f"{tag}[@name='{name}']")
    if found is None or found.get("value") is None:
        raise InputError(f"{path}: <{element.tag} type={element.get('type')!r}> has no <{tag} name={name!r}>")
    return found.get("value")


def _xml_floats(element, path: str, count: int) -> np.ndarray:
    try:
        values = np.array([float(v) for v in element.get("value", "").replace(",", " ").split()])
    except ValueError:
        values = np.zeros(0)
    if len(values) == 1:
        values = np.repeat(values, count)
    if len(values) != count or not np.all(np.isfinite(values)):
        raise InputError(f"{path}: <{element.tag} name={element.get('name')!r}> must hold {count} finite numbers")
    return values


def _xml_matrix(element, path: str) -> np.ndarray | None:
    """The 4x4 of a ``to_world`` transform given as one <matrix>, None when absent."""
    transform = element.find("transform[@name='to_world']")
    if transform is None:
        return None
    children = list(transform)
    if len(children) != 1 or children[0].tag != "matrix":
        raise InputError(f"{path}: only a to_world given as one <matrix> is read")
    return _xml_floats(children[0], path, 16).reshape(4, 4)


def import_warnings(arrays: dict, components: str = "both") -> list[str]:
    """What an import may have read wrong, one line each: an albedo black or of one colour on
    every face (an empty or unread texture; a component the dataset's ``components`` leaves
    out, 'diffuse' or 'specular', is black by right, and where ``arrays['textured']`` names the
    parts a texture fed, the others are constants by right), and no light at all (the estimate then
    holds a constant one, which the reports compare as if it were the method's)."""
    out = []
    checked = {"diffuse": ("diffuse",), "specular": ("specular",)}.get(components, ("diffuse", "specular"))
    for name in [n for n in checked if n in arrays.get("textured", checked)]:
        values = arrays.get(name)
        if values is None:
            continue
        known = values[np.isfinite(values).all(axis=1)]
        if not len(known):
            continue
        if np.all(np.abs(known) <= 1e-6):
            out.append(f"the imported {name} albedo is black on every face: an empty or unread texture?")
        elif np.all(np.ptp(known, axis=0) <= 1e-6 * np.abs(known).max()):
            out.append(f"the imported {name} albedo is one colour on every face ({known[0].round(4).tolist()}): "
                       "a texture that did not map onto the mesh?")
    if arrays.get("radiance_sh") is None and arrays.get("pseudo_sh") is None:
        out.append("no light imported: the estimate holds a constant light, and the report's illumination "
                   "figures score that constant, not the method's light")
    return out


# an imported albedo may carry any global scale (the reports fit one), but one above this is no
# reflectance in any unit: its squared errors overflow the reports' sums
MAX_IMPORTED_ALBEDO = 1e6


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
    for name, values in (("diffuse", diffuse), ("specular", specular)):
        known = values[np.isfinite(values).all(axis=1)]
        if np.any(known < 0) or np.any(known > MAX_IMPORTED_ALBEDO):
            worst = int(np.argmax(np.any((values < 0) | (values > MAX_IMPORTED_ALBEDO), axis=1)))
            raise InputError(f"{source}: {name} albedo of face {worst} is {values[worst].tolist()}: an albedo is a "
                             f"reflectance, >= 0 (and at most {MAX_IMPORTED_ALBEDO:g} in any unit its light's "
                             "scale allows)")
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
    # an imported result carries no grouping of its own: faces of identical albedos are one group
    labels = np.full(num_faces, -1, dtype=np.int64)
    labels[observed] = np.unique(np.hstack([diffuse, specular])[observed], axis=0, return_inverse=True)[1].ravel()
    info = {"imported_from": source, "clusters": int(labels.max() + 1)}
    with np.errstate(over="ignore", invalid="ignore"):   # unestimated faces (NaN: transparent texels) hold 0
        scaled = tuple(np.where(observed[:, None], a * dc, 0.0) for a in (diffuse, specular))
        finite = all(np.all(np.isfinite(a)) for a in scaled) and np.all(np.isfinite(pseudo / dc))
    if not finite or any(np.any(a > MAX_IMPORTED_ALBEDO) for a in scaled):
        raise InputError(f"{source}: the albedos times the light's mean (DC) {dc.tolist()} exceed "
                         f"{MAX_IMPORTED_ALBEDO:g} (the light's scale is too large for a reflectance)")
    return Estimate(scaled[0], scaled[1], pseudo / dc, labels, observed, f"imported-{source.split(':')[0]}",
                    config, info)
