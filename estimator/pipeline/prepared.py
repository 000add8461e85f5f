"""The stages every method shares: observations, shadow function, reflection matrices."""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import sparse

from ..core import sh
from ..core.data import MultiViewData, TriangleMesh
from ..core.errors import InputError
from ..core.settings import Section
from ..model.reflection import mirror_directions
from ..model.reflection_models import ReflectionConfig, ReflectionModel, reflection_model
from ..rays.backend import BackendConfig
from ..rays.raycast import ClusterCaster, RayCaster
from ..rays.visibility import SphereSampling, Visibility, VisibilityConfig, shadow_function, sphere_sampling
from .observations import ObservationConfig, Observations, gather_observations

ROW_CHUNK = 65_536   # rows of a reflection matrix computed at once when they are streamed (~63 MB)


@dataclass
class StreamingConfig(Section):
    """When the reflection rows are streamed instead of held, and how a streamed light is found.

    Attributes
    ----------
    dense_rows : faces plus kept observations above which the reflection rows (float64, M
        wide) are not held in memory but computed in chunks when needed (:class:`Prepared`);
        1.5 M rows hold at most 1.4 GiB. Only methods with ``streams`` accept such a problem.
        It also bounds the pixels whose equations in the faces they cover are held
        (:mod:`.footprints`): beyond it, the faces of a mesh denser than its photos are
        observed through their pixel centres, and the thin faces of a resolved one
        (:attr:`.observations.Observations.thin`) not at all.
    light_faces : a streamed solve finds the light from the observations of this many
        observed faces, then every face's albedos with the light fixed: 121 light
        coefficients are determined many times over by 20,000 faces. The per-face methods
        draw them at random (seeded); the default solves on at most this many clusters of
        faces (fewer on a mesh denser than its photos, ``retinex_segmented.clusters``). At
        least the light's (sh_order + 1)^2 coefficients (:class:`PrepareConfig` checks it).
    """

    dense_rows: int = 1_500_000
    light_faces: int = 20_000

    def check(self):
        return [(self.dense_rows >= 1, "dense_rows must be >= 1"),
                (self.light_faces >= 1, "light_faces must be >= 1")]


@dataclass
class PrepareConfig(StreamingConfig, ObservationConfig, VisibilityConfig, BackendConfig, ReflectionConfig):
    """Every setting :func:`prepare` reads: the reflection model, the variant, the shadow
    function's directions, the observations and the streaming threshold."""

    def check(self):
        m = sh.num_coeffs(self.sh_order)
        return [(self.light_faces >= m, f"light_faces must be at least the light's (sh_order + 1)^2 = {m} "
                                        "coefficients: fewer faces leave the light undetermined")]


@dataclass
class Prepared:
    """Inputs of the solvers, computed once per dataset.

    Attributes
    ----------
    model : the reflection model of ``config``.
    all_obs : every observation (for median colours).
    obs : observations kept for the solve (``min_cos_view`` cut).
    c_matrix : (F, M) the model's diffuse rows of every face, or None when streamed.
    d_rows : (N, M) the model's specular rows of ``obs``, or None when streamed. Both
        multiply the model's light unknown (h, or L for a radiance model).
    timings : seconds per stage.

    A problem larger than ``config.dense_rows`` (faces plus kept observations) is
    *streamed*: the rows are never held whole, and :meth:`diffuse_rows`,
    :meth:`specular_rows`, :meth:`shading` and :meth:`gloss` compute them in chunks of
    :data:`ROW_CHUNK`, so memory stays linear in faces and observations with small constants.
    """

    data: MultiViewData
    config: PrepareConfig
    model: ReflectionModel
    caster: RayCaster
    sampling: SphereSampling
    visibility: Visibility
    all_obs: Observations
    obs: Observations
    c_matrix: np.ndarray
    d_rows: np.ndarray
    timings: dict = field(default_factory=dict)
    adjacency: np.ndarray | None = None   # (E, 2) a clustered problem's adjacent faces (None: the mesh's)
    merged_faces: bool = False            # a clustered problem's faces are clusters of several faces
    # the last light's projections (shading, gloss): a streamed problem's cost one full pass over
    # the rows each, and the solve and the trust diagnostics ask for the same light
    _projections: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def streamed(self) -> bool:
        """True when the reflection rows are computed on demand instead of held."""
        return self.d_rows is None

    @property
    def blends_albedos(self) -> bool:
        """True when a face's colour may blend its neighbours' albedos: the faces are clusters of
        several faces (:meth:`clustered`), or faces smaller than the pixels that see them
        (observed through their pixel centres, :attr:`Observations.unresolved`). A face on a
        boundary then shows a colour between the two sides' (the segmentation cuts a component
        at such bridges where its parts differ: :func:`estimator.solvers.segmentation.segment`)."""
        return self.merged_faces or self.all_obs.unresolved is not None

    @property
    def c_rows(self) -> np.ndarray:
        """(N, M) diffuse matrix row of each kept observation's face (held rows only)."""
        if self.streamed:
            raise InputError("the reflection rows of this problem are streamed (config.dense_rows): "
                             "use diffuse_rows/specular_rows on chunks")
        return self.c_matrix[self.obs.face]

    def diffuse_rows(self, faces: np.ndarray, coat_ior: float | None = None) -> np.ndarray:
        """(n, M) diffuse rows C_i of the faces (n,); with ``coat_ior``, of the light that
        passes a smooth coat of that index on its way in."""
        if not self.streamed and coat_ior is None:
            return self.c_matrix[faces]
        return self.model.diffuse_matrix(self.data.mesh, self.sampling, self.visibility, faces, coat_ior)

    def specular_rows(self, rows: np.ndarray) -> np.ndarray:
        """(n, M) specular rows D_k of the kept observations ``rows`` (n,) (indices into ``obs``)."""
        if not self.streamed:
            return self.d_rows[rows]
        return self.model.specular_rows(*self._mirrored(rows), self.sampling, self.visibility)

    def shading(self, light: np.ndarray, coat_ior: float | None = None) -> np.ndarray:
        """(F, C) C_i . x of every face under the light unknown ``light`` (M, C); with
        ``coat_ior``, through a smooth coat of that index (:meth:`diffuse_rows`)."""
        if not self.streamed and coat_ior is None:
            return self.c_matrix @ light
        return self._projection(("shading", coat_ior), light, self.data.mesh.num_faces,
                                lambda part: self.diffuse_rows(part, coat_ior) @ light)

    def gloss(self, light: np.ndarray) -> np.ndarray:
        """(N, C) D_k . x of every kept observation under the light unknown ``light`` (M, C)."""
        if not self.streamed:
            return self.d_rows @ light
        return self._projection("gloss", light, len(self.obs.face), lambda part: self._gloss_rows(part, light))

    def row_mirrors(self, rows: np.ndarray) -> np.ndarray:
        """(n, 3) the view direction of the kept observations ``rows`` (n,) mirrored about their face's normal."""
        return self._mirrored(rows)[1]

    def _gloss_rows(self, rows: np.ndarray, light: np.ndarray) -> np.ndarray:
        """(n, C) D_k . x of the kept observations ``rows`` (n,) of a streamed problem."""
        return self.model.specular_shading(*self._mirrored(rows), self.sampling, self.visibility, light)

    def _mirrored(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(face (n,), mirrored view direction (n, 3)) of the kept observations ``rows`` (n,)."""
        face = self.obs.face[rows]
        return face, mirror_directions(self.data.mesh.face_normals[face], self.obs.view_dir[rows])

    def _projection(self, kind, light: np.ndarray, count: int, rows_times_light) -> np.ndarray:
        """A streamed projection, in chunks of :data:`ROW_CHUNK` rows; the last light's is kept
        per ``kind`` (a hashable key)."""
        key = (light.shape, light.tobytes())
        cached = self._projections.get(kind)
        if cached is None or cached[0] != key:
            value = np.concatenate([rows_times_light(np.arange(s, min(s + ROW_CHUNK, count)))
                                    for s in range(0, count, ROW_CHUNK)])
            self._projections[kind] = cached = (key, value)
        return cached[1]

    def face_subset(self, faces: np.ndarray) -> "Prepared":
        """The problem restricted to ``faces`` (S,) (sorted, unique), renumbered 0..S-1,
        with its rows held: a light solved on it is a light of the whole problem."""
        mapping = np.full(self.obs.num_faces, -1, dtype=np.int64)
        mapping[faces] = np.arange(len(faces))
        keep = mapping[self.obs.face] >= 0
        sub = self.obs.subset(keep)
        return replace(self, obs=replace(sub, face=mapping[sub.face], num_faces=len(faces), thin=None),
                       c_matrix=self.diffuse_rows(faces), d_rows=self.specular_rows(np.nonzero(keep)[0]),
                       timings=dict(self.timings))

    def row_subset(self, keep: np.ndarray) -> "Prepared":
        """The problem with the kept observations ``keep`` (N,) bool of ``obs`` alone (rows
        held; the faces, their numbering and ``all_obs`` as they are, and no face thin:
        :attr:`Observations.thin` names faces whose rows these may have left out)."""
        return replace(self, obs=replace(self.obs.subset(keep), thin=None),
                       d_rows=None if self.d_rows is None else self.d_rows[keep], timings=dict(self.timings))

    def without_thin(self, keep_grazing: bool = False) -> "Prepared":
        """The problem without the rows of the thin faces (:attr:`Observations.thin`), kept or
        not, as if no pixel had unmixed them; as it is where no other face has a kept row
        (they are then all there is to solve from). ``keep_grazing``: a thin face without a kept
        row (seen only beyond ``min_cos_view``) keeps its other rows, as a face seen only at
        grazing angles does."""
        thin = self.all_obs.thin
        if thin is None or not np.any(~thin[self.obs.face]):
            return self
        kept = self.row_subset(~thin[self.obs.face])
        dropped = thin & self.obs.observed_faces() if keep_grazing else thin
        return replace(kept, all_obs=replace(self.all_obs.subset(~dropped[self.all_obs.face]), thin=None))

    def clustered(self, cluster: np.ndarray, representative: np.ndarray) -> "Prepared":
        """The problem on clusters of faces, its rows held, as if each cluster were one face:
        cluster k has one observation per view, the area-weighted mean of its faces' there
        (:meth:`Observations.merged`), where ``cluster`` (F,) gives each face's cluster (-1:
        left out); its diffuse row is its faces' area-weighted mean row (the merged colour's
        shading), its other geometry (normal, shadow function, specular rows, the rays of a
        sun or of the light the object reflects) that of the face ``representative[k]`` (K,).
        Clusters are adjacent where two of their faces are (:attr:`edges`); where a cluster holds
        several faces, its colour may blend albedos (:attr:`blends_albedos`). The caster traces
        the whole mesh (:class:`~estimator.rays.raycast.ClusterCaster`): every face casts its
        shadow."""
        whole = self.data.mesh
        vertices, corners = np.unique(whole.faces[representative], return_inverse=True)
        mesh = TriangleMesh(whole.vertices[vertices], corners.reshape(-1, 3))
        count, areas = len(representative), whole.areas
        obs, all_obs = self.obs.merged(cluster, count, areas), self.all_obs.merged(cluster, count, areas)
        visibility = Visibility(self.visibility.bits[representative], self.visibility.num_directions)
        mirror = mirror_directions(mesh.face_normals[obs.face], obs.view_dir)
        pairs = cluster[whole.face_adjacency]
        sizes = np.bincount(cluster[cluster >= 0], minlength=count)
        pairs = np.sort(pairs[np.all(pairs >= 0, axis=1) & (pairs[:, 0] != pairs[:, 1])], axis=1)
        return replace(self, data=replace(self.data, mesh=mesh), caster=ClusterCaster(self.caster, cluster, mesh),
                       visibility=visibility, all_obs=all_obs, obs=obs, c_matrix=self._mean_rows(cluster, count, areas),
                       d_rows=self.model.specular_rows(obs.face, mirror, self.sampling, visibility),
                       adjacency=np.unique(pairs, axis=0), merged_faces=bool(sizes.max(initial=0) > 1),
                       timings=dict(self.timings))

    def _mean_rows(self, cluster: np.ndarray, count: int, weight: np.ndarray) -> np.ndarray:
        """(count, M) the ``weight``-weighted mean diffuse row of each cluster's faces, in
        chunks of :data:`ROW_CHUNK` faces."""
        faces = np.nonzero(cluster >= 0)[0]
        total = np.zeros((count, sh.num_coeffs(self.model.order)))
        for start in range(0, len(faces), ROW_CHUNK):
            part = faces[start:start + ROW_CHUNK]
            mixing = sparse.csr_matrix((weight[part], (cluster[part], np.arange(len(part)))), shape=(count, len(part)))
            total += mixing @ self.diffuse_rows(part)
        return total / np.maximum(np.bincount(cluster[faces], weight[faces], minlength=count), 1e-300)[:, None]

    @property
    def edges(self) -> np.ndarray:
        """(E, 2) pairs of adjacent faces: the mesh's, or a clustered problem's own."""
        return self.data.mesh.face_adjacency if self.adjacency is None else self.adjacency

    def projected(self, light: np.ndarray) -> "Prepared":
        """The same observations with the light fixed to ``light`` (M, 3): each row becomes
        its three per-channel projections (C_i . x, D_k . x), so a solve with the light
        fixed to the identity (3, 3) gives the albedos under ``light`` in O(N) memory."""
        return replace(self, c_matrix=self.shading(light), d_rows=self.gloss(light), timings=dict(self.timings))


def _model_matrices(data: MultiViewData, model: ReflectionModel, sampling: SphereSampling,
                    visibility: Visibility, obs: Observations) -> tuple[np.ndarray | None, np.ndarray | None]:
    if streams(data, model.config, obs):
        return None, None
    c_matrix = model.diffuse_matrix(data.mesh, sampling, visibility)
    mirror = mirror_directions(data.mesh.face_normals[obs.face], obs.view_dir)
    return c_matrix, model.specular_rows(obs.face, mirror, sampling, visibility)


def streams(data: MultiViewData, config: PrepareConfig, obs: Observations) -> bool:
    """Whether a problem's reflection rows are streamed: faces plus kept observations
    exceed ``config.dense_rows``."""
    return data.mesh.num_faces + len(obs.face) > config.dense_rows


def with_config(prep: Prepared, config: PrepareConfig) -> Prepared:
    """The same observations and shadow function under another model configuration
    (e.g. another Phong exponent): only the reflection matrices are recomputed."""
    for key in ("directions", "min_cos_view", "min_pixels", "pure_pixels", "min_coverage", "negative_tolerance",
                "subpixel_samples", "variant"):
        if getattr(config, key) != getattr(prep.config, key):
            raise InputError(f"with_config cannot change {key}; run prepare() again")
    t = time.perf_counter()
    model = reflection_model(config)
    c_matrix, d_rows = _model_matrices(prep.data, model, prep.sampling, prep.visibility, prep.obs)
    timings = {**prep.timings, "reflection": time.perf_counter() - t}
    return Prepared(prep.data, config, model, prep.caster, prep.sampling, prep.visibility, prep.all_obs, prep.obs,
                    c_matrix, d_rows, timings)


def prepare(data: MultiViewData, config: PrepareConfig, log=None, method: str | None = None,
            streaming: bool = True, caster: RayCaster | None = None, alternatives: str = "") -> Prepared:
    """Run the shared stages. ``log`` (optional callable) receives progress lines;
    ``caster``: ray queries of ``data.mesh`` already built (None: built here).

    ``streaming`` False (a method that needs the rows held) refuses, before the shadow
    function is computed, a problem larger than ``config.dense_rows``; ``method`` names it
    in the message, and ``alternatives`` the methods that stream.
    """
    say = log or (lambda message: None)
    timings = {}
    t = time.perf_counter()
    caster = caster or RayCaster(data.mesh, config.variant)
    all_obs = gather_observations(caster, data.views, config.min_pixels, config.min_coverage, config.pure_pixels,
                                  config.negative_tolerance, config.subpixel_samples, config.dense_rows)
    normals = data.mesh.face_normals
    cos_view = np.sum(normals[all_obs.face] * all_obs.view_dir, axis=1)
    # the first surface a camera ray hits faces the camera, so on a mesh wound outwards the
    # front-facing pairs outnumber the back-facing ones (an open mesh shows a few insides)
    behind = int(np.sum(cos_view < 0))
    if behind > len(cos_view) - behind:
        centres = np.array([v.camera.center for v in data.views])
        low, high = data.mesh.vertices.min(axis=0), data.mesh.vertices.max(axis=0)
        within = int(np.sum(np.all((centres > low) & (centres < high), axis=1)))
        # cameras inside a mesh in other units see its faces from behind too; a ground plane or an
        # open mesh may hold cameras in its bounds, so both causes are named
        scale = (f"; or, as {within} of the {len(centres)} cameras lie inside the mesh's bounding box, the mesh and "
                 "the cameras may be in different units or places: check the mesh's scale before reversing the "
                 "winding") if within else ""
        raise InputError(f"{behind} of the {len(cos_view)} observed (face, view) pairs see their face from behind its "
                         "normal: the mesh's faces are wound the other way (normals point inwards); reverse the "
                         f"winding, e.g. trimesh's mesh.invert(){scale}")
    obs = all_obs.subset(cos_view > config.min_cos_view)
    if len(obs.face) == 0:
        raise InputError(f"no observation passes min_cos_view={config.min_cos_view}")
    timings["observations"] = time.perf_counter() - t
    say(f"observations: {len(all_obs.face)} (face, view) pairs, {len(obs.face)} kept "
        f"(view within acos({config.min_cos_view}) of the normal)")
    if all_obs.unresolved is not None:
        say(f"{int(all_obs.unresolved.sum())} faces are smaller than the pixels that see them: observed through "
            "the pixels whose centre they hold (a footprint's mean over them and their neighbours)")
    if streams(data, config, obs):
        if not streaming:
            raise InputError(
                f"method {method!r} holds its reflection rows in memory, and this problem has "
                f"{data.mesh.num_faces} faces + {len(obs.face)} observations > dense_rows="
                f"{config.dense_rows} (at most {config.dense_rows * sh.num_coeffs(config.sh_order) * 8 / 2**30:.1f}"
                f" GiB of rows): use a method that streams them ({alternatives or 'see the registry'}), or "
                "raise dense_rows"
            )
        say(f"streamed rows: {data.mesh.num_faces} faces + {len(obs.face)} observations > dense_rows "
            f"{config.dense_rows}")

    t = time.perf_counter()
    sampling = sphere_sampling(config.directions)
    visibility = shadow_function(caster, sampling)
    timings["visibility"] = time.perf_counter() - t
    say(f"visibility: {data.mesh.num_faces} faces x {config.directions} directions")

    t = time.perf_counter()
    model = reflection_model(config)
    c_matrix, d_rows = _model_matrices(data, model, sampling, visibility, obs)
    timings["reflection"] = time.perf_counter() - t
    return Prepared(data, config, model, caster, sampling, visibility, all_obs, obs, c_matrix, d_rows, timings)
