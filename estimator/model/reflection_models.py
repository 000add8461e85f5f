"""Reflection models: how a face's colour in one view depends on its albedos and the light.

Every model has the bilinear form of the paper's Eq. 17,

    R = t_d (C_i . x) + t_s (D_k . x),

with per-face albedos t_d, t_s and one light unknown x (SH coefficients, one
column per colour channel). A model says what x is (the pseudo illumination h
or the radiance L), how its diffuse rows C_i and specular rows D_k are built,
how x becomes the pseudo illumination that every result reports, and what
Mitsuba scene renders the same image. A new model is one class here, named
in :data:`MODELS` and selected by :func:`reflection_model`.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..core import sh
from ..core.data import TriangleMesh
from ..core.settings import Section
from ..rays.visibility import SphereSampling, Visibility
from .reflection import diffuse_matrix, lobe_matrix, mirror_matrix, mirror_shadow

LIGHTS = ("pseudo", "radiance")


DIFFUSE_LIGHTS = ("pseudo", "defiltered")
SPECULAR_MODELS = ("mirror", "lobe")


@dataclass
class ReflectionConfig(Section):
    """The reflection model and its light (read by :func:`reflection_model`).

    Attributes
    ----------
    sh_order : SH order N_L of the light ((N_L + 1)^2 coefficients).
    diffuse_light : 'pseudo' (the paper: the diffuse term from the pseudo illumination) or
        'defiltered' (the pseudo illumination divided by the Phong filter up to
        ``defilter_order``, for exponent ``phong_exponent``).
    defilter_order : highest SH degree that 'defiltered' divides by the Phong filter (at
        most ``sh_order`` there; the other lights do not read it).
    phong_exponent : exponent of the Phong lobe, for the models that depend on it.
    specular_model : 'mirror' (the paper's Eq. 10: the pseudo illumination at the mirror
        direction) or 'lobe' (the Phong lobe integrated over the sphere, cut by the face's
        horizon and shadows, times the radiance: exact for the Phong BRDF).
    """

    sh_order: int = 10
    diffuse_light: str = "pseudo"
    defilter_order: int = 2
    phong_exponent: float = 10.0
    specular_model: str = "mirror"

    def check(self):
        checks = [
            (0 <= self.sh_order <= 30, "sh_order must lie in [0, 30]"),
            (self.diffuse_light in DIFFUSE_LIGHTS, f"diffuse_light must be one of {DIFFUSE_LIGHTS}"),
            # read by the 'defiltered' light alone: another model takes any order
            (self.defilter_order >= 0 and (self.diffuse_light != "defiltered" or self.defilter_order <= self.sh_order),
             "defilter_order must lie in [0, sh_order]"),
            (self.phong_exponent > 0, "phong_exponent must be > 0"),
            (self.specular_model in SPECULAR_MODELS, f"specular_model must be one of {SPECULAR_MODELS}"),
        ]
        if all(ok for ok, _ in checks) and self.diffuse_light == "defiltered" and self.specular_model == "mirror":
            f = sh.phong_filter(self.defilter_order, self.phong_exponent)
            checks.append((not np.any(np.abs(f) < 1e-6),
                           f"the Phong filter of exponent {self.phong_exponent} vanishes below degree "
                           f"{self.defilter_order}; lower defilter_order"))
        return checks


class NoMitsubaEquivalent(ValueError):
    """The model has no single-environment Mitsuba scene that renders the same image."""


@dataclass(frozen=True)
class MitsubaMaterial:
    """The Mitsuba BSDF of a model: its kind ('diffuse_mirror' or 'phong', the
    plugins of ``harness.plugins``) and its float properties.

    Lit by the environment map of the model's light unknown (``light`` SH) and
    path traced with two bounces, it renders the model's prediction.
    """

    kind: str
    properties: dict


class ReflectionModel(ABC):
    """One reflection model, built from an :class:`ReflectionConfig`.

    Attributes
    ----------
    name : registry name.
    light : 'pseudo' (x = h, the pseudo illumination) or 'radiance' (x = L).
    uses_exponent : whether the rows depend on ``config.phong_exponent`` (only then can
        the exponent be estimated by residual).
    shadow_along_mirror : whether the reflection is shadowed by the visibility along the
        mirror direction alone (True), or the visibility is integrated over the lobe.
    """

    name: ClassVar[str] = ""
    light: ClassVar[str] = "pseudo"
    uses_exponent: ClassVar[bool] = False
    shadow_along_mirror: ClassVar[bool] = True

    def __init__(self, config: ReflectionConfig):
        self.config = config
        self.order = config.sh_order

    def diffuse_matrix(self, mesh: TriangleMesh, sampling: SphereSampling, visibility: Visibility,
                       faces: np.ndarray | None = None, coat_ior: float | None = None) -> np.ndarray:
        """(F, M) diffuse rows C_i multiplying the light unknown (the paper's Eq. 13); (n, M)
        for the faces (n,) only, when given; the light passing a smooth coat of index
        ``coat_ior`` on its way in, when given (:func:`estimator.model.reflection.diffuse_matrix`)."""
        return diffuse_matrix(mesh, sampling, visibility, self.order, faces, coat_ior)

    @abstractmethod
    def specular_rows(self, faces: np.ndarray, mirror: np.ndarray, sampling: SphereSampling,
                      visibility: Visibility) -> np.ndarray:
        """(N, M) specular rows D_k for faces (N,) seen along mirrored view directions (N, 3)."""

    def specular_shading(self, faces: np.ndarray, mirror: np.ndarray, sampling: SphereSampling,
                         visibility: Visibility, light: np.ndarray) -> np.ndarray:
        """(N, C) D_k . x of faces (N,) seen along mirrored view directions (N, 3) under the
        light unknown ``light`` (M, C): :meth:`specular_rows` @ ``light``."""
        return self.specular_rows(faces, mirror, sampling, visibility) @ light

    def unshadowed_specular_shading(self, mirror: np.ndarray, light: np.ndarray) -> np.ndarray:
        """(N, C) the reflection of the light unknown ``light`` (M, C) along mirrored view
        directions (N, 3) with nothing in the way: the pseudo illumination at the mirror
        directions, h(r). The paper's model shades it by the visibility along r; the lobe
        model integrates the visibility and the horizon over its lobe instead."""
        return sh.evaluate(self.order, mirror, self.pseudo_from_light(light))

    def pseudo_from_light(self, light: np.ndarray) -> np.ndarray:
        """The pseudo illumination h (M, C) from the light unknown (M, C)."""
        return light

    def unknown_from_radiance(self, radiance: np.ndarray) -> np.ndarray:
        """(M, C) the light unknown whose diffuse shading equals that of the radiance SH
        ``radiance`` (M, C): ``diffuse_matrix @ result == paper diffuse rows @ radiance``."""
        return radiance

    def known_light(self, pseudo: np.ndarray | None, radiance: np.ndarray | None) -> tuple[np.ndarray | None, str]:
        """The light unknown from a known pseudo illumination or radiance, and what it needs."""
        if self.light == "radiance":
            return radiance, "the radiance SH (known_radiance)"
        return pseudo, "the pseudo illumination SH (known_sh)"

    @staticmethod
    def predict(diffuse: np.ndarray, specular: np.ndarray, diffuse_shading: np.ndarray,
                specular_shading: np.ndarray) -> np.ndarray:
        """(N, 3) colours of N observations: t_d (C . x) + t_s (D . x), from the shadings
        C . x and D . x (N, 3) (a face's diffuse shading is the same in every view, so a
        caller takes it once per face) and the albedos t_d, t_s (N, 3)."""
        return diffuse * diffuse_shading + specular * specular_shading

    def mitsuba_material(self) -> MitsubaMaterial:
        """The BSDF that renders this model in Mitsuba, lit by the light unknown as environment."""
        raise NoMitsubaEquivalent(f"reflection model {self.name!r} has no single-environment Mitsuba equivalent")


class PaperModel(ReflectionModel):
    """The paper's model: R = t_d sum h C + t_s h(r) s(r); x = h (Eq. 10 and 13)."""

    name = "paper"

    def specular_rows(self, faces, mirror, sampling, visibility):
        return mirror_matrix(faces, mirror, sampling, visibility, self.order)

    def specular_shading(self, faces, mirror, sampling, visibility, light):
        # h(r) s(r), the light evaluated at the mirror directions without the (N, M) rows
        return sh.evaluate(self.order, mirror, light) * mirror_shadow(faces, mirror, sampling, visibility)[:, None]

    def mitsuba_material(self):
        return MitsubaMaterial("diffuse_mirror", {})


class DefilteredModel(PaperModel):
    """The paper's specular term; the diffuse term uses the radiance, h divided by the
    Phong filter up to ``defilter_order`` (x = h). Diffuse and specular see different
    lights, so no single environment renders it."""

    name = "defiltered"
    uses_exponent = True

    def diffuse_matrix(self, mesh, sampling, visibility, faces=None, coat_ior=None):
        return super().diffuse_matrix(mesh, sampling, visibility, faces, coat_ior) * self._gains()[None]

    def unknown_from_radiance(self, radiance):
        return radiance / self._gains()[: len(radiance), None]

    def _gains(self) -> np.ndarray:
        """((order + 1)^2,) the diffuse rows' per-coefficient gain: 1 / Phong filter up to
        ``defilter_order``, 1 above."""
        c = self.config
        gains = np.ones(self.order + 1)
        f = sh.phong_filter(self.order, c.phong_exponent)
        gains[: c.defilter_order + 1] = 1.0 / f[: c.defilter_order + 1]
        return sh.expand_per_degree(gains)

    def mitsuba_material(self):
        return ReflectionModel.mitsuba_material(self)


class LobeModel(ReflectionModel):
    """The Phong lobe integrated exactly, cut by the horizon and shadows; x = L, the
    radiance (h = L x Phong filter loses the degrees where the filter vanishes)."""

    name = "lobe"
    light = "radiance"
    uses_exponent = True
    shadow_along_mirror = False

    def specular_rows(self, faces, mirror, sampling, visibility):
        return lobe_matrix(faces, mirror, sampling, visibility, self.order, self.config.phong_exponent)

    def pseudo_from_light(self, light):
        return sh.phong_filtered(light, self.config.phong_exponent)

    def mitsuba_material(self):
        return MitsubaMaterial("phong", {"exponent": float(self.config.phong_exponent)})


MODELS: dict[str, type[ReflectionModel]] = {m.name: m for m in (PaperModel, DefilteredModel, LobeModel)}


def model_name(config: ReflectionConfig) -> str:
    """The model a configuration selects: ``specular_model`` x ``diffuse_light``."""
    if config.specular_model == "lobe":
        return "lobe"
    return "defiltered" if config.diffuse_light == "defiltered" else "paper"


def reflection_model(config: ReflectionConfig) -> ReflectionModel:
    """The :class:`ReflectionModel` of a configuration."""
    return MODELS[model_name(config)](config)
