"""Resolved illumination of a scene: what Mitsuba renders and its exact SH.

Two registries make a new kind one class in one place:

* :data:`LIGHT_KINDS`: the kinds of rendered light (``Illumination.kind``), each a
  :class:`LightKind` that says whether it is a delta light, its SH and its JSON record;
* :data:`SPEC_TYPES`: the ``[illumination] type`` values of a scene spec, each a builder
  from the validated spec to an :class:`Illumination` (``probe-clustered`` builds
  directional lights).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field, replace
from typing import Callable, ClassVar

import numpy as np

from estimator import latlong, sh
from harness.io.images import read_linear_rgb
from harness.scene.probe import cluster_probe


@dataclass(frozen=True)
class Illumination:
    """Light as rendered.

    Attributes
    ----------
    kind : a registered :class:`LightKind` ('directional', 'point', 'envmap', 'sunsky').
    to_light : (K, 3) unit directions towards directional lights.
    irradiance : (K, 3) their irradiance (on a surface facing the light).
    positions : (K, 3) point light positions.
    intensity : (K, 3) point light radiant intensity (W/sr).
    envmap : (H, W, 3) radiance map in Mitsuba's envmap orientation (scaled).
    sunsky : parameters of Mitsuba's Hosek-Wilkie ``sunsky`` (to_sun, turbidity,
        ground_albedo, sun_scale, sky_scale, scale), sun direction in world space (+Y up).
    spheres : spherical area lights on a uniform environment: ``positions`` (K, 3), ``radii``
        (K,), ``radiance`` (K, 3) of their surfaces, ``ambient`` (3,) the environment's radiance.
    rotation : (3, 3) rotation applied to the envmap or sun-sky (its Mitsuba ``to_world``).
    """

    kind: str
    to_light: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    irradiance: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    intensity: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    envmap: np.ndarray | None = None
    sunsky: dict | None = None
    spheres: dict | None = None
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    @property
    def is_delta(self) -> bool:
        return LIGHT_KINDS[self.kind].delta

    def rotated(self, rotation: np.ndarray) -> "Illumination":
        """The same light turned by ``rotation`` (3, 3) about the world origin."""
        r = np.asarray(rotation, dtype=np.float64)
        spheres = None if self.spheres is None else {
            **self.spheres, "positions": (np.asarray(self.spheres["positions"]) @ r.T).tolist()}
        return replace(self, to_light=self.to_light @ r.T, positions=self.positions @ r.T, spheres=spheres,
                       rotation=r @ self.rotation)

    def sh(self, order: int, center: np.ndarray | None = None) -> np.ndarray:
        """((L + 1)^2, 3) SH of the radiance arriving at ``center`` (unfiltered; None: the origin)."""
        return LIGHT_KINDS[self.kind].sh(self, order, np.zeros(3) if center is None else center)

    def mitsuba_emitters(self, mi) -> dict:
        """Emitter dicts for ``mi.load_dict`` (directions converted to travel direction)."""
        out = {}
        for k, (d, e) in enumerate(zip(self.to_light, self.irradiance)):
            out[f"light_{k:03d}"] = {"type": "directional", "direction": (-d).tolist(),
                                     "irradiance": {"type": "rgb", "value": e.tolist()}}
        for k, (p, i) in enumerate(zip(self.positions, self.intensity)):
            out[f"light_{k:03d}"] = {"type": "point", "position": p.tolist(),
                                     "intensity": {"type": "rgb", "value": i.tolist()}}
        if self.envmap is not None:
            to_world = np.eye(4)
            to_world[:3, :3] = self.rotation
            out["envmap"] = {"type": "envmap", "bitmap": mi.Bitmap(self.envmap.astype(np.float32)),
                             "to_world": mi.ScalarTransform4f(to_world)}
        if self.sunsky is not None:
            out["sunsky"] = sunsky_emitter(mi, self)
        if self.spheres is not None:
            out.update(sphere_emitters(mi, self.spheres))
        return out

    def to_json(self) -> dict:
        """JSON-able description (an envmap itself is stored as an EXR beside it)."""
        return {"kind": self.kind, **LIGHT_KINDS[self.kind].to_json(self)}

    @classmethod
    def from_json(cls, data: dict, envmap: np.ndarray | None = None) -> "Illumination":
        """The light of a :meth:`to_json` record (``envmap``: the map of an 'envmap' record)."""
        return LIGHT_KINDS[data["kind"]].from_json(data, envmap)


class LightKind(ABC):
    """One kind of rendered light, registered by :func:`light_kind` under its ``name``."""

    name: ClassVar[str] = ""
    delta: ClassVar[bool] = False   # lights from single directions (the direct integrator renders them)

    @abstractmethod
    def sh(self, light: Illumination, order: int, center: np.ndarray) -> np.ndarray:
        """((L + 1)^2, 3) SH of the radiance arriving at ``center`` (3,)."""

    @abstractmethod
    def to_json(self, light: Illumination) -> dict:
        """The record's fields beside ``kind``."""

    @abstractmethod
    def from_json(self, data: dict, envmap: np.ndarray | None) -> Illumination:
        """The light of a record."""


LIGHT_KINDS: dict[str, LightKind] = {}


def light_kind(cls: type[LightKind]) -> type[LightKind]:
    """Class decorator: register a :class:`LightKind` under ``cls.name``."""
    LIGHT_KINDS[cls.name] = cls()
    return cls


def _rows(data: dict, key: str) -> np.ndarray:
    return np.array([light[key] for light in data["lights"]], float).reshape(-1, 3)


@light_kind
class Directional(LightKind):
    """Directional lights: irradiance from single directions."""

    name, delta = "directional", True

    def sh(self, light, order, center):
        return sh.project_directional(order, light.to_light, light.irradiance)

    def to_json(self, light):
        return {"lights": [{"to_light": d.tolist(), "irradiance": e.tolist()}
                           for d, e in zip(light.to_light, light.irradiance)]}

    def from_json(self, data, envmap):
        return Illumination(self.name, to_light=_rows(data, "to_light"), irradiance=_rows(data, "irradiance"))


@light_kind
class Point(LightKind):
    """Point lights: radiant intensity from positions (seen from ``center`` with 1/d^2 falloff)."""

    name, delta = "point", True

    def sh(self, light, order, center):
        offset = light.positions - center
        dist2 = np.sum(offset ** 2, axis=1, keepdims=True)
        return sh.project_directional(order, offset / np.sqrt(dist2), light.intensity / dist2)

    def to_json(self, light):
        return {"lights": [{"position": p.tolist(), "intensity": i.tolist()}
                           for p, i in zip(light.positions, light.intensity)]}

    def from_json(self, data, envmap):
        return Illumination(self.name, positions=_rows(data, "position"), intensity=_rows(data, "intensity"))


@light_kind
class Envmap(LightKind):
    """A lat-long environment map, turned by ``rotation``."""

    name = "envmap"

    def sh(self, light, order, center):
        return sh.rotation_matrix(order, light.rotation) @ sh.project_latlong(order, light.envmap)

    def to_json(self, light):
        return {"envmap_file": "envmap.exr", "rotation": light.rotation.tolist()}

    def from_json(self, data, envmap):
        if envmap is None:
            raise ValueError("an envmap illumination needs its lat-long image")
        return Illumination(self.name, envmap=envmap, rotation=np.array(data.get("rotation", np.eye(3)), float))


@light_kind
class SunSky(LightKind):
    """Mitsuba's Hosek-Wilkie ``sunsky``, turned by ``rotation``."""

    name = "sunsky"

    def sh(self, light, order, center):
        return sunsky_sh(light, order)

    def to_json(self, light):
        return {"sunsky": light.sunsky, "rotation": light.rotation.tolist()}

    def from_json(self, data, envmap):
        return Illumination(self.name, sunsky=data["sunsky"], rotation=np.array(data.get("rotation", np.eye(3)), float))


@light_kind
class Spheres(LightKind):
    """Spherical area lights of uniform radiance on a uniform (dim) environment."""

    name = "spheres"

    def sh(self, light, order, center):
        return spheres_sh(light.spheres, order, center)

    def to_json(self, light):
        return {"spheres": light.spheres}

    def from_json(self, data, envmap):
        return Illumination(self.name, spheres=data["spheres"])


def spheres_sh(spheres: dict, order: int, center: np.ndarray) -> np.ndarray:
    """((L + 1)^2, 3) exact SH of the radiance arriving at ``center`` (3,): the ambient radiance
    A everywhere, and inside the cone of half-angle a that each sphere subtends its radiance L
    instead. A uniform cap about d has the zonal coefficients 2 pi (L - A) times the integral
    of P_l from cos a to 1, (P_{l-1} - P_{l+1})(cos a) / (2 l + 1) (1 - cos a for l = 0), times
    Y_lm(d); the ambient adds A sqrt(4 pi) to the DC."""
    from scipy.special import eval_legendre

    ambient = np.asarray(spheres["ambient"], float)
    out = np.zeros((sh.num_coeffs(order), 3))
    out[0] = ambient * np.sqrt(4 * np.pi)
    l = np.arange(order + 1)
    for position, radius, radiance in zip(spheres["positions"], spheres["radii"], spheres["radiance"]):
        offset = np.asarray(position, float) - center
        distance = np.linalg.norm(offset)
        x = np.sqrt(max(1.0 - (radius / distance) ** 2, 0.0))               # cos of the half-angle
        band = (eval_legendre(np.maximum(l - 1, 0), x) - eval_legendre(l + 1, x)) / (2 * l + 1)
        band[0] = 1.0 - x
        cap = sh.project_directional(order, (offset / distance)[None], (np.asarray(radiance, float) - ambient)[None])
        out += 2 * np.pi * sh.expand_per_degree(band)[:, None] * cap
    return out


def sphere_emitters(mi, spheres: dict) -> dict:
    """Mitsuba shapes with ``area`` emitters for the spheres, and a ``constant`` environment."""
    out = {"ambient": {"type": "constant", "radiance": {"type": "rgb", "value": list(spheres["ambient"])}}}
    for k, (p, r, e) in enumerate(zip(spheres["positions"], spheres["radii"], spheres["radiance"])):
        out[f"sphere_light_{k:03d}"] = {"type": "sphere", "center": list(p), "radius": float(r),
                                        "emitter": {"type": "area", "radiance": {"type": "rgb", "value": list(e)}}}
    return out


SpecBuilder = Callable[..., Illumination]
SPEC_TYPES: dict[str, SpecBuilder] = {}


def illumination_type(name: str, delta: bool = False) -> Callable[[SpecBuilder], SpecBuilder]:
    """Decorator: register a builder ``(spec, seed) -> Illumination`` for ``[illumination] type =
    name``; ``delta``: it builds delta lights (rendered by the direct integrator by default)."""
    def register(builder: SpecBuilder) -> SpecBuilder:
        builder.delta = delta
        SPEC_TYPES[name] = builder
        return builder
    return register


def build_illumination(spec, seed: int = 0) -> Illumination:
    """Resolve a validated illumination spec into lights (clustering probes as needed), its
    colour cast ``tint`` applied."""
    light = SPEC_TYPES[spec.type](spec, seed)
    tint = np.asarray(spec.tint, float)
    if np.all(tint == 1.0):
        return light
    spheres = None if light.spheres is None else {
        **light.spheres, "radiance": (np.asarray(light.spheres["radiance"]) * tint).tolist(),
        "ambient": (np.asarray(light.spheres["ambient"]) * tint).tolist()}
    return replace(light, irradiance=light.irradiance * tint, intensity=light.intensity * tint,
                   envmap=None if light.envmap is None else light.envmap * tint, spheres=spheres)


@illumination_type("directional", delta=True)
def _directional(spec, seed: int) -> Illumination:
    d = np.array([light.to_light for light in spec.lights], float)
    return Illumination("directional", to_light=d / np.linalg.norm(d, axis=1, keepdims=True),
                        irradiance=spec.scale * np.array([light.irradiance for light in spec.lights], float))


@illumination_type("point", delta=True)
def _point(spec, seed: int) -> Illumination:
    return Illumination("point", positions=np.array([light.position for light in spec.lights], float),
                        intensity=spec.scale * np.array([light.intensity for light in spec.lights], float))


@illumination_type("sunsky")
def _sunsky(spec, seed: int) -> Illumination:
    to_sun = np.asarray(spec.to_sun, float)
    return Illumination("sunsky", sunsky={
        "to_sun": (to_sun / np.linalg.norm(to_sun)).tolist(), "turbidity": spec.turbidity,
        "ground_albedo": spec.ground_albedo, "sun_scale": spec.sun_scale, "sky_scale": spec.sky_scale,
        "scale": spec.scale}, rotation=sh.axis_angle_matrix("y", spec.rotation))


@illumination_type("spheres")
def _spheres(spec, seed: int) -> Illumination:
    return Illumination("spheres", spheres={
        "positions": [list(map(float, light.position)) for light in spec.lights],
        "radii": [float(light.radius) for light in spec.lights],
        "radiance": [[spec.scale * v for v in light.radiance] for light in spec.lights],
        "ambient": [spec.scale * v for v in spec.ambient]})


@illumination_type("probe-clustered", delta=True)
def _probe_clustered(spec, seed: int) -> Illumination:
    probe = spec.scale * read_linear_rgb(spec.file).astype(np.float64)
    d, e = cluster_probe(probe, spec.count, white=spec.white, seed=seed)
    return Illumination("directional", to_light=d, irradiance=e)


@illumination_type("envmap")
def _envmap(spec, seed: int) -> Illumination:
    probe = spec.scale * read_linear_rgb(spec.file).astype(np.float64)
    latlong.directions(*probe.shape[:2])  # validates the map size
    return Illumination("envmap", envmap=probe, rotation=sh.axis_angle_matrix("y", spec.rotation))


# Mitsuba's sunsky frame is Z-up; this turns its local +Z to world +Y.
_SUNSKY_FRAME = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
SUN_APERTURE_DEG = 0.5358  # Mitsuba's default, passed explicitly


def sunsky_emitter(mi, light: Illumination, sun: bool = True, sky: bool = True) -> dict:
    """The ``sunsky`` emitter dict of a light (optionally sun or sky only), Y-up, rotated."""
    p = light.sunsky
    to_world = np.eye(4)
    to_world[:3, :3] = light.rotation @ _SUNSKY_FRAME
    return {"type": "sunsky", "sun_direction": (light.rotation @ np.asarray(p["to_sun"])).tolist(),
            "turbidity": float(p["turbidity"]), "albedo": float(p["ground_albedo"]),
            "sun_scale": float(p["sun_scale"] * p["scale"]) if sun else 0.0,
            "sky_scale": float(p["sky_scale"] * p["scale"]) if sky else 0.0,
            "sun_aperture": SUN_APERTURE_DEG, "complex_sun": False,
            "to_world": mi.ScalarTransform4f(to_world)}


def _emitter_radiance(mi, emitter, dirs: np.ndarray) -> np.ndarray:
    """(N, 3) radiance an environment emitter sends towards the origin from directions (N, 3)."""
    import drjit as dr

    si = dr.zeros(mi.SurfaceInteraction3f, len(dirs))
    si.wi = mi.Vector3f(*(-np.asarray(dirs, np.float32)).T)
    return np.array(emitter.eval(si), dtype=np.float64).T


def sunsky_sh(light: Illumination, order: int, sky_size=(256, 512)) -> np.ndarray:
    """SH of a sun-sky light: the sky by quadrature on a lat-long grid (sun off); the sun
    (a uniform disc: ``complex_sun`` off) as a delta light of irradiance
    L_sun x 2 pi (1 - cos(aperture / 2))."""
    from estimator import backend

    mi = backend.set_variant()
    sky = mi.load_dict(sunsky_emitter(mi, light, sun=False))
    h, w = sky_size
    radiance = _emitter_radiance(mi, sky, latlong.directions(h, w).reshape(-1, 3)).reshape(h, w, 3)
    to_sun = light.rotation @ np.asarray(light.sunsky["to_sun"], float)
    sun = mi.load_dict(sunsky_emitter(mi, light, sky=False))
    disc = 2 * np.pi * (1 - np.cos(np.radians(0.5 * SUN_APERTURE_DEG)))
    irradiance = _emitter_radiance(mi, sun, to_sun[None])[0] * disc
    return sh.project_latlong(order, radiance) + sh.project_directional(order, to_sun[None], irradiance[None])
