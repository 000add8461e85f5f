"""The estimator's one entry point, :func:`estimate`: pose check, preparation, the method's solve, screening, trust
diagnostics."""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from .config import EstimatorConfig
from .core import sh
from .core.blas import limited_blas
from .core.data import MultiViewData
from .core.errors import InputError, is_number
from .diagnostics import screening, trust
from .methods import get_method
from .methods.base import REGISTRY
from .model.estimate import Estimate
from .model.reflection_models import reflection_model
from .pipeline import exposure, pose
from .pipeline.observations import check_transparent
from .pipeline.prepared import Prepared, prepare, with_config
from .rays.raycast import RayCaster

EXPONENT_CANDIDATES = (5.0, 7.0, 10.0, 14.0, 20.0, 28.0, 40.0)

# the default for datasets that recommend no method (its accuracy against the paper's method:
# benchmarks/README.md); the paper's algorithm stays available, unchanged, as
# 'bilinear-clustered', and the previous default as 'bilinear-segmented'
DEFAULT_METHOD = "retinex-segmented"


def estimate(data: MultiViewData, method: str | None = None, config: EstimatorConfig | None = None,
             known_sh: np.ndarray | None = None, known_radiance: np.ndarray | None = None, log=None,
             exponent_candidates: tuple[float, ...] | None = None, caster: RayCaster | None = None) -> Estimate:
    """Run a registered method on in-memory data (the estimator's one entry point).

    Parameters
    ----------
    method : a registered name; None: :data:`DEFAULT_METHOD`.
    known_sh : (M', 3) pseudo illumination for 'known-illumination' (truncated/padded to the order).
    known_radiance : (M', 3) radiance SH, for 'known-illumination' with ``specular_model='lobe'``.
    log : optional callable receiving progress lines.
    exponent_candidates : estimate the Phong exponent too: solve with each candidate
        (observations and shadow function computed once) and keep the lowest final
        residual. Only models that depend on the exponent qualify
        (``specular_model='lobe'`` or ``diffuse_light='defiltered'``).
    caster : ray queries of ``data.mesh`` already built (None: built here), whose face-ID
        buffers of cameras it has traced before are reused (the pose refinement passes its own).

    The whole estimate runs with BLAS limited to ``config.blas_threads`` threads
    (:mod:`estimator.core.blas`).
    """
    config = EstimatorConfig() if config is None else config
    if not isinstance(config, EstimatorConfig):
        raise InputError(f"config must be an EstimatorConfig, got {type(config).__name__}")
    config.__post_init__()   # a field assigned after the config was made is checked as at its making
    if log is not None and not callable(log):
        raise InputError(f"log must be a callable taking one line, got {type(log).__name__}")
    for name, light in (("known_sh", known_sh), ("known_radiance", known_radiance)):
        if light is not None:
            shape = np.shape(light)
            if len(shape) != 2 or shape[1] != 3:
                raise InputError(f"{name} must be ((L + 1)^2, 3) SH coefficients per channel, got {shape}")
            sh.order_of(shape[0])
    if exponent_candidates is not None:
        exponent_candidates = tuple(exponent_candidates)
    if exponent_candidates is not None and not (
            len(exponent_candidates) and all(is_number(n) and np.isfinite(n) and n > 0 for n in exponent_candidates)):
        raise InputError(f"exponent_candidates must be Phong exponents > 0, at least one, got {exponent_candidates!r}")
    with limited_blas(config.blas_threads):
        return _estimate(data, method, config, known_sh, known_radiance, log, exponent_candidates, caster)


def _estimate(data: MultiViewData, method: str | None, config: EstimatorConfig, known_sh: np.ndarray | None,
              known_radiance: np.ndarray | None, log, exponent_candidates: tuple[float, ...] | None,
              caster: RayCaster | None) -> Estimate:
    """:func:`estimate`'s body, its BLAS limit set."""
    cls = get_method(DEFAULT_METHOD if method is None else method)
    t0 = time.perf_counter()
    poses, rounds, offsets = None, config.pose_rounds, None
    if caster is not None and caster.mesh is not data.mesh:
        raise InputError("estimate: the caster was built for another mesh than data.mesh")
    # one for the pose check, the refinement and the solve: each view's
    # face-ID buffers are traced once per camera
    caster = caster or RayCaster(data.mesh, config.variant)
    check_transparent(data.views, config.min_coverage)   # before the pose check and refinement trace them
    if rounds == 0 and config.auto_pose > 0 and len(data.views) >= 2:
        offsets = pose.outline_offsets(data, caster)
        if np.nanmax(offsets, initial=0.0) > config.auto_pose:
            rounds = pose.POSE_ROUNDS
            if log:
                log(f"a view's outline is {np.nanmax(offsets):.1f} px off its alpha: refining the poses")
    last: list[Estimate] = []   # the pose refinement's last held-out estimate: where the final solve starts
    if rounds > 0:
        fixed = replace(config, pose_rounds=0, auto_pose=0.0)

        def held_out(d: MultiViewData, prior: Estimate | None) -> Estimate:
            last[:] = [_fit(d, cls, fixed, known_sh, known_radiance, None, exponent_candidates, caster, prior)[0]]
            return last[0]

        if config.pose_folds > len(data.views) and log:
            log(f"pose refinement: pose_folds {config.pose_folds} exceeds the {len(data.views)} views; "
                f"{len(data.views)} groups of one view each")
        data, poses = pose.refine_poses(data, held_out, rounds, min(config.pose_folds, len(data.views)), caster, log)
    pose_seconds = time.perf_counter() - t0
    est, prep, gains, solve_seconds = _fit(data, cls, config, known_sh, known_radiance, log, exponent_candidates,
                                           caster, last[0] if last else None)
    t = time.perf_counter()
    est.info["trust"], stats = trust.diagnose(prep, est, [v.name for v in data.views])
    if gains is not None:   # null for a view that gives no observation: nothing estimated its gain
        silent = set(prep.all_obs.rowless_views.tolist()) | set(prep.all_obs.black_views.tolist())
        est.info["view_gains"] = {v.name: None if i in silent else g.tolist()
                                  for i, (v, g) in enumerate(zip(data.views, gains))}
    est.info["observations"] = int(len(prep.obs.face))
    est.info["observations_all"] = int(len(prep.all_obs.face))
    unresolved = prep.all_obs.unresolved
    est.info["unresolved_faces"] = 0 if unresolved is None else int(unresolved.sum())
    est.info["unobserved_share"] = float(1.0 - est.observed.mean())
    est.info["faces_without_kept_views"] = float(1.0 - prep.obs.observed_faces().mean())
    rejected = prep.all_obs.rejected
    est.info["rejected_pixels"] = {v.name: int(n) for v, n in zip(data.views, rejected) if n > 0}
    est.info["rowless_views"] = rowless = [data.views[int(i)].name for i in prep.all_obs.rowless_views]
    est.info["black_views"] = black = [data.views[int(i)].name for i in prep.all_obs.black_views]
    est.info["winding_conflicts"] = conflicts = int(data.mesh.winding_conflicts().sum())
    est.info["timings"] = {**prep.timings, "solve": solve_seconds, "trust": time.perf_counter() - t,
                           "total": time.perf_counter() - t0}
    if offsets is not None:
        est.info["outline_offsets_px"] = {v.name: (None if np.isnan(o) else float(o))
                                          for v, o in zip(data.views, offsets)}
    if poses is not None:
        est.info["timings"]["pose_refinement"] = pose_seconds
        est.info["poses"] = poses
    est.face_stats = {**est.face_stats, **stats}
    automatic = [] if poses is None or config.pose_rounds > 0 else [
        f"poses refined automatically ({pose.POSE_ROUNDS} rounds): the alpha outline of "
        f"{data.views[int(np.nanargmax(offsets))].name} lay {np.nanmax(offsets):.1f} px from the mesh's "
        f"(auto_pose {config.auto_pose:g} px); the corrected cameras are in 'poses'"]
    off = sorted((p for p in poses or [] if (p["outline_px"] or 0.0) > pose.POSE_OUTLINE_TOLERANCE),
                 key=lambda p: -p["outline_px"])
    unaligned = [p["name"] for p in poses or [] if p["unaligned_rounds"]]
    undone = [p["name"] for p in poses or [] if p["outline_reverted"]]
    small = [p["name"] for p in poses or [] if p.get("too_small")]
    scale = _scale_shift(poses or [], float(np.median([v.camera.width for v in data.views])))
    flat, repeated = data.mesh.degenerate_faces()
    est.info["warnings"] = est.info.get("method_warnings", []) + trust.warnings_for(est) + automatic + _mesh_warnings(
        flat, repeated) + _rowless_warnings(rowless, config.min_pixels) + _black_warnings(black) + (
        _winding_warnings(conflicts) if conflicts else []) + [
        f"pose refinement of {p['name']} diverged (beyond {pose.POSE_MAX_DEGREES:g} deg or "
        f"{pose.POSE_MAX_SHIFT:g} x the distance): it keeps its silhouette-aligned pose" for p in poses or []
        if p["diverged"]] + ([
        f"pose refinement: {len(unaligned)} view(s) were not aligned in some round, the other views determining no "
        f"estimate ({_first(unaligned)}; 'unaligned_rounds' in "
        "'poses'): raise pose_folds, so that each held-out estimate has more views"] if unaligned else []) + ([
        f"pose refinement: {len(small)} view(s) show fewer than {pose.POSE_MIN_POINTS} pixels of estimated faces, "
        f"too few to align, and keep their poses ({_first(small)}; 'too_small' in 'poses'): the object is too small "
        "in them (bring the cameras closer or raise the resolution)"] if small else []) + ([
        f"pose refinement moved the cameras {'closer to' if scale > 0 else 'farther from'} the object by a median "
        f"{100 * abs(scale):.1f} % of their distance, all alike: the images show the object "
        f"{'larger' if scale > 0 else 'smaller'} than the mesh under the given intrinsics, as a focal length "
        f"{'shorter' if scale > 0 else 'longer'} than the camera's (or a mesh in other units) would; the refined "
        "poses absorb it but fit the views less well: check fl_x, fl_y and the mesh's scale ('approach' in "
        "'poses')"] if scale else []) + ([
        f"pose refinement: the last alignment of {len(undone)} view(s) moved their alpha outline more than "
        f"{pose.POSE_OUTLINE_TOLERANCE:g} px off the mesh's, and farther than before, so it was undone and they keep "
        f"their pose from before it ({_first(undone)}; 'outline_reverted' "
        "in 'poses'): the estimate predicts these views poorly"] if undone else []) + ([
        f"after pose refinement the alpha outline of {len(off)} view(s) still lies more than "
        f"{pose.POSE_OUTLINE_TOLERANCE:g} px from the mesh's ({off[0]['name']}: {off[0]['outline_px']:.1f} px; "
        "'outline_px' in 'poses'): the refinement matched no pose to their silhouettes; check the intrinsics (focal "
        "length, principal point) and the mesh's scale against the images"] if off else [])
    return est


SCALE_MIN_VIEWS = 5   # views a scale motion is judged on at least: the MAD of fewer says little


def _scale_shift(poses: list[dict], width: float) -> float:
    """The median share by which the pose refinement moved the views closer to the object
    (:func:`pose.approach`), over the views it aligned (not diverged, not too small, never left
    unaligned), where the motion is a scale error rather than noise (0.0 otherwise): at least
    :data:`SCALE_MIN_VIEWS` views, the median more than 3 of its robust standard errors from 0
    (1.2533 x 1.4826 x the median absolute deviation / sqrt(n)), and moving the image's edge by
    more than half a pixel (share x ``width`` / 2 > 0.5): below that no view can show it."""
    shares = np.array([p["approach"] for p in poses
                       if not (p["diverged"] or p.get("too_small") or p["unaligned_rounds"])])
    if len(shares) < SCALE_MIN_VIEWS:
        return 0.0
    median = float(np.median(shares))
    error = 1.2533 * 1.4826 * float(np.median(np.abs(shares - median))) / np.sqrt(len(shares))
    return median if abs(median) > 3.0 * error and abs(median) * width / 2.0 > 0.5 else 0.0


def _first(names: list[str]) -> str:
    """The first five of ``names``, comma-separated, then ' ...' where there are more."""
    return ", ".join(names[:5]) + (" ..." if len(names) > 5 else "")


def _rowless_warnings(names: list[str], min_pixels: int) -> list[str]:
    """The warning for views that show the mesh but give no observation (``names``, may be
    empty), with the ``min_pixels`` of the run."""
    if not names:
        return []
    cover = "a pixel of theirs whole" if min_pixels == 1 else f"min_pixels={min_pixels} of their pixels whole"
    cause = "" if min_pixels == 1 else ", or min_pixels too high for their resolution"
    return [f"{len(names)} view(s) show the mesh but give no observation: no face covers {cover} (a camera far "
            f"from the object among nearer ones{cause}); faces that only they show stay unestimated "
            f"({_first(names)}; 'rowless_views')"]


def _black_warnings(names: list[str]) -> list[str]:
    """The warning for views that show the mesh black (``names``, may be empty)."""
    if not names:
        return []
    return [f"{len(names)} view(s) show the mesh black, no pixel on it above zero (a failed capture, or only the "
            f"object's unlit side): they give no observation ({_first(names)}; 'black_views')"]


def _winding_warnings(conflicts: int) -> list[str]:
    """The warning for ``conflicts`` (> 0) edges whose two faces are wound in opposite directions."""
    return [f"{conflicts} edge(s) of the mesh join faces wound in opposite directions: a face whose normal points "
            "into the object is seen from behind and never estimated; make the winding consistent (e.g. "
            "trimesh.repair.fix_winding; 'winding_conflicts')"]


def _mesh_warnings(flat: np.ndarray, repeated: np.ndarray) -> list[str]:
    """Warnings for the mesh's faces without a normal and repeated faces ((F,) bool each)."""
    out = []
    if flat.any():
        out.append(f"{int(flat.sum())} face(s) of the mesh have zero area or corners in a line, to the rounding of "
                   f"their coordinates (first: {int(np.argmax(flat))}): they have no normal, are never observed and "
                   "stay unestimated")
    if repeated.any():
        out.append(f"{int(repeated.sum())} face(s) of the mesh repeat the corners of an earlier face (first: "
                   f"{int(np.argmax(repeated))}): the rays hit one of each pair, so the other stays unestimated")
    return out


def _fit(data: MultiViewData, cls, config: EstimatorConfig, known_sh, known_radiance, log, exponent_candidates,
         caster: RayCaster, prior: Estimate | None = None) -> tuple[Estimate, Prepared, np.ndarray | None, float]:
    """The shared stages, the exposure gains, the method's solve and the screening of faces
    whose albedo the data do not determine, without the trust diagnostics (a held-out
    estimate of the pose refinement needs only the estimate). Returns (the estimate with
    ``info['unestimated']``, the prepared problem, the views' gains or None, the solve's seconds).
    ``prior``: an estimate of the same scene from other views, where the method may start."""
    prep = prepare(data, config, log, cls.name, cls.streams, caster,
                   ", ".join(sorted(name for name, kind in REGISTRY.items() if kind.streams)))
    if prep.all_obs.thin is not None and not cls.joins_thin_faces:
        prep = prep.without_thin()
    gains = None
    if config.view_gains:   # from the rows the fit takes: not a thin face's, unmixed from shared pixels
        gains = exposure.view_gains(prep.without_thin().obs)
        prep = exposure.divide_gains(prep, gains)
        if log:
            log(f"view gains: {gains.min():.3f} to {gains.max():.3f} over the views and channels")
    if not np.any(prep.obs.rgb > 0):
        raise InputError("every observed pixel is black or negative: there is no light to estimate from "
                         "(check the images' exposure and sign)")
    t = time.perf_counter()
    try:
        est = _solve(cls, prep, config, known_sh, known_radiance, log, exponent_candidates, prior)
    except np.linalg.LinAlgError as exc:
        raise InputError(f"the solve is singular ({exc}): the observations do not determine the albedos and "
                         "the light (too few lit views or faces?)") from None
    if not np.all(np.isfinite(est.pseudo_sh)):
        raise InputError("the solve produced a non-finite light: the observations do not determine the albedos and "
                         "the light (too few lit views or faces?)")
    solve_seconds = time.perf_counter() - t
    est.info["unestimated"] = _screen(prep, est, cls.reports_residual)
    return est, prep, gains, solve_seconds


def _screen(prep: Prepared, est: Estimate, fitted: bool) -> dict[str, int]:
    """Faces whose albedo the data do not determine marked unestimated
    (:mod:`estimator.diagnostics.screening`). ``fitted``: the method fits the reflection
    model to the observations, so each albedo's standard error under it is its own (a method
    that fits nothing is judged by range only). Returns the count of faces set aside per reason."""
    counts = screening.mark_unestimated(est, screening.left_out(est, prep.obs.observed_faces()))
    counts.update(screening.mark_unestimated(est, screening.out_of_range(est)))
    if not est.observed.any():
        raise InputError("no face has a finite albedo within the physical range: the observations do not "
                         "determine the albedos and the light (too few lit views or faces?)")
    code = np.zeros(len(est.observed), np.int8)
    if fitted:
        diffuse_precision, specular_precision = trust.albedo_precision(prep, est)
        own = specular_precision if est.config.components == "specular" else diffuse_precision
        code[screening.undetermined(est, own)] = 3
        rows = np.bincount(prep.obs.face, minlength=len(code))
        code[(code == 0) & screening.contradicted(est, own, rows)] = 4
    if code.any():
        counts.update(screening.mark_unestimated(est, code))
        if not est.observed.any():
            raise InputError("no face's albedo is determined by the observations (each one's standard error "
                             "exceeds its value): add views or light")
    return counts


def _solve(cls, prep, config, known_sh, known_radiance, log, exponent_candidates, prior=None) -> Estimate:
    if exponent_candidates:
        if not reflection_model(config).uses_exponent:
            raise InputError("estimating the Phong exponent needs a model that depends on it: "
                             "specular_model='lobe' or diffuse_light='defiltered'")
        if not cls.reports_residual:
            raise InputError(f"estimating the Phong exponent compares the methods' residuals; {cls.name} reports "
                             "none (choose a method that fits the observations, or give the exponent)")
        tried = {}
        for n in exponent_candidates:
            candidate = cls(replace(config, phong_exponent=float(n)), known_sh, known_radiance, prior=prior)
            tried[float(n)] = candidate.solve(with_config(prep, candidate.config))
            if log:
                log(f"phong exponent {n}: residual {tried[float(n)].info['residuals'][-1]:.5f}")
        est = min(tried.values(), key=lambda e: e.info["residuals"][-1])
        est.info["exponent_selection"] = {str(n): e.info["residuals"][-1] for n, e in tried.items()}
        if log:
            log(f"phong exponent chosen: {est.config.phong_exponent:g} (the lowest final residual, "
                f"{est.info['residuals'][-1]:.5f})")
        return est
    return cls(config, known_sh, known_radiance, log, prior).solve(prep)
