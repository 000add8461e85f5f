"""Parameters of the estimator, validated in one place."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

from .errors import InputError
from .sh import phong_filter

COMPONENTS = ("both", "specular", "diffuse")
DIFFUSE_LIGHTS = ("pseudo", "defiltered")
SPECULAR_MODELS = ("mirror", "lobe")
LOSSES = ("auto", "none", "huber", "cauchy", "tukey")


@dataclass
class EstimatorConfig:
    """Every parameter of the pipeline (defaults follow the paper where it gives one).

    Attributes
    ----------
    sh_order : SH order N_L of the pseudo illumination ((N_L + 1)^2 coefficients).
    directions : number of sample directions of the shadow function (paper: 1164).
    iterations, tol : ALS iteration cap and relative residual-change stop.
    components : 'both', 'specular' (t_d = 0, the earth experiment) or 'diffuse'.
    min_cos_view : keep an observation only when r . n = v . n exceeds this
        (0.5 = within 60 degrees of the normal). Far from the normal the Phong
        lobe around r is cut by the horizon, which the mirror term ignores.
    min_pixels : pixels a face must cover in a view to give an observation.
    pure_pixels : use only pixels covered by one face alone (corner rays agree).
    min_brightness : bilinear-clustered leaves unestimated (label -1) the faces whose
        median colour is below this fraction of the 95th percentile: unlit in every
        view, they carry no colour information.
    bandwidth : angular mean-shift sigma on unit colours (radians).
    split_bandwidth : Euclidean split sigma, relative to a cluster's median albedo.
    min_cluster_fraction : a split-off cluster needs at least this share of the
        estimated faces (else its faces join the nearest kept sub-cluster).
    recluster_rounds : cap on solve + re-cluster rounds.
    diffuse_light : 'pseudo' (the paper: diffuse term from the pseudo
        illumination) or 'defiltered' (divided by the Phong filter up to
        ``defilter_order``, for exponent ``phong_exponent``).
    specular_model : 'mirror' (the paper's Eq. 10: D = Y(r) s(r) times the
        pseudo illumination) or 'lobe' (the Phong lobe of ``phong_exponent``
        integrated over the sphere with the face's horizon and shadows, times
        the radiance; exact for the Phong BRDF, needs the exponent).
    negative_tolerance : a pixel with a channel below -negative_tolerance x its view's
        99th-percentile value is dropped as an outlier (and counted): sensor and Monte
        Carlo noise on black stays within a percent of the bright level.
    min_coverage : a pixel is used only when the object covers at least this share of
        it (alpha); 0.999 keeps whole pixels and drops silhouette edges, whose colour
        mixes object and background.
    recluster_min_shading : re-clustering judges a face's shading-corrected colour only
        when its diffuse shading is at least this fraction of the
        ``recluster_shading_percentile`` of all faces' shading: dividing by a small
        shading amplifies noise, and a quarter of the well-lit level keeps the dim faces
        of a region while dropping the ones in shadow.
    lm_damping_start, lm_damping_raise, lm_damping_lower, lm_damping_max : the
        Levenberg-Marquardt schedule: initial damping, factor on a rejected step,
        divisor after an accepted one, and the damping at which a step is given up
        (Madsen, Nielsen & Tingleff's usual values; raising by more than lowering
        keeps the solver from oscillating between the two).
    diffuse_quantile : ``bilinear-segmented`` takes a face's diffuse radiance as this
        quantile of its colours (less the fitted specular) over the views.
    segment_threshold, uniform_spread : neighbours whose log-albedos differ by less than
        ``segment_threshold`` join one region; a region is uniform (its faces share one
        albedo) when its log-albedo spread is below ``uniform_spread``.
    robust_loss : M-estimator of the iteratively reweighted solve ('none': least squares,
        the paper; 'huber', 'cauchy' or 'tukey'; 'auto': the method's own, least squares
        for ``bilinear-clustered`` (the paper's full method, kept unchanged) and
        ``known-illumination``, Cauchy for ``retinex-segmented``, ``bilinear-segmented`` and
        ``bilinear-per-face``),
        on residuals relative to the face's
        median colour (:mod:`estimator.robust`).
    robust_rounds : reweighting rounds (each one more bilinear solve).
    glint_ratio : before the first robust solve, a row brighter than this x its face's
        median colour is clipped to that level (a glint must not set the first light).
    relabel_rounds : ``bilinear-segmented`` moves boundary faces to the neighbouring region
        that best predicts their observations, then solves again, up to this many times.
    tie_regions : ``bilinear-segmented`` makes the regions' albedo ratios agree with the
        radiance ratios across their boundaries (neighbours see the same light).
    segment_min_shading : ``bilinear-segmented`` segments faces whose diffuse shading is at
        least this fraction of the ``recluster_shading_percentile`` level (a low quantile
        of the colour over views divided by the shading is clean down to a few percent).
    retinex_quantile : ``retinex-segmented`` takes a face's diffuse radiance as this quantile
        of its colours over the views (low: highlights of the coat move with the view and
        rarely reach it).
    retinex_ridge : weight of the (l (l + 1))^2 penalty on the light in the edge fit, per
        row (a tie-breaker for coefficients the shading does not see).
    retinex_iterations : Gauss-Newton steps of the edge fit per channel.
    retinex_min_uniform_share : ``retinex-segmented`` ties faces to uniform regions only
        when this share of the lit faces lies in one; below it the object is textured and
        the edges alone set the light (regions found inside a texture are not uniform).
    region_max_deviation, region_max_drift : the regions are dropped (the object is treated
        as a texture) when, under the light fitted with them tied, the median face's own
        albedo deviates from its region's (mean over channels of |log ratio|) by more than
        ``region_max_deviation`` *and* by more than ``region_max_drift`` times the median
        such difference between neighbouring faces of a region. Measured: full-size region
        scenes 0.040-0.051 and 1.13-1.69; tiny ones (noisier) 0.042-0.098 and 0.80-0.93;
        textured scenes where the Earth's oceans formed 2-3 large "regions" (venice,
        phong/dawn) 0.071-0.119 and 1.98-2.31.
    coat_correction, coat_ior, coat_order : ``retinex-segmented`` removes the reflection of a
        smooth dielectric coat of index ``coat_ior`` of the light's orders up to
        ``coat_order`` (at most ``sh_order``), its weight fitted to the colours' changes across views (zero on a
        bare diffuse surface; :mod:`estimator.coat`). The steps run again only when the
        coat's median share of the colours exceeds ``coat_min_share``; the fitted weight is
        scaled down until subtracting it turns at most ``coat_max_negative`` more of the
        observations non-positive (a coat cannot reflect more than a pixel shows; without
        that cap one city case lost 22 % of its faces and fell to 12 dB).
    interreflection : ``retinex-segmented`` adds to each face's shading the light the object
        reflects onto it (one bounce, from the observed radiance of the faces its blocked
        directions hit; :mod:`estimator.indirect`); the light's scale becomes an unknown.
        Off by default: on the real-light family it raised the cases with >= 90 % within
        ±10 % from 32 to 35 of 36 but lowered those >= 30 dB from 31 to 28 (28 meet all
        three targets either way), and cost the textured scene 1.2 dB.
    sun_min_gain : ``retinex-segmented`` looks for a sun (:mod:`estimator.sun`): a delta
        light with exact cast shadows beside the SH light, its direction found by a search
        on the edge fit's robust cost; it is kept when it lowers that cost by at least this
        fraction. 1 turns the search off.
    reflected_light, reflected_regions, reflected_min_explained, reflected_sun_max_ratio, reflected_sun_max_angle :
        ``retinex-segmented`` takes the light from the coat's reflection
        (:mod:`estimator.reflected_light`: a 32 x 64 lat-long map fitted to the colours'
        changes across views, every face's diffuse free, so no albedo can bias it) instead
        of the albedo edges (and, with ``reflected_regions``, of the uniform regions: each
        region then takes its faces' median albedo under that light), when no sun was kept
        by the edge search, the map is determined (4 rows per vertex beyond the faces' own
        unknowns; about 10 at full size) and it explains at least
        ``reflected_min_explained`` of the view changes (mean over the channels): 0.986-0.999
        where the map's light was the better one, 0.976-0.978 under lab's lamps with the
        smooth coat (the map's light cost 10.8-14.7 dB on the region scenes there, 2.1 dB on
        the textured one), 0.946-0.964 on smooth plastic under grace, hall and lobby, whose
        small bright sources a 32 x 64 map cannot hold, and 0.51-0.77 on a bare (specular-free)
        texture. Where the edge search kept a sun, the map's light replaces it only when the
        map's own sun is kept too, within ``reflected_sun_max_angle`` degrees of it (about a
        map cell; the whole map cannot hold a studio's lamps: smooth plastic under studio fell
        from 33.9-54.2 to 10.3-12.5 dB with it; agreeing suns were 0.6-2.5 degrees apart, and a
        sun 16 degrees high came out of the map 13.6 degrees low, costing plastic/sunsky-low
        22 dB). The map's brightest
        compact source then becomes a sun with exact shadows, its irradiance fitted to the
        edges, kept when the edge cost ratio is at most ``reflected_sun_max_ratio``
        (0.90-0.96 where it helped on the development scenes, 0.976 on roughplastic/lab
        where it cost 0.8 dB). The albedo is then the map fit's diffuse radiance (the
        coat's reflection removed, its exit transmission divided out) over a shading through
        the coat (the cosine weighted by 1 - F on the way in, as Mitsuba's ``plastic``).
        Textured scenes (9, full size): median 23.6 -> 32.7 dB.
    reflected_diffuse_min_explained : where the map's light fails its gate and the light
        comes from the edges alone, ``retinex-segmented`` still takes the map fit's diffuse
        radiance (the coat's reflection removed, its exit transmission divided out) under a
        shading through the coat, when the map is determined and explains at least this
        share of the view changes (smooth plastic under lab's lamps 0.977, under grace's
        windows 0.952-0.958; Phong and bare textures 0.5-0.77): the map's light errs where a
        source is narrower than a cell, but its reflection removed per view is still closer
        to the diffuse radiance than a low quantile of the colours. Textured plastic/lab
        30.4 -> 34.0 dB, plastic/grace 29.1 -> 34.4. (Where the map's light passes its gate
        on a texture, its SH part is likewise replaced by the edges' fit on that diffuse,
        beside the map's sun.)
    reflected_lobe : ``retinex-segmented`` also tries the light a shared Phong lobe of
        exponent ``phong_exponent`` reflects (:mod:`estimator.lobe_light`: SH radiance fitted
        to the colours' changes across views, every face's diffuse free, no Fresnel), first on
        every 4th face, and takes it when it explains at least ``reflected_min_explained`` of
        the view changes and more than the coat's map (lobe 0.998-0.9998 on the Phong textured
        scenes with a white specular of 0.2, where the map explains 0.979-0.994; 0.27 on smooth
        plastic/lab, 0.81-0.93 on roughplastic/park, 0.01 on a bare diffuse texture); uniform
        regions are then found again under it. Its DC, which the views cannot fix, is the one whose albedos vary
        least across the edges (:func:`estimator.lobe_light.dc_from_edges`); the edge search's
        sun (kept by that search or not) joins both terms as a delta light when its
        irradiance is positive and it lowers the edges' cost to ``reflected_sun_max_ratio``.
    ad_time_budget, ad_resolution, ad_spp, ad_learning_rate, ad_envmap_height : the
        ``mitsuba-ad`` peer: wall-clock seconds of Adam steps, the rendered width it aims at
        (the views are box-averaged by an integer factor), samples per pixel, Adam's
        learning rate, and the final envmap height (it starts at half, doubling halfway).
    ad_specular : ``mitsuba-ad`` fits a per-face specular albedo too, under Mitsuba's
        ``blendbsdf`` of diffuse and a near-mirror ``roughconductor`` (:mod:`estimator.peer`);
        False: Lambertian only.
    dense_rows : faces plus kept observations above which the reflection rows (float64, M
        wide) are not held in memory but computed in chunks when needed
        (:class:`estimator.pipeline.Prepared`); only the per-face methods stream
        (``bilinear-per-face``, ``known-illumination``, ``median-color``), the others refuse a
        larger problem with an error that says so. The default, 1.5 M rows, holds at most
        1.4 GiB of rows.
    light_faces : a streamed per-face solve finds the light from the observations of this
        many observed faces drawn at random (seeded), then every face's albedos with the
        light fixed: 121 light coefficients are determined many times over by 20,000 faces
        (earth-specular, 20,480 faces at 1024²: the light from 5,000 faces is 0.03 % from the
        held solve's, the albedos 0.03 % apart at the median, 98.05 % within ±10 % either
        way; benchmarks/README.md).
    albedo_prior : ``bilinear-per-face`` pulls each face's albedos toward its neighbours'
        where its own observations are weak (:mod:`estimator.albedo_prior`): an
        edge-preserving Cauchy prior on neighbour differences, this many times the data's
        own texture spread wide (0: off, the paper's per-face solve). 2 was chosen on
        earth-specular (full size, within ±10 %): shot noise 10 % 0.896 -> 0.934, 20 % 0.711
        -> 0.768, read noise 5 % 0.572 -> 0.604; clean unchanged at 0.980; read noise 10 % and
        20 %, where the noise exceeds most pixels, lose 0.006 and 0.027 (width 4 lost 0.13).
    pose_rounds, pose_folds : per-view pose refinement before the solve
        (:mod:`estimator.pose`): 0 rounds (the default) trusts the cameras; otherwise each
        camera first moves so the mesh's silhouette matches the view's alpha, then, each
        round, the views are split into ``pose_folds`` interleaved groups and each group is
        aligned with the image an estimate from the other groups predicts. On earth-specular
        (24 views) 2 rounds bring 2 degrees + 4 cm of jitter from 12.7 px to 0.6 px median
        reprojection error (benchmarks/README.md).
    auto_pose : with ``pose_rounds`` 0, the poses are refined anyway (2 rounds) when any view's
        alpha outline lies more than this many pixels from the mesh's outline under its
        camera (:func:`estimator.pose.outline_offsets`; 0: never). Correct poses measured
        0.01-0.28 px on every shipped and benchmark dataset; 0.5 deg of jitter 8.2 px at the
        worst view, a 3 % focal error 3.7 px. The check costs about 0.5 s for 24 views at 256².
    variant : Mitsuba variant for the ray queries (None: auto).
    """

    sh_order: int = 10
    directions: int = 1164
    iterations: int = 20
    tol: float = 1e-6
    components: str = "both"
    min_cos_view: float = 0.5
    min_pixels: int = 1
    pure_pixels: bool = True
    min_brightness: float = 0.03
    bandwidth: float = 0.08
    split_bandwidth: float = 0.2
    min_cluster_fraction: float = 0.01
    recluster_rounds: int = 5
    diffuse_light: str = "pseudo"
    defilter_order: int = 2
    phong_exponent: float = 10.0
    specular_model: str = "mirror"
    min_coverage: float = 0.999
    negative_tolerance: float = 0.01
    recluster_min_shading: float = 0.25
    recluster_shading_percentile: float = 90.0
    lm_damping_start: float = 1e-3
    lm_damping_raise: float = 4.0
    lm_damping_lower: float = 3.0
    lm_damping_max: float = 1e8
    diffuse_quantile: float = 0.25
    segment_threshold: float = 0.12
    uniform_spread: float = 0.08
    segment_min_shading: float = 0.05
    tie_regions: bool = True
    relabel_rounds: int = 3
    relabel_free_ratio: float = 3.0
    retinex_quantile: float = 0.2
    retinex_ridge: float = 1e-9
    retinex_iterations: int = 30
    retinex_min_uniform_share: float = 0.5
    region_max_deviation: float = 0.065
    region_max_drift: float = 1.85
    coat_correction: bool = True
    interreflection: bool = False
    coat_ior: float = 1.5
    coat_order: int = 4
    coat_min_share: float = 0.005
    coat_max_negative: float = 0.005
    sun_min_gain: float = 0.15
    reflected_light: bool = True
    reflected_regions: bool = True
    reflected_min_explained: float = 0.982
    reflected_sun_max_ratio: float = 0.97
    reflected_sun_max_angle: float = 6.0
    reflected_lobe: bool = True
    reflected_diffuse_min_explained: float = 0.9
    robust_loss: str = "auto"
    robust_rounds: int = 2
    glint_ratio: float = 4.0
    ad_time_budget: float = 60.0
    ad_resolution: int = 64
    ad_spp: int = 4
    ad_learning_rate: float = 0.02
    ad_envmap_height: int = 16
    ad_specular: bool = True
    dense_rows: int = 1_500_000
    light_faces: int = 20_000
    albedo_prior: float = 2.0
    pose_rounds: int = 0
    pose_folds: int = 4
    auto_pose: float = 1.0
    variant: str | None = None

    def __post_init__(self):
        self._check_types()
        checks = [
            (0 <= self.sh_order <= 30, "sh_order must lie in [0, 30]"),
            (self.directions >= 12, "directions must be >= 12"),
            (self.iterations >= 1, "iterations must be >= 1"),
            (self.tol >= 0, "tol must be >= 0"),
            (self.components in COMPONENTS, f"components must be one of {COMPONENTS}"),
            (-1.0 <= self.min_cos_view < 1.0, "min_cos_view must lie in [-1, 1)"),
            (self.min_pixels >= 1, "min_pixels must be >= 1"),
            (self.bandwidth > 0 and self.split_bandwidth > 0, "bandwidths must be > 0"),
            (0 <= self.min_brightness < 1, "min_brightness must lie in [0, 1)"),
            (0 <= self.min_cluster_fraction < 0.5, "min_cluster_fraction must lie in [0, 0.5)"),
            (self.recluster_rounds >= 1, "recluster_rounds must be >= 1"),
            (self.diffuse_light in DIFFUSE_LIGHTS, f"diffuse_light must be one of {DIFFUSE_LIGHTS}"),
            (0 <= self.defilter_order <= self.sh_order, "defilter_order must lie in [0, sh_order]"),
            (self.phong_exponent > 0, "phong_exponent must be > 0"),
            (self.specular_model in SPECULAR_MODELS, f"specular_model must be one of {SPECULAR_MODELS}"),
            (0 < self.min_coverage <= 1, "min_coverage must lie in (0, 1]"),
            (self.negative_tolerance >= 0, "negative_tolerance must be >= 0"),
            (0 <= self.diffuse_quantile <= 1, "diffuse_quantile must lie in [0, 1]"),
            (0 <= self.retinex_quantile <= 1, "retinex_quantile must lie in [0, 1]"),
            (self.retinex_ridge >= 0, "retinex_ridge must be >= 0"),
            (self.retinex_iterations >= 1, "retinex_iterations must be >= 1"),
            (0 <= self.retinex_min_uniform_share <= 1, "retinex_min_uniform_share must lie in [0, 1]"),
            (self.region_max_deviation > 0 and self.region_max_drift > 0,
             "region_max_deviation and region_max_drift must be > 0"),
            (0 <= self.reflected_min_explained <= 1, "reflected_min_explained must lie in [0, 1]"),
            (0 <= self.reflected_diffuse_min_explained <= 1, "reflected_diffuse_min_explained must lie in [0, 1]"),
            (self.reflected_sun_max_ratio >= 0, "reflected_sun_max_ratio must be >= 0"),
            (0 <= self.reflected_sun_max_angle <= 180, "reflected_sun_max_angle must lie in [0, 180] degrees"),
            (self.coat_ior > 1, "coat_ior must be > 1"),
            (0 <= self.coat_min_share < 1, "coat_min_share must lie in [0, 1)"),
            (0 <= self.coat_max_negative < 1, "coat_max_negative must lie in [0, 1)"),
            (self.coat_order >= 0, "coat_order must be >= 0"),
            (0 <= self.sun_min_gain <= 1, "sun_min_gain must lie in [0, 1]"),
            (self.robust_loss in LOSSES, f"robust_loss must be one of {LOSSES}"),
            (self.robust_rounds >= 0, "robust_rounds must be >= 0"),
            (self.glint_ratio > 1, "glint_ratio must be > 1"),
            (self.relabel_rounds >= 0, "relabel_rounds must be >= 0"),
            (self.relabel_free_ratio >= 1, "relabel_free_ratio must be >= 1"),
            (self.ad_time_budget > 0, "ad_time_budget must be > 0"),
            (self.ad_resolution >= 8 and self.ad_spp >= 1 and self.ad_envmap_height >= 4,
             "ad_resolution must be >= 8, ad_spp >= 1 and ad_envmap_height >= 4"),
            (self.ad_learning_rate > 0, "ad_learning_rate must be > 0"),
            (self.dense_rows >= 1, "dense_rows must be >= 1"),
            (self.light_faces >= 1, "light_faces must be >= 1"),
            (self.pose_rounds >= 0, "pose_rounds must be >= 0"),
            (self.albedo_prior >= 0, "albedo_prior must be >= 0 (0: off)"),
            (self.auto_pose >= 0, "auto_pose must be >= 0 (0: never)"),
            (self.pose_folds >= 2, "pose_folds must be >= 2 (a view group is aligned against an estimate "
                                   "from the other views)"),
            (0 <= self.segment_min_shading < 1, "segment_min_shading must lie in [0, 1)"),
            (self.segment_threshold > 0 and self.uniform_spread > 0,
             "segment_threshold and uniform_spread must be > 0"),
            (0 <= self.recluster_min_shading < 1, "recluster_min_shading must lie in [0, 1)"),
            (0 < self.recluster_shading_percentile <= 100, "recluster_shading_percentile must lie in (0, 100]"),
            (self.lm_damping_start > 0 and self.lm_damping_max > self.lm_damping_start,
             "lm_damping_start must be > 0 and below lm_damping_max"),
            (self.lm_damping_raise > 1 and self.lm_damping_lower > 1,
             "lm_damping_raise and lm_damping_lower must be > 1"),
        ]
        for ok, message in checks:
            if not ok:
                raise InputError(f"estimator config: {message}")
        if self.diffuse_light == "defiltered" and self.specular_model == "mirror":
            f = phong_filter(self.defilter_order, self.phong_exponent)
            if np.any(np.abs(f) < 1e-6):
                raise InputError(f"estimator config: the Phong filter of exponent {self.phong_exponent} vanishes "
                                 f"below degree {self.defilter_order}; lower defilter_order")

    def _check_types(self) -> None:
        """Each field has its default's type: int, float (an int is taken), bool or str
        (``variant`` may be None); floats must be finite."""
        for f in fields(self):
            value, default = getattr(self, f.name), f.default
            if f.name == "variant":
                ok = value is None or isinstance(value, str)
            elif isinstance(default, bool):
                ok = isinstance(value, bool)
            elif isinstance(default, int):
                ok = isinstance(value, int) and not isinstance(value, bool)
            elif isinstance(default, float):
                ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
                if ok:
                    object.__setattr__(self, f.name, float(value))
            else:
                ok = isinstance(value, type(default))
            if not ok:
                kind = ("a string or null" if f.name == "variant" else
                        "a finite number" if isinstance(default, float) else type(default).__name__)
                raise InputError(f"estimator config: {f.name} must be {kind}, got {value!r}")

    @property
    def lm_schedule(self) -> tuple[float, float, float, float]:
        """(start, raise, lower, max) damping of the Levenberg-Marquardt solve."""
        return self.lm_damping_start, self.lm_damping_raise, self.lm_damping_lower, self.lm_damping_max

    def to_dict(self) -> dict:
        return asdict(self)
