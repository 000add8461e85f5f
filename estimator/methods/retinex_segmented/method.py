"""The orchestrator of ``retinex-segmented``: the radiance, the light decision, the estimate,
and the coat's correction around them."""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...core import sh
from ...core.errors import InputError
from ...core.reductions import group_quantile
from ...core.settings import Section
from ...light import coat, indirect, sun
from ...model.estimate import Estimate
from ...pipeline.prepared import Prepared
from ..base import Method, register_method
from .clusters import carried, cluster_count, solve_on_clusters
from .decision import choose, light_hypotheses, prediction_cost
from .level import coat_level
from .result import to_estimate
from .thin import joined_to_regions, thin_faces
from .values import CoatReflection, FitContext, Hypothesis, LightSource, ReflectionFits, Solution


def first_sun(chosen: Hypothesis) -> sun.Sun | None:
    """The sun a first fit found, for its refits: not searched again (no evaluations)."""
    return chosen.found and replace(chosen.found, evaluations=0)


def coat_name(reflected: CoatReflection) -> str:
    """How ``run.json``'s ``coat_costs`` names a coat's reflection: 'degree N' (a dielectric
    coat's, of the light to degree N) or 'lobe N' (a Phong lobe's of exponent N)."""
    return f"degree {reflected.order}" if reflected.exponent is None else f"lobe {reflected.exponent:g}"


@dataclass
class RegionConfig(Section):
    """When ``retinex-segmented`` ties faces to uniform regions.

    Attributes
    ----------
    retinex_min_uniform_share : faces are tied to regions only when at least this share of
        the lit faces lies in some uniform region; below it the object is a texture and the
        edges alone set the light.
    region_max_deviation, region_max_drift : the regions are dropped (a texture) when, under
        the light fitted with them tied, the median face's own albedo deviates from its
        region's (mean over channels of |log ratio|) by more than ``region_max_deviation``
        *and* by more than ``region_max_drift`` times the median such difference between
        neighbouring faces of a region (independent Gaussian noise alone gives about
        1 / sqrt(2)).

    The three values were chosen on the shipped probes, not derived. On the random family's
    development seeds each sits at a local optimum (moving one of them up or down gained on
    one seed at most, with a loss elsewhere, or loosened a gate that a texture passes then),
    and a drift bound from the Bayesian
    information criterion, sqrt(ln(n) / 2) for n colour values, ties a texture whose
    neighbouring faces differ by more than noise. The measurements are in the git history.
    """

    retinex_min_uniform_share: float = 0.5
    region_max_deviation: float = 0.065
    region_max_drift: float = 1.85

    def check(self):
        return [
            (0 <= self.retinex_min_uniform_share <= 1, "retinex_min_uniform_share must lie in [0, 1]"),
            (self.region_max_deviation > 0 and self.region_max_drift > 0,
             "region_max_deviation and region_max_drift must be > 0"),
        ]


def coat_groups(est: Estimate, per_region: bool) -> tuple[np.ndarray, int]:
    """(F,) the coat group of each face and the number of groups G: with ``per_region`` each
    uniform region of ``est`` is its own group (a part of another material takes its own coat)
    and every other face (a texture's, or unestimated) shares group R; otherwise one group."""
    regions = int(est.info.get("uniform_regions") or 0) if per_region else 0
    labels = est.labels
    group = np.where((labels >= 0) & (labels < regions), labels, regions)
    return group.astype(np.int64), regions + 1


@register_method
class RetinexSegmented(Method):
    """The light from albedo edges and uniform regions, in the log domain (beyond the paper).

    1. A face's diffuse radiance is a low quantile (``retinex_quantile``) of its colours
       over the views.
    2. The light is fitted to the log radiance ratios of neighbouring faces, with a robust
       loss that lets albedo edges go (:func:`estimator.light.edge_fit.log_shading_fit`): a
       Retinex prior on the mesh, which needs no region and holds on textures.
    3. Radiance over that shading gives per-face albedos; uniform regions are found on the
       face-adjacency graph (:func:`estimator.solvers.segmentation.segment`).
    4. When at least ``retinex_min_uniform_share`` of the lit faces lie in uniform
       regions, the light is fitted again with each region's faces tied to one albedo
       (far-apart faces of a region constrain the light as the edges cannot), and each
       region takes that albedo, unless the faces drift from their region's albedo beyond
       ``region_max_deviation`` and ``region_max_drift`` times the noise between neighbours
       (a texture chained into regions). Otherwise the edges alone set the light and every
       face keeps its own albedo (a texture).
    5. The specular albedo is solved with that light fixed (per region; faces outside every
       region share the regions' median, or, without regions, the median of every face's own fit).
    6. With ``coat_correction``, the reflection of a dielectric coat (``coat_ior``) of the
       environment's mean level (where the mirror direction escapes the object), apart, of
       the light's low orders (``coat_order``) and, with ``coat_lobe``, a Phong lobe's (no
       Fresnel factor; its exponent the one whose rows explain the changes best) are each
       fitted to the colours' changes across views
       (:mod:`estimator.light.coat`), with ``coat_per_region`` a grey coat's strength per
       uniform region (a matte part takes none; the other faces share one), scaled down until
       at most ``coat_max_negative`` more of the observations would turn non-positive,
       subtracted, and steps 1-5 run again (the first fit's regions, tied as they are, one more
       hypothesis); of the uncorrected and the corrected fits the one that predicts the colours
       as recorded (a coat's reflection added back) at the lowest
       :func:`.decision.prediction_cost` is kept, the weights its unknowns (three with one weight).
       With ``coat_level``, where some of those reflections are worth trying, the level the coat's
       reflection adds to every view of a face is found first from the albedo edges, alternated
       with the light (:mod:`.level`); where the edges' criterion keeps it, it is subtracted
       from every colour and steps 1-5 run again before the reflections are fitted.

    With ``interreflection`` each face's shading also holds the light the object reflects
    onto it (:mod:`estimator.light.indirect`). Beside the edges' light, the light of the coat's
    reflection (:mod:`estimator.light.coat_map`, when that map is determined), the edges'
    light on the map's diffuse radiance (a texture) and, with ``reflected_lobe``, a shared
    Phong lobe's (:mod:`estimator.light.lobe_light`) are each turned into an estimate, and the
    one that best predicts the observations, at the Bayesian information criterion's price
    per unknown, is kept (:mod:`.decision`). Where the kept light models the coat, the
    cheapest hypothesis that does not is corrected as in step 6 and the kept one weighed again,
    as it is, against that hypothesis uncorrected and corrected, by the same criterion (a light
    from the coat's view changes could otherwise win against fits whose coat was not yet
    removed); with ``coat_level`` step 6 is skipped there instead.

    7. The faces steps 1-6 had no row of (:mod:`.thin`: thin faces, which no pure pixel
       covers, their rows unmixed from pixels they share; faces seen only beyond
       ``min_cos_view``) join the estimate's uniform regions where their neighbours and their
       own albedo agree.

    On a mesh with more observed faces than ``light_faces`` (a dense scan), or whose rows are
    streamed, steps 1-6 run on that many clusters of faces and every face's albedo follows
    under their light (:mod:`.clusters`); thin faces then have no rows.
    """

    name = "retinex-segmented"
    default_loss = "cauchy"
    streams = True
    joins_thin_faces = True   # left out of the fit, joined to its regions (:mod:`.thin`)

    def solve(self, prep):
        c = self.config
        if c.components == "specular":
            raise InputError("retinex-segmented estimates the diffuse albedo from shading; for specular-only "
                             "data (components='specular') use bilinear-per-face")
        thin = thin_faces(prep.obs)
        observed = np.nonzero(prep.obs.observed_faces() & (True if thin is None else ~thin))[0]
        count = cluster_count(prep, c.light_faces, len(observed))
        if prep.streamed or (count < len(observed) and not carried(c)):
            # a cluster would merge a thin face's kept rows into its colour: on clusters they have
            # none; one seen only at grazing angles joins a region as the other such faces do
            est = solve_on_clusters(self, prep.without_thin(keep_grazing=True), observed, count)
            est.info["outside_faces"]["thin"] = 0 if thin is None else int(thin.sum())   # dropped, not joined
            return est
        return self.solve_held(prep).estimate

    def solve_held(self, prep, keep_regions: bool = True) -> Solution:
        """Steps 1-6 on a problem whose rows are held (with ``coat_level``, the coat's level
        removed before step 6); the estimate with the hypothesis it came from, the coat's level
        and the coat's reflection subtracted before it (what :func:`.clusters.extend`
        carries from clusters to faces). ``keep_regions``: offer the coat's refits the first
        fit's regions tied as they are (off on clusters, whose regions the extension to faces
        finds again by segmentation: regions kept without it could not be carried)."""
        c = self.config
        t = time.perf_counter()
        whole, thin = prep, thin_faces(prep.obs)
        if thin is not None:   # steps 1-6 without them; they join the estimate under its light
            prep = prep.row_subset(~thin[prep.obs.face])
        fits = ReflectionFits(prep.obs)   # the view-dependent fits, made on first need from these observations
        est, chosen, plain = self._fit(prep, fits)
        self.log(f"light from {est.info['light_from']} ({est.info['uniform_regions']} uniform regions), "
                 f"{time.perf_counter() - t:.1f} s")
        weight, applied, level, rival = np.zeros((1, 3)), None, np.zeros(3), None
        if c.coat_correction and chosen.source.models_the_coat and plain is not None and not c.coat_level:
            # weighed again against the cheapest other hypothesis once that is corrected for the coat
            rival, (est, chosen) = (est, chosen), plain
            self.log(f"{rival[1].source.value} weighed again against {chosen.source.value} corrected for the coat")
        if c.coat_correction and not chosen.source.models_the_coat:
            candidates = self._coat_candidates(prep, est)
            if c.coat_level and candidates:   # a glossy layer's reflection is seen: its level too
                prep, est, chosen, level = self._remove_level(prep, fits, est, chosen)
                if level.any():   # the candidates again, on the colours less the level, under the new light
                    candidates = None
            est, chosen, applied, prep = self._correct_coat(prep, fits, est, chosen, t, keep_regions, candidates,
                                                            rival)
            if applied is not None:
                weight = applied.weight
        # the faces a view shows that the fit had no row of: thin faces, and faces seen only
        # beyond min_cos_view (their rows kept out of every fit)
        outside = whole.all_obs.observed_faces() & ~prep.obs.observed_faces()
        est.info["outside_faces"] = {"thin": 0, "grazing": 0, "joined": 0}
        if outside.any() and not whole.merged_faces:   # clusters: extend() finds every face's albedo
            est = self._with_outside(whole, prep, fits, est, chosen, applied, level, outside)
        est.info["coat_level"] = level.tolist()
        est.info["coat_degree"] = None if applied is None else applied.order
        est.info["coat_exponent"] = None if applied is None else applied.exponent
        est.info["coat_weight"] = weight.tolist()
        est.info["clustering_s"] = time.perf_counter() - t
        return Solution(est, chosen, applied, fits, level)

    def _remove_level(self, prep, fits: ReflectionFits, est: Estimate,
                      chosen: Hypothesis) -> tuple[Prepared, Estimate, Hypothesis, np.ndarray]:
        """The coat's view-independent level (:func:`.level.coat_level`) under the first fit;
        where the edges' criterion keeps it, subtracted from every colour and steps 1-5 run
        again (the sun found the first time reused). Returns the problem on the colours less the
        level, the estimate, its hypothesis and the (3,) level (0: none kept, or the refit took
        its light from the coat's map, whose fit still holds the level; the first fit and
        ``prep`` unchanged)."""
        c = self.config
        found = coat_level(chosen, prep.edges, prep.c_matrix[:, 0] > 0, fits.transfer if c.interreflection else None,
                           self._edge_fit_arguments(), c.coat_max_negative)
        self.log(f"coat's level: {np.round(found.level, 6).tolist()} (edges' cost lower by {found.gain:.1f}, "
                 f"price {found.price:.1f})")
        if not found.level.any():
            return prep, est, chosen, found.level
        less = replace(prep, obs=replace(prep.obs, rgb=prep.obs.rgb - found.level))
        refit, hypothesis, _ = self._fit(less, fits, first_sun(chosen), recorded=False)
        if LightSource(refit.info["light_from"]).models_the_coat:
            return prep, est, chosen, np.zeros(3)
        return less, refit, hypothesis, found.level

    def _correct_coat(self, prep, fits: ReflectionFits, est: Estimate, chosen: Hypothesis, t: float,
                      keep_regions: bool = True, candidates: list[tuple[CoatReflection, np.ndarray]] | None = None,
                      rival: tuple[Estimate, Hypothesis] | None = None
                      ) -> tuple[Estimate, Hypothesis, CoatReflection | None, Prepared]:
        """Step 6: the coat's reflection of the environment's mean level (SH degree 0), of the
        light's low orders (``coat_order``) and, with ``coat_lobe``, a Phong lobe's
        (:meth:`_lobe_shape`), each fitted to the colours' changes across views,
        scaled down to ``coat_max_negative``, subtracted, and steps 1-5 run again (reusing the
        sun found the first time; with ``keep_regions`` the first fit's regions, tied as they
        are, are one more hypothesis); the uncorrected and the corrected fits are judged by
        :func:`.decision.prediction_cost` on the colours of ``prep`` (as observed, less the
        coat's level where one was removed; each coat's reflection
        added back, one unknown per region's strength and two for the grey coat's shared
        colour: three with one group; the lobe's exponent one more). ``candidates``: those of
        :meth:`_coat_candidates` on these colours under ``est`` (None: found here). ``rival``:
        an estimate whose light models the coat, with its hypothesis, judged beside them as it
        is (the first fit's choice, which ``est`` lost to before its correction). Returns the
        estimate kept, its hypothesis, the reflection subtracted before it (None: none) and the
        problem it was fitted on (``prep``, its colours less that reflection)."""
        c, obs = self.config, prep.obs
        candidates = self._coat_candidates(prep, est) if candidates is None else candidates
        group = coat_groups(est, c.coat_per_region)[0][obs.face]
        est.info["coat_costs"] = None
        if not candidates:   # nothing to correct: a rival, which the first fit chose, stands
            return (*(rival or (est, chosen)), None, prep)
        found = first_sun(chosen)
        regions = chosen.labels if chosen.regions and keep_regions else None   # the first fit's, for each refit
        corrected = [replace(prep, obs=replace(obs, rgb=obs.rgb - reflection)) for _, reflection in candidates]
        fitted = [self._fit(less, fits, found, regions, False)[:2] for less in corrected]
        rivals = [] if rival is None else [rival]
        # a coat's unknowns: its groups' strengths and two of the grey colour; a lobe's exponent one more
        costs = prediction_cost(prep, [est] + [e for e, _ in fitted + rivals],
                                [None] + [r for _, r in candidates] + [None] * len(rivals),
                                [0] + [len(np.unique(group)) + 2 + (r.exponent is not None) for r, _ in candidates]
                                + [0] * len(rivals))
        best = int(np.argmin(costs))
        named = {"none": float(costs[0]), **{coat_name(r): float(x) for (r, _), x in zip(candidates, costs[1:])},
                 **{h.source.value: float(costs[-1]) for _, h in rivals}}
        costs_text = ", ".join(f"{name} {cost:.1f}" for name, cost in named.items())
        self.log(f"coat's reflection: costs {costs_text}; {list(named)[best]} kept, {time.perf_counter() - t:.1f} s")
        applied = None
        if best > len(candidates):
            est, chosen = rival
        elif best:
            (est, chosen), applied, prep = fitted[best - 1], candidates[best - 1][0], corrected[best - 1]
        est.info["coat_costs"] = named
        return est, chosen, applied, prep

    def _with_outside(self, whole: Prepared, fitted: Prepared, fits: ReflectionFits, est: Estimate,
                      chosen: Hypothesis, applied: CoatReflection | None, level: np.ndarray,
                      outside: np.ndarray) -> Estimate:
        """``est`` with the faces ``outside`` (F,) bool the fit had no row of (thin faces, and
        faces seen only beyond ``min_cos_view``) joined to its regions under its light
        (:func:`.thin.joined_to_regions`, in the context of the problem ``fitted`` the estimate
        came from). A face's radiance is the same quantile as every face's, over its kept rows
        of ``whole`` (a thin face's), or all its rows where none is kept, less the coat's
        ``level`` and ``applied`` reflection (such a face is in no region of the first fit, so
        in the last coat group). The fitted faces keep every value, and the estimate its record
        of its choices, with the faces counted (``info['outside_faces']``: thin, seen only at
        grazing angles, and joined); where none joins (a texture, or a light from the coat's
        map or lobe) the estimate is returned as it is."""
        kept = whole.obs.observed_faces()
        count = {"thin": int(np.sum(outside & kept)), "grazing": int(np.sum(outside & ~kept)), "joined": 0}
        est.info["outside_faces"] = count
        if not chosen.regions or chosen.source.models_the_coat:
            # a light from the coat's view changes divides the map's or the lobe's diffuse
            # radiance, which these faces' colours less a level alone do not match
            return est
        c = self.config
        own, beyond = whole.obs.subset((outside & kept)[whole.obs.face]), whole.all_obs.subset(
            (outside & ~kept)[whole.all_obs.face])
        face, view_dir = np.concatenate([own.face, beyond.face]), np.concatenate([own.view_dir, beyond.view_dir])
        rgb = np.concatenate([own.rgb, beyond.rgb]) - level
        if applied is not None:
            rgb = rgb - applied.unregioned(face, view_dir, whole, c.coat_ior)
        radiance = group_quantile(face, rgb, whole.obs.num_faces, c.retinex_quantile)
        ctx, _ = self._context(fitted, fits)
        shade = chosen.shading.columns @ chosen.light + ctx.extra
        joined = joined_to_regions(ctx, replace(chosen, radiance=np.where(outside[:, None], radiance, chosen.radiance)),
                                   outside & (fitted.c_matrix[:, 0] > 0), shade)
        count["joined"] = int(np.sum(joined.lit & ~chosen.lit))
        if not count["joined"]:
            return est
        out = to_estimate(ctx, joined, self)
        out.info = {**est.info, **out.info}
        return out

    def _coat_candidates(self, prep, est: Estimate) -> list[tuple[CoatReflection, np.ndarray]]:
        """The coat's reflections worth trying on the colours of ``prep`` under ``est``'s light:
        of the environment's mean level (SH degree 0), of the light's low orders (``coat_order``)
        and, with ``coat_lobe``, a Phong lobe's (:meth:`_lobe_shape`), each fitted to the colours'
        changes across views and scaled down to ``coat_max_negative``; those whose median
        reflection exceeds ``coat_min_share`` of the colours, each with its (N, 3) reflection.
        Empty: the colours show no coat's reflection (a matte object)."""
        c, obs = self.config, prep.obs
        normals = prep.data.mesh.face_normals[obs.face]
        escapes = coat.mirror_escapes(obs.face, normals, obs.view_dir, prep.sampling, prep.visibility)
        group, groups = coat_groups(est, c.coat_per_region)
        group = group[obs.face]
        level = c.coat_min_share * np.median(np.linalg.norm(obs.rgb, axis=1))
        shapes = [(CoatReflection(est.light, np.ones((groups, 3)), order), None)
                  for order in sorted({0, c.coat_order})]
        if c.coat_lobe:
            shapes.append(self._lobe_shape(obs, normals, est.light, escapes, group, groups))
        candidates = []
        for reflected, rows in shapes:
            rows = reflected.rows(normals, obs.view_dir, c.coat_ior, escapes) if rows is None else rows
            weight = coat.fit_coat(obs.face, obs.rgb, rows, obs.num_faces, self.loss, group=group,
                                   num_groups=groups)
            weight = weight * coat.admissible_scale(obs.rgb, weight[group] * rows, c.coat_max_negative,
                                                    group=group, num_groups=groups)[:, None]
            reflection = weight[group] * rows
            if np.median(np.linalg.norm(reflection, axis=1)) > level:     # else negligible: not tried
                candidates.append((replace(reflected, weight=weight), reflection))
        return candidates

    def _lobe_shape(self, obs, normals: np.ndarray, light: np.ndarray, escapes: np.ndarray, group: np.ndarray,
                    groups: int) -> tuple[CoatReflection, np.ndarray]:
        """The Phong lobe (:func:`coat.lobe_rows`) of the exponent among
        :data:`coat.LOBE_EXPONENTS` whose rows, weighted as :func:`coat.fit_coat` fits them,
        leave the least of the colours' changes across views unexplained
        (:func:`coat.unexplained_cost`); with its rows (N, 3) per unit weight."""
        rows = coat.lobe_rows(normals, obs.view_dir, light, coat.LOBE_EXPONENTS, escapes)
        fitted = [coat.fit_coat(obs.face, obs.rgb, r, obs.num_faces, self.loss, group=group,
                                num_groups=groups)[group] * r for r in rows]
        best = int(np.argmin(coat.unexplained_cost(obs.face, obs.rgb, fitted, obs.num_faces)))
        shape = CoatReflection(light, np.ones((groups, 3)), sh.order_of(light.shape[0]), coat.LOBE_EXPONENTS[best])
        return shape, rows[best]

    def _edge_fit_arguments(self) -> dict[str, Any]:
        """The edge fit's keyword arguments (:func:`estimator.light.edge_fit.log_shading_fit`)
        from the settings, without the indirect shading."""
        c = self.config
        return dict(loss=self.loss, ridge=c.retinex_ridge, iterations=c.retinex_iterations,
                    max_edges=c.retinex_max_edges)

    def _fit(self, prep, fits: ReflectionFits, found: sun.Sun | None = None, labels: np.ndarray | None = None,
             recorded: bool = True) -> tuple[Estimate, Hypothesis, tuple[Estimate, Hypothesis] | None]:
        """Steps 1-5 on the observations of ``prep``; ``found``: the sun of an earlier fit
        (None: search for one when ``sun_min_gain`` < 1); ``labels``: an earlier fit's uniform
        regions, offered tied as they are (:func:`.edges.kept_regions`); ``recorded``: False
        where ``prep``'s colours are less a coat's reflection or level a refit subtracted (the
        parted regions' modes are then not sought, :func:`.edges.parted_regions`). Returns the
        chosen estimate and its hypothesis, and where the chosen light models the coat, the
        estimate and hypothesis of least cost among those that do not (None otherwise), its
        record of the costs marking it chosen."""
        ctx, radiance = self._context(prep, fits, recorded)
        hypotheses = light_hypotheses(ctx, radiance, found, labels)
        estimates = [to_estimate(ctx, h, self) for h in hypotheses]
        best = choose(prep, hypotheses, estimates)
        others = [i for i, h in enumerate(hypotheses) if not h.source.models_the_coat]
        if not hypotheses[best].source.models_the_coat or not others:
            return estimates[best], hypotheses[best], None
        record = estimates[best].info["hypotheses"]
        plain = min(others, key=lambda i: record[i]["cost"])
        estimates[plain].info["hypotheses"] = [{**entry, "chosen": i == plain} for i, entry in enumerate(record)]
        return estimates[best], hypotheses[best], (estimates[plain], hypotheses[plain])

    def _context(self, prep, fits: ReflectionFits, recorded: bool = True) -> tuple[FitContext, np.ndarray]:
        """What steps 1-5 read on the observations of ``prep`` (:class:`FitContext`: the usable
        faces, the edge fit's arguments, the shading the object adds to itself), and the (F, 3)
        diffuse radiance of each face (a low quantile of its colours over its views)."""
        c = self.config
        mesh, obs = prep.data.mesh, prep.obs
        radiance = group_quantile(obs.face, obs.rgb, mesh.num_faces, c.retinex_quantile)
        # a face that sees no direction of the sky (its DC shading is 0) is lit only by the
        # object itself: the direct light cannot explain its radiance, so it takes no part
        usable = np.all(np.isfinite(radiance) & (radiance > 0), axis=1) & (prep.c_matrix[:, 0] > 0)
        if not usable.any():
            dark = [name for name, lit in zip(("red", "green", "blue"), np.any(obs.rgb > 0, axis=0)) if not lit]
            cause = (f": the {' and '.join(dark)} channel is zero or negative in every observation (a light or camera "
                     "that records none of it, or albedos of 0 in it everywhere); the light is fitted to every "
                     "channel's shading, so use a method that does not estimate it (median-color) or check the "
                     "images' white balance and channel order") if dark else ""
            raise InputError(f"no face has a positive diffuse radiance in its kept views{cause}")
        ctx = FitContext(prep, c, self.model, self.loss, fits, prep.edges, usable,
                         self._edge_fit_arguments(), recorded=recorded)
        if c.interreflection:
            if fits.transfer is None:
                fits.transfer = indirect.indirect_transfer(prep.caster, prep.sampling, prep.visibility)
            ctx.fit["indirect"] = ctx.extra = fits.transfer @ np.where(usable[:, None], radiance, 0.0)
        return ctx, radiance

