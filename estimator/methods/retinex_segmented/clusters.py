"""``retinex-segmented`` on a mesh with more observed faces than ``light_faces`` or denser than
its photos (a dense scan), or a problem too large to hold its rows (:attr:`Prepared.streamed`).

The light, its sun, the coat's reflection and whether the faces form uniform regions are found
on a problem of at most ``light_faces`` clusters of neighbouring faces (:func:`face_clusters`,
:func:`cluster_count`), whose
rows are held: each cluster shows its faces' mean colour per view and touches the clusters its
faces touch, so the edges and regions it sees span the whole object at the scale of a mesh of
that many faces, however dense the mesh (neighbouring faces of a dense mesh see too little of
the light's variation between them). Every face's albedo then follows with that light fixed,
as the held solve divides radiance by shading (from rows computed in chunks when they are
streamed). The light has a few hundred unknowns, which tens of thousands of clusters determine
many times over; the albedos are per face and need every face."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from ...core import sh
from ...core.errors import InputError
from ...core.reductions import group_quantile
from ...light import coat_map, indirect, sun
from ...model.estimate import Estimate
from ...pipeline.prepared import Prepared
from ...solvers.segmentation import assign_to_regions, compact_regions, segment, split_modes, split_regions
from .result import to_estimate
from .shading import divide_shade, in_unit_dc
from .thin import joined_to_regions
from .values import FitContext, LightSource, ReflectionFits, Solution

# a compact patch of A pixels (a square of side s) holds about (s - 1)^2 pixels wholly inside it;
# those pure pixels are at least half of its pixels from s = 1 / (1 - 1 / sqrt 2): A ~ 11.7
RESOLVED_PIXELS = (1.0 / (1.0 - 0.5 ** 0.5)) ** 2

# what the estimate of the whole mesh keeps from the clustered problem's: how its light was chosen
CARRIED = ("hypotheses", "coat_level", "coat_weight", "coat_costs", "coat_degree", "reflection_explained",
           "lobe_explained")


def face_clusters(mesh, observed: np.ndarray, count: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(F,) the cluster of each face (-1 for a face not in ``observed`` (O,)) and (K,) each
    cluster's representative face: ``count`` observed faces drawn at random (``seed``), each
    observed face joining the nearest in position and normal (the normal scaled by a cluster's
    side, sqrt(observed area / count), so that the two sides of a thin wall part); every
    observed face its own cluster when there are at most ``count``."""
    cluster = np.full(mesh.num_faces, -1, dtype=np.int64)
    if len(observed) <= count:
        cluster[observed] = np.arange(len(observed))
        return cluster, np.asarray(observed, dtype=np.int64)
    representative = np.sort(np.random.default_rng(seed).choice(observed, count, replace=False))
    side = np.sqrt(mesh.areas[observed].sum() / count)
    features = np.hstack([mesh.centroids, side * mesh.face_normals])
    cluster[observed] = cKDTree(features[representative]).query(features[observed])[1]
    return cluster, representative


def cluster_count(prep: Prepared, light_faces: int, observed: int) -> int:
    """How many clusters the light is found on: at most ``light_faces``, and on a mesh denser
    than its photos (:attr:`Observations.unresolved`) few enough that a cluster's rows average
    :data:`RESOLVED_PIXELS` pixels each, as a face the images resolve does (half of them pure):
    a footprint of a few pixels mixes its neighbours and the segmentation sees noise where a
    region is uniform. Every observed face is its own cluster when the count reaches theirs
    (``observed``: how many faces have a kept row)."""
    count = min(light_faces, observed)
    pixels = prep.all_obs.footprint_pixels
    if prep.all_obs.unresolved is not None and pixels:
        count = min(count, max(1, int(np.ceil(observed * pixels / RESOLVED_PIXELS))))
    return count


def carried(config) -> str | None:
    """The setting that is not carried from clusters to faces (``coat_per_region``: a coat per
    region of the clusters; ``reflected_lobe``: the lobe's diffuse radiance), or None."""
    return next((name for name in ("coat_per_region", "reflected_lobe") if getattr(config, name)), None)


def solve_on_clusters(method, prep: Prepared, observed: np.ndarray, count: int) -> Estimate:
    """The estimate of ``method`` (a :class:`RetinexSegmented`): its held solve on ``count``
    clusters (:func:`cluster_count`) of the ``observed`` faces (K,) (:meth:`Prepared.clustered`),
    then :func:`extend` to every face; refused with a setting :func:`carried` names."""
    c = method.config
    setting = carried(c)
    if setting:
        raise InputError(f"{setting} is not carried from the clusters a streamed problem's light is found on to "
                         f"its faces: set {setting}=false, or raise dense_rows so that the rows are held")
    cluster, representative = face_clusters(prep.data.mesh, observed, count)
    method.log(f"the light from {len(representative)} clusters of faces")
    part = method.solve_held(prep.clustered(cluster, representative), keep_regions=False)
    est = extend(method, prep, part)
    est.info.update({k: part.estimate.info[k] for k in CARRIED if k in part.estimate.info})
    est.info["light_faces"] = int(len(representative))
    return est


def extend(method, prep: Prepared, part: Solution) -> Estimate:
    """The estimate of every face of ``prep`` under the light of ``part`` (the clustered
    problem's :class:`Solution`): its coat's level and reflection subtracted from every
    observation, each face's diffuse radiance (the ``retinex_quantile``, or with a light from
    the coat's map, the radiance under that map, :func:`coat_map.diffuse_radiance`) over its
    shading under that light (its sun's shadowed column, and the light the object reflects onto it with
    ``interreflection``); where the clustered problem tied uniform regions, the regions are
    found again on the whole mesh under that light (parted again where the clustered problem
    parted them, :func:`.edges.parted_regions`; faces near a region in albedo join it, as in
    :func:`.edges.tied_regions`) and each takes its faces' median albedo. Faces seen only beyond
    ``min_cos_view`` then join those regions by the rule of the held solve's faces outside its
    fit (:func:`.thin.joined_to_regions`, their radiance from all their rows), except under a
    light from the coat's view changes, whose diffuse radiance their colours do not match;
    ``info['outside_faces']`` counts them."""
    c, h, model = method.config, part.hypothesis, method.model
    mesh, f = prep.data.mesh, prep.data.mesh.num_faces

    def diffuse_part(o):
        """``o`` with the coat's level and reflection subtracted from its colours (one coat
        group: ``coat_per_region`` is not carried)."""
        rgb = o.rgb - part.level
        if part.coat is not None:
            rgb = rgb - part.coat.unregioned(o.face, o.view_dir, prep, c.coat_ior)
        return replace(o, rgb=rgb)

    if part.level.any() or part.coat is not None:
        prep = replace(prep, obs=diffuse_part(prep.obs))
    obs = prep.obs
    # faces seen only beyond min_cos_view: no fit keeps their rows; they join the regions below
    outside = prep.all_obs.observed_faces() & ~obs.observed_faces()
    radiance = group_quantile(obs.face, obs.rgb, f, c.retinex_quantile)
    if h.source.from_coat_map:   # the map's diffuse radiance, as the clusters' light was fitted to
        mapped = coat_map.diffuse_radiance(part.fits.coat_map, obs.face, obs.rgb, obs.view_dir, mesh.face_normals,
                                           prep.sampling, prep.visibility, c.coat_ior, loss=method.loss)
        radiance = np.where(np.isfinite(mapped) & (mapped > 0), mapped, radiance)
    sees_sky = np.any(prep.visibility.bits != 0, axis=1)    # the held solve's "DC shading > 0"
    usable = np.all(np.isfinite(radiance) & (radiance > 0), axis=1) & sees_sky
    m = sh.num_coeffs(model.order)
    shade = prep.shading(h.light[:m], h.shading.coat_ior)
    if h.shading.sun is not None:
        columns = sun.sun_shadings(mesh, prep.caster, h.shading.sun.directions, h.shading.sun.coat_ior)
        shade = shade + columns @ h.light[m:]
    if c.interreflection:
        shade = shade + indirect.indirect_shading(prep.caster, prep.sampling, prep.visibility,
                                                  np.where(usable[:, None], radiance, 0.0))
    albedo, lit = divide_shade(shade, radiance, usable)
    labels, regions, edges = np.full(f, -1, dtype=np.int64), 0, prep.edges
    if h.regions:
        features = in_unit_dc(albedo, h.light)
        bridges = prep.blends_albedos   # faces smaller than their pixels
        labels, _ = segment(np.where(lit[:, None], features, 1.0), edges, lit, c.segment_threshold, c.uniform_spread,
                            bridges=bridges)
        if h.source is LightSource.EDGES_AND_PARTED_REGIONS:
            labels = split_regions(labels, features, lit, edges, c.segment_threshold, c.uniform_spread, bridges)
            if part.coat is None and not part.level.any():   # on the colours as recorded, as the parts were found
                labels = split_modes(labels, features, lit, edges)
        joined = assign_to_regions(labels, features, lit, edges, 2.5 * c.segment_threshold)
        labels, ids = compact_regions(np.where(lit & (joined < int(labels.max()) + 1), joined, -1))
        regions = len(ids)
        tied = labels >= 0
        albedo[tied] = group_quantile(labels[tied], albedo[tied], regions, 0.5)[labels[tied]]
    whole = replace(h, radiance=radiance, albedo=albedo, lit=lit, labels=labels, regions=regions)
    ctx = FitContext(prep, c, model, method.loss, ReflectionFits(obs), edges, usable)
    if outside.any() and regions and not h.source.models_the_coat:
        beyond = diffuse_part(prep.all_obs.subset(outside[prep.all_obs.face]))
        seen = np.where(outside[:, None], group_quantile(beyond.face, beyond.rgb, f, c.retinex_quantile), radiance)
        whole = joined_to_regions(ctx, replace(whole, radiance=seen), outside & sees_sky, shade)
    est = to_estimate(ctx, whole, method)
    est.info["outside_faces"] = {"thin": 0, "grazing": int(outside.sum()),
                                 "joined": int(np.sum(whole.lit & outside))}
    return est
