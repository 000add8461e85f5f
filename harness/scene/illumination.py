"""Resolved illumination of a scene: what Mitsuba renders and its exact SH."""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from estimator import latlong, sh

from harness.io.images import read_linear_rgb
from harness.scene.probe import cluster_probe
from harness.scene.spec import IlluminationSpec


@dataclass(frozen=True)
class Illumination:
    """Light as rendered.

    Attributes
    ----------
    kind : 'directional', 'point' or 'envmap'.
    to_light : (K, 3) unit directions towards directional lights.
    irradiance : (K, 3) their irradiance (on a surface facing the light).
    positions : (K, 3) point light positions.
    intensity : (K, 3) point light radiant intensity (W/sr).
    envmap : (H, W, 3) radiance map in Mitsuba's envmap orientation (scaled).
    sunsky : parameters of Mitsuba's Hosek-Wilkie ``sunsky`` (to_sun, turbidity,
        ground_albedo, sun_scale, sky_scale, scale), sun direction in world space (+Y up).
    rotation : (3, 3) rotation applied to the envmap or sun-sky (its Mitsuba ``to_world``).
    """

    kind: str
    to_light: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    irradiance: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    intensity: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    envmap: np.ndarray | None = None
    sunsky: dict | None = None
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    @property
    def is_delta(self) -> bool:
        return self.kind in ("directional", "point")

    def rotated(self, rotation: np.ndarray) -> "Illumination":
        """The same light turned by ``rotation`` (3, 3) about the world origin."""
        r = np.asarray(rotation, dtype=np.float64)
        return replace(self, to_light=self.to_light @ r.T, positions=self.positions @ r.T,
                       rotation=r @ self.rotation)

    def sh(self, order: int, center: np.ndarray = np.zeros(3)) -> np.ndarray:
        """((L + 1)^2, 3) SH of the radiance arriving at ``center`` (unfiltered).

        Point lights are taken as seen from ``center`` (direction and 1/d^2 falloff there).
        """
        if self.kind == "directional":
            return sh.project_directional(order, self.to_light, self.irradiance)
        if self.kind == "point":
            offset = self.positions - center
            dist2 = np.sum(offset ** 2, axis=1, keepdims=True)
            return sh.project_directional(order, offset / np.sqrt(dist2), self.intensity / dist2)
        if self.kind == "sunsky":
            return sunsky_sh(self, order)
        coeffs = sh.project_latlong(order, self.envmap)
        return sh.rotation_matrix(order, self.rotation) @ coeffs

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
        return out

    def to_json(self) -> dict:
        """JSON-able description (the envmap itself is stored as an EXR beside it)."""
        out = {"kind": self.kind}
        if self.kind == "directional":
            out["lights"] = [{"to_light": d.tolist(), "irradiance": e.tolist()}
                             for d, e in zip(self.to_light, self.irradiance)]
        elif self.kind == "point":
            out["lights"] = [{"position": p.tolist(), "intensity": i.tolist()}
                             for p, i in zip(self.positions, self.intensity)]
        elif self.kind == "sunsky":
            out["sunsky"] = self.sunsky
            out["rotation"] = self.rotation.tolist()
        else:
            out["envmap_file"] = "envmap.exr"
            out["rotation"] = self.rotation.tolist()
        return out

    @classmethod
    def from_json(cls, data: dict, envmap: np.ndarray | None = None) -> "Illumination":
        kind = data["kind"]
        if kind == "directional":
            lights = data["lights"]
            return cls(kind, to_light=np.array([l["to_light"] for l in lights], float).reshape(-1, 3),
                       irradiance=np.array([l["irradiance"] for l in lights], float).reshape(-1, 3))
        if kind == "point":
            lights = data["lights"]
            return cls(kind, positions=np.array([l["position"] for l in lights], float).reshape(-1, 3),
                       intensity=np.array([l["intensity"] for l in lights], float).reshape(-1, 3))
        if kind == "sunsky":
            return cls(kind, sunsky=data["sunsky"], rotation=np.array(data.get("rotation", np.eye(3)), float))
        if envmap is None:
            raise ValueError("an envmap illumination needs its lat-long image")
        return cls(kind, envmap=envmap, rotation=np.array(data.get("rotation", np.eye(3)), float))


def build_illumination(spec: IlluminationSpec, seed: int = 0) -> Illumination:
    """Resolve an illumination spec into lights (clustering probes as needed)."""
    s = spec.scale
    if spec.type == "directional":
        d = np.array([l.to_light for l in spec.lights], float)
        return Illumination("directional", to_light=d / np.linalg.norm(d, axis=1, keepdims=True),
                            irradiance=s * np.array([l.irradiance for l in spec.lights], float))
    if spec.type == "point":
        return Illumination("point", positions=np.array([l.position for l in spec.lights], float),
                            intensity=s * np.array([l.intensity for l in spec.lights], float))
    if spec.type == "sunsky":
        to_sun = np.asarray(spec.to_sun, float)
        return Illumination("sunsky", sunsky={
            "to_sun": (to_sun / np.linalg.norm(to_sun)).tolist(), "turbidity": spec.turbidity,
            "ground_albedo": spec.ground_albedo, "sun_scale": spec.sun_scale, "sky_scale": spec.sky_scale,
            "scale": s}, rotation=sh.axis_angle_matrix("y", spec.rotation))
    probe = s * read_linear_rgb(spec.file).astype(np.float64)
    if spec.type == "probe-clustered":
        d, e = cluster_probe(probe, spec.count, white=spec.white, seed=seed)
        return Illumination("directional", to_light=d, irradiance=e)
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
