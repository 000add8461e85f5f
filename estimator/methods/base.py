"""The method contract: the :class:`Method` base class and the registry of methods by name.

A new method is one class in its own file of this room, decorated with
:func:`register_method` and imported in ``estimator/methods/__init__.py``."""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from ..core import sh
from ..core.errors import InputError
from ..model.estimate import Estimate
from ..model.reflection_models import reflection_model
from ..pipeline.prepared import Prepared
from ..solvers import robust
from ..solvers.bilinear import BilinearResult, solve_bilinear

if TYPE_CHECKING:   # the config composes every room's section, this one's too
    from ..config import EstimatorConfig


REGISTRY: dict[str, type["Method"]] = {}

def register_method(cls: type["Method"]) -> type["Method"]:
    """Class decorator: make a method available under ``cls.name``."""
    if not getattr(cls, "name", None):
        raise InputError(f"{cls.__name__} needs a 'name'")
    REGISTRY[cls.name] = cls
    return cls


def get_method(name: str) -> type["Method"]:
    if name not in REGISTRY:
        raise InputError(f"unknown method {name!r}; registered: {', '.join(sorted(REGISTRY))}")
    return REGISTRY[name]


class Method(ABC):
    """A way to turn prepared observations into an Estimate."""

    name: ClassVar[str] = ""
    needs_illumination: ClassVar[bool] = False
    default_loss: ClassVar[str] = "none"
    streams: ClassVar[bool] = False   # solve() accepts a streamed problem (Prepared.streamed)
    # solve() takes the rows of thin faces (Observations.thin: unmixed from pixels they share)
    # and decides what they may determine; for the other methods they are dropped before the
    # solve, so those see a resolved mesh's faces as they always have
    joins_thin_faces: ClassVar[bool] = False
    # info["residuals"] holds the relative residual after each step, the last the final fit's:
    # what the Phong exponent is selected by (tests/estimator/test_method_contract.py checks it)
    reports_residual: ClassVar[bool] = True

    def __init__(self, config: EstimatorConfig, known_sh: np.ndarray | None = None,
                 known_radiance: np.ndarray | None = None, log=None, prior: Estimate | None = None):
        self.config = config
        # an estimate of the same object and light from other views (the pose refinement's
        # previous held-out estimate): a method may start its light there, and a robust solve
        # its weights (_prior_weights). On a well-determined problem the result is the cold
        # start's within the solver's tolerance; where the data leave several local optima,
        # the one reached may differ
        self.prior = prior
        self.model = reflection_model(config)
        self.known_sh = known_sh
        self.known_radiance = known_radiance
        self.log = log or (lambda message: None)   # progress lines of a long solve

    @abstractmethod
    def solve(self, prep: Prepared) -> Estimate: ...

    def _from_groups(self, prep: Prepared, face_group: np.ndarray, result: BilinearResult,
                     observed: np.ndarray, info: dict) -> Estimate:
        f = prep.data.mesh.num_faces
        diffuse, specular = np.zeros((f, 3)), np.zeros((f, 3))
        diffuse[observed] = result.diffuse[face_group[observed]]
        specular[observed] = result.specular[face_group[observed]]
        labels = np.where(observed, face_group, -1).astype(np.int64)
        groups = len(np.unique(face_group[prep.obs.face]))
        per_group = 2 if self.config.components == "both" else 1
        light_unknowns = 0 if self.needs_illumination else result.light.shape[0] - 1   # unit DC: the gauge
        info = {**info, "residuals": result.residuals, "lm_residuals": result.lm_residuals,
                "lm_steps": [len(r) for r in result.lm_residuals],
                "degrees_of_freedom": {"observations": int(3 * len(prep.obs.face)),
                                       "unknowns": int(3 * (groups * per_group + light_unknowns))}}
        radiance = result.light if self.model.light == "radiance" else None
        return Estimate(diffuse, specular, self.model.pseudo_from_light(result.light), labels, observed,
                        self.name, self.config, info, radiance)

    def _solve_groups(self, prep: Prepared, face_group: np.ndarray, num_groups: int,
                      fixed_light: np.ndarray | None = None, weights: np.ndarray | None = None) -> BilinearResult:
        """The bilinear solve over groups; ``weights`` (N,) scale each observation's squared
        residual. With ``config.robust_loss`` other than 'none', the solve is iteratively
        reweighted (:mod:`estimator.solvers.robust`): glints are clipped at ``glint_ratio`` x the
        face's median colour first, then ``robust_rounds`` rounds reweight every row by the
        loss of its relative residual. With a prior estimate of the faces (:meth:`_prior_weights`),
        a free light and ``robust_rounds`` >= 1, the first weights are the prior's and
        ``robust_rounds`` - 1 rounds follow. The result's ``weights`` are the final ones."""
        base = np.ones(len(prep.obs.face)) if weights is None else weights
        if self.loss == "none":
            result = self._weighted_solve(prep, face_group, num_groups, fixed_light, weights, self._prior_light())
            result.weights = base
            return result
        warm = self._prior_weights(prep, base) if self.config.robust_rounds > 0 and fixed_light is None else None
        w = base * (self._initial_weights(prep) if warm is None else warm)
        rounds = self.config.robust_rounds - (warm is not None)
        result = None
        for round_ in range(rounds + 1):
            result = self._weighted_solve(prep, face_group, num_groups, fixed_light, w,
                                          self._prior_light() if result is None else result.light)
            if round_ < rounds:
                w = base * self._reweight(prep, face_group, result, base)
        result.weights = w
        return result

    def _prior_light(self) -> np.ndarray | None:
        """(M, 3) the prior estimate's light unknown where it has this model's shape, else None."""
        if self.prior is None or self.prior.model.light != self.model.light:
            return None
        light = self.prior.light
        return light if light is not None and light.shape == (sh.num_coeffs(self.config.sh_order), 3) else None

    @property
    def loss(self) -> str:
        """The robust loss in use: ``config.robust_loss``, or the method's own for 'auto'."""
        return self.default_loss if self.config.robust_loss == "auto" else self.config.robust_loss

    def _prior_weights(self, prep: Prepared, base: np.ndarray) -> np.ndarray | None:
        """(N,) the robust weights of every row under the prior estimate (its albedos and
        light), where it has this model's light and estimated the rows' faces; None without
        one. A prior from other views of the same object has been through the reweighting
        already, so its weights stand in for the first round's (a warm start of the
        reweighting: one bilinear solve fewer). Rows of faces the prior left unestimated get
        the glint clipping of :meth:`_initial_weights`. Only a problem on the mesh's own faces
        qualifies: a face subset or a clustered problem numbers its faces otherwise."""
        light = self._prior_light()
        faces = prep.data.mesh.num_faces
        if light is None or prep.adjacency is not None or prep.obs.num_faces != faces \
                or self.prior.diffuse.shape[0] != faces:
            return None
        obs = prep.obs
        known = self.prior.observed[obs.face] & np.all(np.isfinite(self.prior.diffuse[obs.face])
                                                       & np.isfinite(self.prior.specular[obs.face]), axis=1)
        if not known.any():
            return None
        diffuse = np.where(known[:, None], self.prior.diffuse[obs.face], 0.0)
        specular = np.where(known[:, None], self.prior.specular[obs.face], 0.0)
        weights = self._weights_under(prep, diffuse, specular, light, base * known)
        return np.where(known, weights, self._initial_weights(prep))

    def _initial_weights(self, prep: Prepared) -> np.ndarray:
        """(N,) glint clipping before the first robust solve (ones without a robust loss)."""
        if self.loss == "none":
            return np.ones(len(prep.obs.face))
        obs = prep.obs
        return robust.initial_weights(obs.face, obs.rgb, obs.num_faces, self.config.glint_ratio, obs.face_levels)

    def _reweight(self, prep: Prepared, face_group: np.ndarray, result: BilinearResult,
                  base: np.ndarray | None = None) -> np.ndarray:
        """(N,) robust weights of every observation under ``result`` (ones without a robust
        loss); the scale is taken over the rows with ``base`` > 0."""
        if self.loss == "none":
            return np.ones(len(prep.obs.face))
        g = face_group[prep.obs.face]
        return self._weights_under(prep, result.diffuse[g], result.specular[g], result.light, base)

    def _weights_under(self, prep: Prepared, diffuse: np.ndarray, specular: np.ndarray, light: np.ndarray,
                       among: np.ndarray | None) -> np.ndarray:
        """(N,) the robust loss's weights of the rows under the albedos ``diffuse`` and
        ``specular`` (N, 3), one per row, and the light unknown ``light`` (M, 3); the scale is
        taken over the rows with ``among`` > 0 (None: every row)."""
        predicted = self.model.predict(diffuse, specular, prep.c_rows @ light, prep.d_rows @ light)
        r = robust.relative_residuals(prep.obs.rgb, predicted)
        return robust.irls_weights(r, self.loss, robust.robust_scale(r, among))

    def _weighted_solve(self, prep: Prepared, face_group: np.ndarray, num_groups: int,
                        fixed_light: np.ndarray | None, weights: np.ndarray | None,
                        initial_light: np.ndarray | None = None) -> BilinearResult:
        """One bilinear solve; rows are multiplied by the square root of ``weights`` (the
        model is linear in its rows)."""
        c = self.config
        rgb, c_rows, d_rows = prep.obs.rgb, prep.c_rows, prep.d_rows
        if weights is not None:
            root = np.sqrt(weights)[:, None]
            rgb, c_rows, d_rows = rgb * root, c_rows * root, d_rows * root
        return solve_bilinear(rgb, face_group[prep.obs.face], c_rows, d_rows, num_groups,
                              c.components, c.iterations, c.tol, fixed_light, schedule=c.lm_schedule,
                              initial_light=initial_light)

    def _solve_per_face(self, prep: Prepared, fixed_light: np.ndarray | None = None) -> Estimate:
        """Every observed face its own group. A streamed problem (:attr:`Prepared.streamed`)
        is solved in two steps of bounded memory: the light from the observations of
        ``config.light_faces`` observed faces drawn at random (seed 0), then every face's
        albedos with that light fixed, on the rows' projections onto it. A light given
        (``fixed_light``) is used the same way: the robust rounds weigh (N, 3) projections
        instead of (N, M) rows."""
        group, observed, g = _per_face_groups(prep)
        info = {"clusters": g}
        if fixed_light is None and not prep.streamed:
            return self._from_groups(prep, group, self._solve_groups(prep, group, g), observed, info)
        light = fixed_light
        if light is None:
            seen = np.nonzero(observed)[0]
            sample = np.sort(np.random.default_rng(0).choice(seen, min(self.config.light_faces, len(seen)),
                                                             replace=False))
            sub = prep.face_subset(sample)
            sub_group, _, sub_g = _per_face_groups(sub)
            light = self._solve_groups(sub, sub_group, sub_g).light
            info["light_faces"] = int(len(sample))
        result = self._solve_groups(prep.projected(light), group, g, np.eye(3))
        result.light = light
        return self._from_groups(prep, group, result, observed, info)


def _per_face_groups(prep: Prepared) -> tuple[np.ndarray, np.ndarray, int]:
    observed = prep.obs.observed_faces()
    group = np.cumsum(observed) - 1
    return np.where(observed, group, 0), observed, int(observed.sum())
