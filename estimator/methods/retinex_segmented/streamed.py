"""``retinex-segmented`` on a problem too large to hold its rows (:attr:`Prepared.streamed`).

The light, its sun, the coat's reflection and whether the faces form uniform regions are found
on a sub-mesh of contiguous patches whose rows are held (:func:`patch_faces`); every face's
albedo then follows with that light fixed, as the held solve divides radiance by shading,
from rows computed in chunks. The light has a few hundred unknowns, which tens of thousands
of faces determine many times over; the albedos are per face and need every face."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from ...core import sh
from ...core.errors import InputError
from ...core.reductions import group_quantile
from ...light import coat, indirect, sun
from ...model.estimate import Estimate
from ...pipeline.prepared import Prepared
from ...solvers.segmentation import MIN_UNIFORM_FACES, assign_to_regions, segment, split_regions
from .result import to_estimate
from .shading import divide_shade, in_unit_dc
from .values import FitContext, LightSource, ReflectionFits, Solution

# a patch holds ten of the smallest components the segmentation calls uniform, so that the
# regions a patch's border cuts are few against those it holds whole
PATCH_FACES = 10 * MIN_UNIFORM_FACES

# what the estimate of the whole mesh keeps from the sub-problem's: how its light was chosen
CARRIED = ("hypotheses", "coat_weight", "coat_costs", "reflection_explained", "lobe_explained")


def patch_faces(centroids: np.ndarray, observed: np.ndarray, count: int, patches: int, seed: int = 0) -> np.ndarray:
    """(S,) sorted faces: ``patches`` patches of about ``count / patches`` faces each, the
    faces of ``observed`` (O,) whose centroids (F, 3) lie nearest to one of them drawn at
    random (``seed``); every observed face when there are at most ``count``.

    A patch keeps each face's neighbours, which the edge fit and the regions need (faces drawn
    one by one would have none); spread over the object, the patches' normals see the light
    from many sides."""
    if len(observed) <= count:
        return np.sort(observed)
    centres = np.random.default_rng(seed).choice(observed, min(patches, count), replace=False)
    _, near = cKDTree(centroids[observed]).query(centroids[centres], k=max(1, count // len(centres)))
    return np.unique(observed[np.reshape(near, -1)])


def solve_streamed(method, prep: Prepared) -> Estimate:
    """The estimate of ``method`` (a :class:`RetinexSegmented`) on the streamed problem
    ``prep``: its held solve on ``config.light_faces`` faces in as many patches as the light has
    coefficients (fewer where a patch would hold under :data:`PATCH_FACES` faces), then
    :func:`extend` to every face."""
    c = method.config
    if c.coat_per_region:
        raise InputError("coat_per_region ties a coat to each uniform region of the sub-mesh a streamed problem's "
                         "light is found on, which the other faces do not share: set coat_per_region=false, or "
                         "raise dense_rows so that the rows are held")
    patches = max(1, min(sh.num_coeffs(method.model.order), c.light_faces // PATCH_FACES))
    faces = patch_faces(prep.data.mesh.centroids, np.nonzero(prep.obs.observed_faces())[0], c.light_faces, patches)
    method.log(f"streamed: the light from {len(faces)} faces in {patches} patches")
    part = method.solve_held(prep.sub_mesh(faces))
    est = extend(method, prep, part)
    est.info.update({k: part.estimate.info[k] for k in CARRIED if k in part.estimate.info})
    est.info["light_faces"] = int(len(faces))
    return est


def extend(method, prep: Prepared, part: Solution) -> Estimate:
    """The estimate of every face of ``prep`` under the light of ``part`` (a sub-problem's
    :class:`Solution`): its coat's reflection subtracted from every observation, each face's
    diffuse radiance (the ``retinex_quantile``) over its shading under that light (its sun's
    shadowed column, and the light the object reflects onto it with ``interreflection``);
    where the sub-problem tied uniform regions, the regions are found again on the whole
    mesh under that light (faces near a region in albedo join it, as in
    :func:`.edges.tied_regions`) and each takes its faces' median albedo."""
    c, h, model = method.config, part.hypothesis, method.model
    mesh, obs = prep.data.mesh, prep.obs
    if part.coat is not None:
        rows = coat.coat_rows(mesh.face_normals[obs.face], obs.view_dir, part.coat.light, c.coat_order, c.coat_ior)
        obs = replace(obs, rgb=obs.rgb - part.coat.weight[0] * rows)
        prep = replace(prep, obs=obs)
    f = mesh.num_faces
    radiance = group_quantile(obs.face, obs.rgb, f, c.retinex_quantile)
    sees_sky = np.any(prep.visibility.bits != 0, axis=1)    # the held solve's "DC shading > 0"
    usable = np.all(np.isfinite(radiance) & (radiance > 0), axis=1) & sees_sky
    m = sh.num_coeffs(model.order)
    shade = prep.shading(h.light[:m], h.shading.coat_ior)
    if h.shading.sun is not None:
        column = sun.sun_shading(mesh, prep.caster, h.shading.sun.direction, h.shading.sun.coat_ior)
        shade = shade + column[:, None] * h.light[m]
    if c.interreflection:
        shade = shade + indirect.indirect_shading(prep.caster, prep.sampling, prep.visibility,
                                                  np.where(usable[:, None], radiance, 0.0))
    albedo, lit = divide_shade(shade, radiance, usable)
    labels, regions = np.full(f, -1, dtype=np.int64), 0
    if h.regions:
        edges = mesh.face_adjacency
        features = in_unit_dc(albedo, h.light)
        labels, _ = segment(np.where(lit[:, None], features, 1.0), edges, lit, c.segment_threshold, c.uniform_spread)
        if h.source is LightSource.EDGES_AND_PARTED_REGIONS:
            labels = split_regions(labels, features, lit, edges, c.segment_threshold, c.uniform_spread)
        regions = int(labels.max()) + 1
        joined = assign_to_regions(labels, features, lit, edges, 2.5 * c.segment_threshold)
        labels = np.where(lit & (joined < regions), joined, -1)
        tied = labels >= 0
        albedo[tied] = group_quantile(labels[tied], albedo[tied], regions, 0.5)[labels[tied]]
    whole = replace(h, radiance=radiance, albedo=albedo, lit=lit, labels=labels, regions=regions)
    ctx = FitContext(prep, c, model, method.loss, ReflectionFits(obs), mesh.face_adjacency, usable)
    return to_estimate(ctx, whole, method)
