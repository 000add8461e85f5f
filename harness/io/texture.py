"""An estimate as texture maps: a UV atlas, baked diffuse and specular textures
(PNG sRGB and EXR linear), OBJ + MTL, glTF 2.0 binary and the light as a lat-long EXR.

The per-face albedo is constant over each face, so baking is exact: every texel a
face covers takes the face's value, and the empty texels around the charts take
the value of the nearest covered texel (dilation across seams, so that filtering
and mip-mapping do not bleed the background into the object).
"""
from __future__ import annotations

import json
import os

import numpy as np
from scipy import ndimage

from estimator import Estimate, InputError, TriangleMesh, sh, uv_atlas
from harness.io.exr import write_exr
from reports.metrics import srgb_encode


def bake(faces: np.ndarray, uv: np.ndarray, values: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-face values (F, C) into a (size, size, C) texture over the UV layout.

    Each face is splatted at barycentric sample points dense enough for its texel
    footprint, then its centroid last (a face's centroid texel is its own); empty
    texels take their nearest covered texel. Row 0 is v = 1 (image convention).

    Returns (texture (size, size, C) float32, covered (size, size) bool).
    """
    corners = uv[faces]                                                      # (F, 3, 2)
    extent = np.ptp(corners, axis=1).max(axis=1) * size                     # texels across each face
    k = int(np.clip(np.ceil(2 * np.percentile(extent, 99)), 2, 32))
    i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
    keep = i + j <= k
    bary = np.column_stack([i[keep], j[keep], k - i[keep] - j[keep]]) / k    # (S, 3)
    texture = np.zeros((size, size, values.shape[1]), np.float32)
    covered = np.zeros((size, size), bool)
    for weights in (bary, np.full((1, 3), 1 / 3)):                          # samples, then centroids
        points = np.einsum("sk,fkd->fsd", weights, corners).reshape(-1, 2)
        col = np.clip((points[:, 0] * size).astype(np.int64), 0, size - 1)
        row = np.clip(((1.0 - points[:, 1]) * size).astype(np.int64), 0, size - 1)
        face = np.repeat(np.arange(len(faces)), len(weights))
        texture[row, col] = values[face]
        covered[row, col] = True
    if not covered.all():
        _, (rows, cols) = ndimage.distance_transform_edt(~covered, return_indices=True)
        texture = texture[rows, cols]
    return texture, covered


def sample(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Nearest-texel lookup of (size, size, C) at uv (N, 2) -> (N, C), :func:`bake`'s layout."""
    size = texture.shape[0]
    col = np.clip((uv[:, 0] * size).astype(np.int64), 0, size - 1)
    row = np.clip(((1.0 - uv[:, 1]) * size).astype(np.int64), 0, size - 1)
    return texture[row, col]


def srgb8(linear: np.ndarray) -> np.ndarray:
    """Linear [0, 1] -> 8-bit sRGB (clipped)."""
    return np.round(srgb_encode(linear) * 255.0).astype(np.uint8)


# both albedo maps and the alpha as one float32 map of 8192^2, their 8-bit copies, the rasteriser's
# buffers: 6.1 GiB peak
MAX_SIZE = 8192


def material_mtl(png_scale: dict, exponent: float) -> str:
    """The OBJ material of an exported estimate: ``map_Kd diffuse.png`` and ``map_Ks
    specular.png`` with ``Kd``/``Ks`` undoing each PNG's scale (viewers multiply the map by
    the factor, so map x factor is the albedo), ``Ns`` the Phong exponent of the estimate's
    specular lobe (the paper's mirror model is the limit of a large one)."""
    kd, ks = (1.0 / png_scale[name] for name in ("diffuse", "specular"))
    return ("# pseudolight estimate: Kd x map_Kd = diffuse albedo, Ks x map_Ks = specular albedo (linear; the PNGs\n"
            "# are sRGB-encoded, diffuse.exr and specular.exr hold the linear values)\n"
            "newmtl estimate\nKa 0 0 0\n"
            f"Kd {kd:.6g} {kd:.6g} {kd:.6g}\nKs {ks:.6g} {ks:.6g} {ks:.6g}\nNs {min(float(exponent), 1000.0):.6g}\n"
            "map_Kd diffuse.png\nmap_Ks specular.png\n")


def export_textures(folder: str, mesh: TriangleMesh, est: Estimate, uv: np.ndarray | None = None,
                    size: int = 1024) -> dict:
    """Write the estimate's texture maps, meshes and light into ``folder`` (which must exist).

    Files: ``diffuse.{png,exr}``, ``specular.{png,exr}``, ``mesh.obj`` + ``material.mtl``
    (:func:`material_mtl`: both maps), ``mesh.glb`` (the diffuse map as base colour, metallic
    0, roughness 1: glTF's metallic-roughness model has no Phong specular albedo, which
    stays in ``specular.*`` and the MTL), ``radiance.exr`` and ``texture.json`` (scales and
    counts; ``radiance.from`` names the light in ``radiance.exr``). The PNGs are
    8-bit sRGB of the albedo times ``png_scale`` (so the brightest 0.5 % saturate at most:
    the estimate's albedo is in the light's unit-DC gauge, not bounded by 1); the EXRs are
    the linear albedo itself. Both carry an alpha channel, 0 on the texels of faces the estimate
    left unestimated (their colour 0 is no albedo; ``texture.json`` counts them, and
    ``import --from uv-textures`` reads them back as unestimated). The mesh's own UVs are used when
    they lie in [0, 1]; otherwise (UDIM tiles, tiling) the mesh is unwrapped with xatlas, as
    one texture cannot hold several tiles.
    """
    import trimesh
    from PIL import Image

    if size < 16 or size > MAX_SIZE:
        raise InputError(f"--size must lie in [16, {MAX_SIZE}], got {size}")
    source = "mesh" if uv is not None else "xatlas"
    if uv is not None and not (np.all(np.isfinite(uv)) and uv.min() >= 0.0 and uv.max() <= 1.0):
        # UDIM tiles or tiling UVs would overlap in one [0, 1] texture: unwrap instead
        uv, source = None, "xatlas (the mesh's own UVs leave [0, 1]: UDIM tiles or tiling)"
    vertices, faces, uvs = uv_atlas(mesh, uv)
    summary = {"faces": int(len(faces)), "vertices": int(len(vertices)), "size": int(size),
               "uv_source": source, "png_scale": {}, "unestimated_faces": int((~est.observed).sum())}
    images = {}
    albedos = {name: np.where(est.observed[:, None], getattr(est, name), 0.0) for name in ("diffuse", "specular")}
    # one splat for both maps and the estimated faces' alpha (1 or 0 per texel)
    baked, covered = bake(faces, uvs, np.hstack([albedos["diffuse"], albedos["specular"],
                                                 est.observed[:, None]]), size)
    estimated = baked[..., 6]
    summary["covered_share"] = float(covered.mean())
    for k, (name, values) in enumerate(albedos.items()):
        texture = baked[..., 3 * k:3 * k + 3]
        top = float(np.percentile(values[est.observed], 99.5)) if est.observed.any() else 1.0
        scale = 1.0 / top if top > 1.0 else 1.0
        write_exr(os.path.join(folder, f"{name}.exr"), np.dstack([texture, estimated]))
        images[name] = Image.fromarray(np.dstack([srgb8(texture * scale), (255 * estimated).astype(np.uint8)]))
        images[name].save(os.path.join(folder, f"{name}.png"))
        summary["png_scale"][name] = scale
    light = est.radiance_sh if est.radiance_sh is not None else est.pseudo_sh
    env = sh.to_latlong(light, 128, 256)
    write_exr(os.path.join(folder, "radiance.exr"), np.maximum(env, 0.0))
    summary["radiance"] = {"from": "radiance_sh" if est.radiance_sh is not None else "pseudo_sh (no radiance model)",
                           "clamped_negative_share": float(np.mean(env < 0))}
    material = trimesh.visual.material.PBRMaterial(name="estimate", baseColorTexture=images["diffuse"],
                                                   metallicFactor=0.0, roughnessFactor=1.0)
    textured = trimesh.Trimesh(vertices, faces, process=False,
                               visual=trimesh.visual.TextureVisuals(uv=uvs, material=material))
    textured.export(os.path.join(folder, "mesh.glb"))
    simple = trimesh.visual.material.SimpleMaterial(name="estimate", image=images["diffuse"])
    obj_mesh = trimesh.Trimesh(vertices, faces, process=False,
                               visual=trimesh.visual.TextureVisuals(uv=uvs, material=simple))
    obj_mesh.export(os.path.join(folder, "mesh.obj"), mtl_name="material.mtl")   # vt, mtllib and usemtl lines
    os.remove(os.path.join(folder, "estimate.png"))   # trimesh's copy of diffuse.png; the MTL names both maps
    with open(os.path.join(folder, "material.mtl"), "w") as f:
        f.write(material_mtl(summary["png_scale"], est.config.phong_exponent))
    with open(os.path.join(folder, "texture.json"), "w") as f:
        json.dump(summary, f, indent=1)
    return summary
