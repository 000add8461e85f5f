"""Scene specs: TOML files validated into typed dataclasses.

Every unknown key, missing asset and out-of-range value is refused with a
:class:`SpecError` that names the key (``section.key``) or the file.
"""
from __future__ import annotations

import copy
import dataclasses
import math
import os
import tomllib
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimator import InputError
from harness.io.lens import COEFFICIENTS, Lens, source_pixels
from harness.scene.geometry import GEOMETRY_KINDS
from harness.scene.illumination import SPEC_TYPES


class SpecError(InputError):
    """A scene spec that cannot be used; the message names the key or file."""


def _check_keys(where: str, raw: dict, cls) -> None:
    if not isinstance(raw, dict):
        raise SpecError(f"{where} must be a table, got {type(raw).__name__}")
    allowed = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(raw) - allowed)
    if unknown:
        raise SpecError(f"unknown key{'s' if len(unknown) > 1 else ''} "
                        f"{', '.join(f'{where}.{k}' for k in unknown)} (allowed: {', '.join(sorted(allowed))})")


def _num(where: str, value, lo=None, hi=None, integer=False, lo_open=False) -> float:
    ok_type = isinstance(value, int) if integer else isinstance(value, (int, float))
    if isinstance(value, bool) or not ok_type:
        raise SpecError(f"{where} must be {'an integer' if integer else 'a number'}, got {value!r}")
    if not math.isfinite(value):
        raise SpecError(f"{where} must be finite, got {value!r}")
    if lo is not None and (value <= lo if lo_open else value < lo):
        raise SpecError(f"{where} must be {'>' if lo_open else '>='} {lo}, got {value}")
    if hi is not None and value > hi:
        raise SpecError(f"{where} must be <= {hi}, got {value}")
    return value


def _vec(where: str, value, n=3, nonneg=False, nonzero=False) -> list[float]:
    if isinstance(value, (int, float)) and not isinstance(value, bool) and n == 3 and not nonzero:
        value = [float(value)] * 3
    if not isinstance(value, list) or len(value) != n or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise SpecError(f"{where} must be a list of {n} numbers, got {value!r}")
    if not all(math.isfinite(v) for v in value):
        raise SpecError(f"{where} must be finite, got {value!r}")
    if nonneg and min(value) < 0:
        raise SpecError(f"{where} must be non-negative, got {value}")
    if nonzero and not any(value):
        raise SpecError(f"{where} must not be the zero vector")
    return [float(v) for v in value]


def _choice(where: str, value, options) -> str:
    if not isinstance(value, str) or value not in options:
        raise SpecError(f"{where} must be one of {', '.join(map(repr, options))}, got {value!r}")
    return value


def _asset(where: str, value, base_dir: str) -> str:
    if not isinstance(value, str) or not value:
        raise SpecError(f"{where} must be a file path, got {value!r}")
    path = value if os.path.isabs(value) else os.path.normpath(os.path.join(base_dir, value))
    if not os.path.isfile(path):
        raise SpecError(f"{where}: file not found: {path}")
    return path


@dataclass
class GeometrySpec:
    type: str = "icosphere"
    subdivisions: int = 4
    radius: float = 1.0
    lobes: int = 4
    depth: float = 0.3
    bumps: float = 0.08
    frequency: int = 6
    file: str | None = None

    def validate(self, base_dir: str) -> None:
        _choice("geometry.type", self.type, tuple(GEOMETRY_KINDS))
        _num("geometry.bumps", self.bumps, 0, 0.5)
        _num("geometry.frequency", self.frequency, 3, 16, integer=True)
        _num("geometry.subdivisions", self.subdivisions, 0, 8, integer=True)  # 8: 1,310,720 faces
        _num("geometry.radius", self.radius, 0, lo_open=True)
        _num("geometry.lobes", self.lobes, 1, 16, integer=True)
        _num("geometry.depth", self.depth, 0, 0.9)
        if self.type == "mesh":
            self.file = _asset("geometry.file", self.file, base_dir)
        elif self.file is not None:
            raise SpecError(f"geometry.file is only for geometry.type = 'mesh', not {self.type!r}")


PATTERNS = ("noise", "stripes", "checks", "gradient")
MATERIAL_MODELS = ("phong", "diffuse", "plastic", "roughplastic")


@dataclass
class AlbedoSpec:
    """An albedo: a constant ``value``, an image ``texture`` (spherical or UV mapping), or a
    procedural ``pattern`` between two ``colors`` (:func:`harness.scene.textures.pattern_albedo`:
    ``frequency`` bands or cells over the sphere of directions, ``axis`` for stripes and
    gradients, ``noise`` seeded by the scene's seed)."""

    value: list[float] | None = None
    texture: str | None = None
    pattern: str | None = None
    colors: list[list[float]] = field(default_factory=lambda: [[0.05, 0.05, 0.05], [0.8, 0.8, 0.8]])
    frequency: float = 4.0
    axis: list[float] = field(default_factory=lambda: [0.0, 1.0, 0.0])
    scale: float = 1.0
    mapping: str = "spherical"

    def validate(self, where: str, base_dir: str) -> None:
        _choice(f"{where}.mapping", self.mapping, ("spherical", "uv"))
        if sum(x is not None for x in (self.value, self.texture, self.pattern)) != 1:
            raise SpecError(f"{where} needs exactly one of 'value' (RGB), 'texture' (image file) or 'pattern' "
                            f"({', '.join(PATTERNS)})")
        if self.value is not None:
            self.value = _vec(f"{where}.value", self.value, nonneg=True)
        elif self.texture is not None:
            self.texture = _asset(f"{where}.texture", self.texture, base_dir)
        else:
            _choice(f"{where}.pattern", self.pattern, PATTERNS)
        if not isinstance(self.colors, list) or len(self.colors) != 2:
            raise SpecError(f"{where}.colors must be a list of two RGB colours, got {self.colors!r}")
        self.colors = [_vec(f"{where}.colors[{i}]", c, nonneg=True) for i, c in enumerate(self.colors)]
        _num(f"{where}.frequency", self.frequency, 0, 64, lo_open=True)
        self.axis = _vec(f"{where}.axis", self.axis, nonzero=True)
        _num(f"{where}.scale", self.scale, 0)


@dataclass
class RegionSpec:
    """A part of the object, chosen by direction bands (:func:`harness.scene.textures.region_labels`).

    ``diffuse`` is its uniform albedo, or ``albedo`` a texture inside it; ``model`` (with
    ``alpha``, ``exponent``, ``int_ior``) gives it a material of its own (an object of mixed
    materials); None: the object's ``material.model``."""

    name: str = ""
    diffuse: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    specular: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    axis: list[float] = field(default_factory=lambda: [0.0, 1.0, 0.0])
    ranges: list[list[float]] = field(default_factory=list)
    albedo: AlbedoSpec | None = None
    model: str | None = None
    alpha: float | None = None
    exponent: float | None = None
    int_ior: float | None = None

    def validate(self, where: str, base_dir: str = ".") -> None:
        if not isinstance(self.name, str) or not self.name:
            raise SpecError(f"{where}.name must be a non-empty string")
        if self.albedo is not None:
            if self.albedo.mapping != "spherical":
                raise SpecError(f"{where}.albedo must use the spherical mapping")
            self.albedo.validate(f"{where}.albedo", base_dir)
        if self.model is not None:
            _choice(f"{where}.model", self.model, MATERIAL_MODELS)
        if self.alpha is not None:
            _num(f"{where}.alpha", self.alpha, 0.01, 1.0)
        if self.exponent is not None:
            _num(f"{where}.exponent", self.exponent, 0, 10000, lo_open=True)
        if self.int_ior is not None:
            _num(f"{where}.int_ior", self.int_ior, 1.0, 4.0, lo_open=True)
        self.diffuse = _vec(f"{where}.diffuse", self.diffuse, nonneg=True)
        self.specular = _vec(f"{where}.specular", self.specular, nonneg=True)
        self.axis = _vec(f"{where}.axis", self.axis, nonzero=True)
        if not isinstance(self.ranges, list):
            raise SpecError(f"{where}.ranges must be a list of [lo, hi] pairs")
        self.ranges = [_vec(f"{where}.ranges[{i}]", r, n=2) for i, r in enumerate(self.ranges)]
        for i, (lo, hi) in enumerate(self.ranges):
            if not -1.0 <= lo <= hi <= 1.0:
                raise SpecError(f"{where}.ranges[{i}] must satisfy -1 <= lo <= hi <= 1, got {[lo, hi]}")


@dataclass
class MaterialSpec:
    model: str = "phong"
    exponent: float = 10.0
    int_ior: float = 1.49
    alpha: float = 0.1
    distribution: str = "beckmann"
    diffuse: AlbedoSpec | None = None
    specular: AlbedoSpec | None = None
    regions: list[RegionSpec] = field(default_factory=list)

    def validate(self, base_dir: str) -> None:
        _choice("material.model", self.model, MATERIAL_MODELS)
        _num("material.exponent", self.exponent, 0, 10000, lo_open=True)
        _num("material.int_ior", self.int_ior, 1.0, 4.0, lo_open=True)
        _num("material.alpha", self.alpha, 0.01, 1.0)
        _choice("material.distribution", self.distribution, ("beckmann", "ggx"))
        if self.regions:
            if self.diffuse is not None or self.specular is not None:
                raise SpecError("material.regions cannot be combined with material.diffuse/specular")
            for i, region in enumerate(self.regions):
                region.validate(f"material.regions[{i}]", base_dir)
                # the first region is the base (every face no later region takes); each later one
                # takes the faces in its bands: without bands it would take every face
                if i == 0 and region.ranges:
                    raise SpecError("material.regions[0] is the base region, which covers every face no later "
                                    "region takes: give it no ranges")
                if i > 0 and not region.ranges:
                    raise SpecError(f"material.regions[{i}].ranges is empty: only the first region, the base, "
                                    "covers every face; give this one [lo, hi] bands along its axis")
        else:
            self.diffuse = self.diffuse or AlbedoSpec(value=[0.0, 0.0, 0.0])
            self.specular = self.specular or AlbedoSpec(value=[0.0, 0.0, 0.0])
            self.diffuse.validate("material.diffuse", base_dir)
            self.specular.validate("material.specular", base_dir)

    @property
    def mixed(self) -> bool:
        """True when some region has a material of its own: the object mixes materials."""
        return any(r.model is not None or r.alpha is not None or r.exponent is not None or r.int_ior is not None
                   for r in self.regions)

    def region_material(self, region: "RegionSpec") -> "MaterialSpec":
        """The material of one region: the object's, with the region's own settings."""
        own = {k: getattr(region, k) for k in ("model", "alpha", "exponent", "int_ior")
               if getattr(region, k) is not None}
        return dataclasses.replace(self, regions=[], diffuse=None, specular=None, **own)

    def uses_uv(self) -> bool:
        return any(a is not None and a.texture is not None and a.mapping == "uv"
                   for a in (self.diffuse, self.specular))


@dataclass
class LightSpec:
    """A directional light (``to_light``, ``irradiance``), a point light (``position``,
    ``intensity``) or a spherical area light (``position``, ``radius``, ``radiance``)."""

    to_light: list[float] | None = None
    irradiance: Any = 1.0
    position: list[float] | None = None
    intensity: Any = 1.0
    radius: float | None = None
    radiance: Any = 1.0


LIGHT_LISTS = ("directional", "point", "spheres")   # illumination types that list their lights


def _check_light(where: str, kind: str, light: LightSpec) -> None:
    """One entry of ``illumination.lights`` for a light of type ``kind``, validated in place."""
    if kind == "spheres":
        if light.position is None or light.radius is None or light.to_light is not None:
            raise SpecError(f"{where}: a spherical light needs 'position' and 'radius' (and no 'to_light')")
        light.position = _vec(f"{where}.position", light.position)
        _num(f"{where}.radius", light.radius, 0, lo_open=True)
        if np.linalg.norm(light.position) <= light.radius:
            raise SpecError(f"{where}: the sphere must not contain the origin (the object's centre)")
        light.radiance = _vec(f"{where}.radiance", light.radiance, nonneg=True)
    elif kind == "directional":
        if light.position is not None or light.to_light is None:
            raise SpecError(f"{where}: a directional light needs 'to_light' (and no 'position')")
        light.to_light = _vec(f"{where}.to_light", light.to_light, nonzero=True)
        light.irradiance = _vec(f"{where}.irradiance", light.irradiance, nonneg=True)
    else:
        if light.to_light is not None or light.position is None:
            raise SpecError(f"{where}: a point light needs 'position' (and no 'to_light')")
        light.position = _vec(f"{where}.position", light.position)
        light.intensity = _vec(f"{where}.intensity", light.intensity, nonneg=True)


@dataclass
class IlluminationSpec:
    type: str = "directional"
    lights: list[LightSpec] = field(default_factory=list)
    file: str | None = None
    count: int = 40
    white: bool = True
    scale: float = 1.0
    to_sun: list[float] = field(default_factory=lambda: [0.5, 0.6, 0.3])
    turbidity: float = 3.0
    ground_albedo: float = 0.3
    sun_scale: float = 1.0
    sky_scale: float = 1.0
    rotation: float = 0.0
    ambient: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    tint: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0])

    def validate(self, base_dir: str) -> None:
        _choice("illumination.type", self.type, tuple(SPEC_TYPES))
        _num("illumination.scale", self.scale, 0, lo_open=True)
        self.tint = _vec("illumination.tint", self.tint, nonneg=True, nonzero=True)
        if self.type == "sunsky" and self.tint != [1.0, 1.0, 1.0]:
            raise SpecError("illumination.tint does not apply to 'sunsky' (its colour is the sky model's)")
        self.ambient = _vec("illumination.ambient", self.ambient, nonneg=True)
        if any(self.ambient) and self.type != "spheres":
            raise SpecError(f"illumination.ambient is the environment of 'spheres', not of {self.type!r}")
        if self.type in LIGHT_LISTS:
            if not self.lights:
                raise SpecError(f"illumination.lights must list at least one {self.type} light")
            for i, light in enumerate(self.lights):
                _check_light(f"illumination.lights[{i}]", self.type, light)
        elif self.lights:
            raise SpecError(f"illumination.lights is not used by illumination.type = {self.type!r}")
        if self.type in ("probe-clustered", "envmap"):
            self.file = _asset("illumination.file", self.file, base_dir)
        elif self.file is not None:
            raise SpecError(f"illumination.file is not used by illumination.type = {self.type!r}")
        _num("illumination.count", self.count, 1, 1000, integer=True)
        if not isinstance(self.white, bool):
            raise SpecError(f"illumination.white must be true or false, got {self.white!r}")
        self.to_sun = _vec("illumination.to_sun", self.to_sun, nonzero=True)
        if self.type == "sunsky" and self.to_sun[1] <= 0:
            raise SpecError(f"illumination.to_sun must point above the horizon (+Y up), got {self.to_sun}")
        _num("illumination.turbidity", self.turbidity, 1, 10)
        _num("illumination.ground_albedo", self.ground_albedo, 0, 1)
        _num("illumination.sun_scale", self.sun_scale, 0)
        _num("illumination.sky_scale", self.sky_scale, 0)
        _num("illumination.rotation", self.rotation, -360, 360)
        if self.rotation and self.type not in ("envmap", "sunsky"):
            raise SpecError(f"illumination.rotation turns an envmap or sunsky, not {self.type!r} lights")

    @property
    def is_delta(self) -> bool:
        return SPEC_TYPES[self.type].delta


@dataclass
class CameraSpec:
    count: int = 24
    test_count: int = 4
    distribution: str = "fibonacci"
    distance: float = 4.0
    fov: float = 35.0
    width: int = 256
    height: int = 256
    elevation: float = 20.0
    min_elevation: float = 8.0
    max_elevation: float = 65.0
    lens_model: str = "PINHOLE"
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    def lens(self) -> Lens | None:
        """The distorting lens every view is rendered through, or None for a pinhole."""
        if self.lens_model == "PINHOLE":
            return None
        return Lens(self.lens_model, **{key: float(getattr(self, key)) for key in COEFFICIENTS})

    def validate(self) -> None:
        _num("cameras.count", self.count, 1, 10000, integer=True)
        _num("cameras.test_count", self.test_count, 0, 10000, integer=True)
        _choice("cameras.distribution", self.distribution, ("fibonacci", "ring", "table-top"))
        _num("cameras.min_elevation", self.min_elevation, -89, 89)
        _num("cameras.max_elevation", self.max_elevation, self.min_elevation, 89)
        _num("cameras.distance", self.distance, 0, lo_open=True)
        _num("cameras.fov", self.fov, 1, 170)
        _num("cameras.width", self.width, 8, 8192, integer=True)
        _num("cameras.height", self.height, 8, 8192, integer=True)
        _num("cameras.elevation", self.elevation, -89, 89)
        _choice("cameras.lens_model", self.lens_model, ("PINHOLE", "OPENCV", "OPENCV_FISHEYE"))
        for key in COEFFICIENTS:
            _num(f"cameras.{key}", getattr(self, key), -1, 1)
            if self.lens_model == "PINHOLE" and getattr(self, key):
                raise SpecError(f"cameras.{key} distorts the lens: set cameras.lens_model = 'OPENCV' (or "
                                "'OPENCV_FISHEYE') with it")
        if self.lens_model != "PINHOLE":
            fx = 0.5 * self.width / np.tan(np.radians(0.5 * self.fov))
            try:
                source_pixels(self.lens(), self.width, self.height, fx, fx, 0.5 * self.width, 0.5 * self.height)
            except InputError as exc:
                raise SpecError(f"cameras.lens_model, k1..p2: {exc}") from None


@dataclass
class RenderSpec:
    spp: int = 4
    integrator: str = "auto"
    max_depth: int = 6
    half: bool = False

    def validate(self, illumination: IlluminationSpec) -> None:
        _num("render.spp", self.spp, 1, 65536, integer=True)
        _choice("render.integrator", self.integrator, ("auto", "direct", "path"))
        _num("render.max_depth", self.max_depth, 2, 64, integer=True)
        if not isinstance(self.half, bool):
            raise SpecError(f"render.half must be true or false, got {self.half!r}")
        if self.integrator == "direct" and not illumination.is_delta:
            raise SpecError(f"render.integrator = 'direct' needs delta lights; "
                            f"illumination.type = {illumination.type!r} needs 'path'")

    def resolved_integrator(self, illumination: IlluminationSpec) -> str:
        if self.integrator != "auto":
            return self.integrator
        return "direct" if illumination.is_delta else "path"


@dataclass
class FaultSpec:
    """Faults of real captures, applied to the training views after rendering (the test
    views stay clean and truly posed, so novel-view scores measure the estimate). Seeded
    (``seed``, added to the scene's) and recorded in ``transforms.json`` under ``faults``;
    the estimator never reads that record. All zero: no fault.

    Attributes
    ----------
    noise_read : Gaussian read-noise sigma, as a fraction of the view's 99th-percentile
        object value (its exposure level).
    noise_shot : shot noise; variance ``noise_shot x level x value`` (photon noise of an
        exposure whose level collects 1 / noise_shot photons).
    clip : exposure clipping: values above ``clip`` x level are cut (0: none).
    ldr : frames point at 8-bit sRGB PNGs of the (clipped) image scaled so that the
        clip level (or the level) is 255; the linear EXR stays beside it.
    pose_rotation : degrees; each training pose turns by a random angle of this standard
        deviation about a random axis through its centre.
    pose_translation : each training centre moves by a random vector of this standard
        deviation per axis, as a fraction of its distance to the object centre.
    focal_error : relative error of the written focal length (every view: intrinsics are shared).
    vertex_noise : vertices move along their normals by this standard deviation, as a
        fraction of the mean edge length (the written mesh; faces keep their identity).
    decimate : the written mesh keeps about this fraction of the faces (vertex clustering;
        0: off). Faces then change identity: the ground truth is carried to each written
        face from the rendered face nearest to its centroid.
    glare_views, glare_size, glare_value : that many training views get a square patch of
        ``glare_size`` pixels where ``glare_value`` (absolute, linear) is added, centred on
        a random object pixel.
    occluder_views, occluder_size, occluder_value : likewise, patches replaced by the value.
    exposure_jitter : auto-exposure: each training view is multiplied by exp(N(0, sigma))
        (every channel alike), before noise and clipping.
    white_balance_jitter : auto white balance: each channel of each training view is
        multiplied by exp(N(0, sigma)) on top of the exposure.
    seed : added to the scene's seed for the fault draws.
    """

    noise_read: float = 0.0
    noise_shot: float = 0.0
    clip: float = 0.0
    ldr: bool = False
    pose_rotation: float = 0.0
    pose_translation: float = 0.0
    focal_error: float = 0.0
    vertex_noise: float = 0.0
    decimate: float = 0.0
    glare_views: int = 0
    glare_size: int = 32
    glare_value: float = 0.5
    occluder_views: int = 0
    occluder_size: int = 32
    occluder_value: float = 0.0
    exposure_jitter: float = 0.0
    white_balance_jitter: float = 0.0
    seed: int = 0

    def validate(self) -> None:
        _num("faults.exposure_jitter", self.exposure_jitter, 0, 2)
        _num("faults.white_balance_jitter", self.white_balance_jitter, 0, 1)
        for key, top in (("noise_read", 10.0), ("noise_shot", 10.0), ("clip", 1e6), ("pose_translation", 1.0),
                         ("vertex_noise", 1.0)):
            _num(f"faults.{key}", getattr(self, key), 0, top)
        _num("faults.pose_rotation", self.pose_rotation, 0, 45)
        _num("faults.focal_error", self.focal_error, -0.5, 0.5)
        _num("faults.decimate", self.decimate, 0, 0.99)
        for key in ("glare_views", "occluder_views", "seed"):
            _num(f"faults.{key}", getattr(self, key), 0, 2 ** 31 - 1, integer=True)
        for key in ("glare_size", "occluder_size"):
            _num(f"faults.{key}", getattr(self, key), 1, integer=True)
        for key in ("glare_value", "occluder_value"):
            _num(f"faults.{key}", getattr(self, key), -1e6, 1e6)
        if not isinstance(self.ldr, bool):
            raise SpecError(f"faults.ldr must be true or false, got {self.ldr!r}")

    @property
    def active(self) -> bool:
        """Whether any fault is set."""
        return self.summary() != ""

    def summary(self) -> str:
        """The faults that are on, as 'key value' pairs ('' when none is)."""
        on = {"noise_read", "noise_shot", "clip", "ldr", "pose_rotation", "pose_translation", "focal_error",
              "vertex_noise", "decimate", "exposure_jitter", "white_balance_jitter"}
        parts = [f"{k} {getattr(self, k)}" for k in sorted(on) if getattr(self, k)]
        for kind in ("glare", "occluder"):
            if getattr(self, f"{kind}_views"):
                parts.append(
                    f"{getattr(self, f'{kind}_views')} {kind} patch(es) of {getattr(self, f'{kind}_size')} px, "
                    f"value {getattr(self, f'{kind}_value')}"
                )
        return ", ".join(parts)


@dataclass
class SceneSpec:
    name: str
    description: str = ""
    seed: int = 0
    geometry: GeometrySpec = field(default_factory=GeometrySpec)
    material: MaterialSpec = field(default_factory=MaterialSpec)
    illumination: IlluminationSpec = field(default_factory=IlluminationSpec)
    cameras: CameraSpec = field(default_factory=CameraSpec)
    render: RenderSpec = field(default_factory=RenderSpec)
    faults: FaultSpec = field(default_factory=FaultSpec)
    estimator: dict = field(default_factory=dict)
    profiles: dict = field(default_factory=dict)
    path: str | None = None

    def inputs(self) -> list[str]:
        """The files this spec reads: the spec itself and its assets (mesh, textures, probe)."""
        found = [self.path] if self.path else []

        def walk(value):
            if isinstance(value, dict):
                for v in value.values():
                    walk(v)
            elif isinstance(value, list):
                for v in value:
                    walk(v)
            elif isinstance(value, str) and os.path.isabs(value) and os.path.isfile(value):
                found.append(value)

        walk(dataclasses.asdict(self))
        return sorted(set(found))


def _check_finite(where: str, value) -> None:
    """Every float anywhere in a raw spec must be finite (TOML allows nan and inf)."""
    if isinstance(value, float) and not math.isfinite(value):
        raise SpecError(f"{where} must be finite, got {value!r}")
    if isinstance(value, dict):
        for key, item in value.items():
            _check_finite(f"{where}.{key}" if where else str(key), item)
    elif isinstance(value, list):
        for index, item in enumerate(value):
            _check_finite(f"{where}[{index}]", item)


def _text(where: str, value) -> str:
    if not isinstance(value, str):
        raise SpecError(f"{where} must be a string, got {value!r}")
    return value


def _table(where: str, value) -> dict:
    if not isinstance(value, dict):
        raise SpecError(f"{where} must be a table, got {value!r}")
    return dict(value)


def _list(where: str, value) -> list:
    if not isinstance(value, list):
        raise SpecError(f"{where} must be a list of tables, got {value!r}")
    return value


def _build(where: str, raw: dict, cls):
    _check_keys(where, raw, cls)
    return cls(**raw)


def _region(where: str, raw: dict) -> RegionSpec:
    raw = _table(where, raw)
    if "albedo" in raw:
        raw["albedo"] = _build(f"{where}.albedo", _table(f"{where}.albedo", raw["albedo"]), AlbedoSpec)
    return _build(where, raw, RegionSpec)


def _estimator_defaults(raw: dict) -> dict:
    """The spec's [estimator] table: estimator settings recommended for this scene."""
    from estimator import REGISTRY, EstimatorConfig

    if not isinstance(raw, dict):
        raise SpecError("estimator must be a table")
    allowed = {f.name for f in dataclasses.fields(EstimatorConfig)} | {"method"}
    unknown = sorted(set(raw) - allowed)
    if unknown:
        raise SpecError(f"unknown key(s) {', '.join('estimator.' + k for k in unknown)}")
    if "method" in raw and (not isinstance(raw["method"], str) or raw["method"] not in REGISTRY):
        raise SpecError(f"estimator.method {raw['method']!r} is not a registered method ({', '.join(REGISTRY)})")
    try:
        EstimatorConfig(**{k: v for k, v in raw.items() if k != "method"})
    except (TypeError, ValueError) as exc:
        raise SpecError(f"estimator: {exc}") from exc
    return dict(raw)


def _flatten(overrides: dict, prefix: str = "") -> dict:
    """Nested override tables as dotted keys ({'cameras': {'count': 5}} -> {'cameras.count': 5}):
    an override sets keys, it never replaces a whole table."""
    out = {}
    for key, value in overrides.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict) and value:
            out.update(_flatten(value, dotted + "."))
        else:
            out[dotted] = value
    return out


def apply_overrides(raw: dict, overrides: dict[str, Any]) -> dict:
    """Copy of ``raw`` with dotted keys set, e.g. {'cameras.width': 64}."""
    out = copy.deepcopy(raw)
    for dotted, value in _flatten(overrides).items():
        node = out
        *parents, leaf = dotted.split(".")
        for key in parents:
            node = node.setdefault(key, {})
            if not isinstance(node, dict):
                raise SpecError(f"override {dotted}: {key} is not a table")
        node[leaf] = value
    return out


def parse_spec(raw: dict, base_dir: str, profile: str | None = None,
               overrides: dict[str, Any] | None = None) -> SceneSpec:
    """Validate a raw spec (a dict as read from TOML) into a :class:`SceneSpec`.

    Parameters
    ----------
    base_dir : folder that relative asset paths are resolved against.
    profile : name of a table under ``[profiles]`` whose dotted keys override the spec.
    overrides : further dotted-key overrides, applied last.
    """
    _check_keys("spec", raw, SceneSpec)
    _check_finite("", raw)
    _check_finite("", overrides or {})
    if "name" not in raw:
        raise SpecError("spec.name is missing (a non-empty string)")
    if not isinstance(raw["name"], str) or not raw["name"]:
        raise SpecError(f"spec.name must be a non-empty string, got {raw['name']!r}")
    profiles = raw.get("profiles", {})
    if profile is not None:
        if profile not in profiles:
            raise SpecError(f"profile {profile!r} not found; the spec has {sorted(profiles) or 'none'}")
        raw = apply_overrides(raw, profiles[profile])
    if overrides:
        raw = apply_overrides(raw, overrides)
    _check_keys("spec", raw, SceneSpec)   # again: a profile or --set may name a key the spec lacks
    if not isinstance(raw.get("name"), str) or not raw["name"]:
        raise SpecError(f"spec.name must be a non-empty string, got {raw.get('name')!r}")
    mat = _table("material", raw.get("material", {}))
    _check_keys("material", mat, MaterialSpec)
    for key in ("diffuse", "specular"):
        if key in mat:
            mat[key] = _build(f"material.{key}", mat[key], AlbedoSpec)
    mat["regions"] = [_region(f"material.regions[{i}]", r)
                      for i, r in enumerate(_list("material.regions", mat.get("regions", [])))]
    ill = _table("illumination", raw.get("illumination", {}))
    _check_keys("illumination", ill, IlluminationSpec)
    ill["lights"] = [_build(f"illumination.lights[{i}]", r, LightSpec)
                     for i, r in enumerate(_list("illumination.lights", ill.get("lights", [])))]
    spec = SceneSpec(
        name=raw["name"],
        description=_text("spec.description", raw.get("description", "")),
        seed=_num("spec.seed", raw.get("seed", 0), 0, 2 ** 31 - 1, integer=True),
        geometry=_build("geometry", raw.get("geometry", {}), GeometrySpec),
        material=MaterialSpec(**mat),
        illumination=IlluminationSpec(**ill),
        cameras=_build("cameras", raw.get("cameras", {}), CameraSpec),
        render=_build("render", raw.get("render", {}), RenderSpec),
        faults=_build("faults", raw.get("faults", {}), FaultSpec),
        estimator=_estimator_defaults(raw.get("estimator", {})),
        profiles=profiles,
    )
    spec.geometry.validate(base_dir)
    spec.material.validate(base_dir)
    if spec.material.uses_uv() and spec.geometry.type != "mesh":
        raise SpecError("material texture mapping = 'uv' needs geometry.type = 'mesh' with texture coordinates")
    spec.illumination.validate(base_dir)
    spec.cameras.validate()
    spec.render.validate(spec.illumination)
    spec.faults.validate()
    return spec


def read_toml(path: str, what: str) -> dict:
    """A TOML file as a dict; a missing, unreadable or invalid file is a :class:`SpecError`
    naming ``what`` it should be (a scene spec, a suite)."""
    if not os.path.isfile(path):
        raise SpecError(f"{what} not found: {path}")
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{path} is not valid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise SpecError(f"{path} is not a text file (a {what} is TOML)") from None
    except OSError as exc:
        raise SpecError(f"cannot read {what} {path}: {exc.strerror or exc}") from None


def load_spec(path: str | os.PathLike, profile: str | None = None,
              overrides: dict[str, Any] | None = None) -> SceneSpec:
    """Read and validate a scene spec TOML file."""
    path = str(path)
    raw = read_toml(path, "scene spec")
    spec = parse_spec(raw, os.path.dirname(os.path.abspath(path)), profile, overrides)
    spec.path = os.path.abspath(path)
    return spec


SCENES_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "scenes")


def shipped_scenes() -> dict[str, str]:
    """Name -> path of the scene specs shipped in ``scenes/``."""
    out = {}
    for entry in sorted(os.listdir(SCENES_DIR)):
        if entry.endswith(".toml"):
            out[entry[:-5]] = os.path.join(SCENES_DIR, entry)
    return out


def resolve_scene(name_or_path: str) -> str:
    """A shipped scene name or a TOML path -> path."""
    if os.path.isfile(name_or_path):
        return name_or_path
    scenes = shipped_scenes()
    if name_or_path in scenes:
        return scenes[name_or_path]
    raise SpecError(f"no scene spec file or shipped scene named {name_or_path!r} "
                    f"(shipped: {', '.join(scenes)})")
