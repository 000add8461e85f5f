"""The seeded random scene family: one scene spec drawn per seed, to judge the estimator on
scenes nobody tuned it on (``pseudolight generate random --seed N``).

Each seed draws independently (:func:`draw`):

* light: a shipped HDR probe at a random rotation; Mitsuba's ``sunsky`` with a random sun
  elevation (10-70 degrees), azimuth and turbidity (2-8); or 1-4 distant spherical area lights
  (40-100 object radii away, half-angle 2-9 degrees) of random colour temperature (2500-9000 K)
  and power on a dim uniform environment; the
  probe and the spheres get a random colour cast (``tint``);
* material: Mitsuba's ``diffuse``, ``plastic``, ``roughplastic`` (alpha 0.05-0.5), the
  project's Phong (exponent 5-100, white specular 0.1-0.3), or mixed: each region its own;
* albedo: 3-10 uniform regions whose palette always holds a very dark colour (0.02-0.1) and a
  saturated one; a texture (the Earth, or a noise, stripes, checks or gradient pattern); or
  both (textured regions beside uniform ones);
* geometry: the bumpy blob (its bumps seeded), the Stanford bunny or the Utah teapot;
* cameras: 12-40 views over the whole sphere, or table-top (elevations 8-65 degrees: the
  underside is never seen).

Everything is rendered by Mitsuba's own plugins and its ``path`` integrator (the Phong
material by the project's plugin), with per-face ground truth as for every spec.
"""
from __future__ import annotations

import numpy as np

from harness.scene.spec import SceneSpec, parse_spec

PROBES = ("apartment.exr", "city.exr", "dawn.exr", "grace.hdr", "hall.exr", "lab.exr", "lobby.exr", "park.exr",
          "studio.exr", "sunrise.exr", "uffizi.hdr", "venice.exr")
LIGHTS = ("probe", "sunsky", "spheres")
MATERIALS = ("diffuse", "plastic", "roughplastic", "phong", "mixed")
ALBEDOS = ("regions", "texture", "both")
GEOMETRIES = ("blob", "bunny", "teapot")
CAMERAS = ("sphere", "table-top")
PATTERNS = ("earth", "noise", "stripes", "checks", "gradient")

# the sizes of the full family and of its tiny profile (the test suite's)
PROFILES = {"tiny": {"cameras.width": 128, "cameras.height": 128, "render.spp": 16, "cameras.test_count": 1,
                     "geometry.subdivisions": 3}}


def blackbody_rgb(kelvin: float) -> list[float]:
    """Linear Rec. 709 colour of a light of correlated colour temperature ``kelvin``, unit
    luminance: on the CIE daylight locus from 4000 K, Kang et al.'s Planckian approximation
    below (colour-science)."""
    import colour

    xy = colour.temperature.CCT_to_xy_CIE_D(kelvin) if kelvin >= 4000 else colour.temperature.CCT_to_xy_Kang2002(
        kelvin)
    rgb = colour.XYZ_to_RGB(colour.xy_to_XYZ(xy), colour.RGB_COLOURSPACES["ITU-R BT.709"])
    rgb = np.maximum(rgb, 0.0)
    return (rgb / max(float(rgb @ [0.2126, 0.7152, 0.0722]), 1e-12)).tolist()


def _direction(elevation_deg: float, azimuth: float) -> np.ndarray:
    """(3,) unit direction at an elevation (degrees above the horizon, +Y up) and azimuth (radians)."""
    e = np.radians(elevation_deg)
    return np.array([np.cos(e) * np.sin(azimuth), np.sin(e), np.cos(e) * np.cos(azimuth)])


def _unit(rng: np.random.Generator) -> list[float]:
    v = rng.standard_normal(3)
    return (v / np.linalg.norm(v)).tolist()


def _palette(rng: np.random.Generator, n: int) -> list[list[float]]:
    """``n`` albedos: one very dark (mean over channels 0.02-0.1), one saturated, the rest of any hue and
    lightness (0.1-0.8), in random order."""
    colours = []
    for k in range(n):
        hue = rng.random(3)
        if k == 0:
            colours.append((0.02 + 0.08 * rng.random()) * (0.5 + hue) / np.mean(0.5 + hue))
        elif k == 1:
            c = np.full(3, 0.03 + 0.05 * rng.random())
            c[rng.integers(3)] = 0.5 + 0.3 * rng.random()
            colours.append(c)
        else:
            colours.append((0.1 + 0.7 * rng.random()) * (0.3 + hue) / np.max(0.3 + hue))
    order = rng.permutation(n)
    return [np.clip(colours[i], 0.005, 0.9).round(4).tolist() for i in order]


def _regions(rng: np.random.Generator, n: int) -> list[dict]:
    """``n`` regions: the first the whole body, each later one a random cap that overrides."""
    out = [{"name": "base"}]
    for k in range(1, n):
        out.append({"name": f"part{k}", "axis": _unit(rng), "ranges": [[float(0.35 + 0.45 * rng.random()), 1.0]]})
    return out


def _material(rng: np.random.Generator, kind: str) -> dict:
    if kind == "roughplastic":
        return {"model": kind, "alpha": round(float(0.05 + 0.45 * rng.random()), 3)}
    if kind == "phong":
        return {"model": kind, "exponent": round(float(np.exp(rng.uniform(np.log(5), np.log(100)))), 1)}
    return {"model": kind}


def _texture(rng: np.random.Generator, pattern: str) -> dict:
    if pattern == "earth":
        return {"texture": "assets/natural_earth_720x360.png", "scale": round(float(0.6 + 0.3 * rng.random()), 3)}
    dark, bright = _palette(rng, 2)
    return {"pattern": pattern, "colors": [dark, bright], "axis": _unit(rng),
            "frequency": float(rng.integers(2, 7))}


def _light(rng: np.random.Generator, kind: str) -> dict:
    if kind == "sunsky":
        to_sun = _direction(rng.uniform(10, 70), rng.uniform(0, 2 * np.pi))
        return {"type": "sunsky", "turbidity": round(float(rng.uniform(2, 8)), 2), "to_sun": to_sun.tolist()}
    tint = np.exp(0.1 * rng.standard_normal(3))
    tint = (tint / tint.mean()).round(4).tolist()
    if kind == "probe":
        return {"type": "envmap", "file": f"assets/{PROBES[rng.integers(len(PROBES))]}",
                "rotation": round(float(rng.uniform(0, 360)), 1), "tint": tint}
    lights = []
    for _ in range(int(rng.integers(1, 5))):
        direction = _direction(rng.uniform(-20, 80), rng.uniform(0, 2 * np.pi))
        # distant, as the method's light is (a direction's radiance, the same at every point):
        # from 40-100 object radii a sphere's irradiance varies by at most 4 R / d = 10 % across
        # the object (1 / d^2) and its direction by 1.4 degrees; half-angle 2-9 degrees
        distance = rng.uniform(40, 100)
        radius = distance * np.sin(np.radians(rng.uniform(2, 9)))
        # radiance for an irradiance of 1-4 at the origin: E = L pi sin^2(half angle)
        irradiance = rng.uniform(1, 4)
        radiance = irradiance / (np.pi * (radius / distance) ** 2)
        colour = np.asarray(blackbody_rgb(rng.uniform(2500, 9000)))
        lights.append({"position": (distance * direction).round(4).tolist(), "radius": round(float(radius), 4),
                       "radiance": (radiance * colour).round(4).tolist()})
    return {"type": "spheres", "lights": lights, "ambient": [round(float(rng.uniform(0.02, 0.1)), 4)] * 3,
            "tint": tint}


def draw(seed: int) -> tuple[dict, dict]:
    """The raw scene spec of ``seed`` (a dict as read from TOML) and its strata (the kind drawn
    on each axis: ``light``, ``material``, ``albedo``, ``geometry``, ``cameras``)."""
    rng = np.random.default_rng([seed, 20261201])
    strata = {"light": LIGHTS[rng.integers(len(LIGHTS))], "material": MATERIALS[rng.integers(len(MATERIALS))],
              "albedo": ALBEDOS[rng.integers(len(ALBEDOS))], "geometry": GEOMETRIES[rng.integers(len(GEOMETRIES))],
              "cameras": CAMERAS[rng.integers(len(CAMERAS))]}
    if strata["material"] == "mixed" and strata["albedo"] == "texture":
        strata["albedo"] = "both"        # each region its own material needs regions
    geometry = {"type": "bumpy", "subdivisions": 4, "lobes": int(rng.integers(2, 6)),
                "depth": round(float(rng.uniform(0.1, 0.3)), 3), "bumps": round(float(rng.uniform(0.03, 0.08)), 3),
                "frequency": int(rng.integers(5, 9))}
    if strata["geometry"] != "blob":
        geometry = {"type": "mesh", "file": f"assets/{strata['geometry']}.ply"}
    material: dict = _material(rng, "plastic" if strata["material"] == "mixed" else strata["material"])
    specular = round(float(rng.uniform(0.1, 0.3)), 3)
    if strata["albedo"] == "texture":
        material["diffuse"] = _texture(rng, PATTERNS[rng.integers(len(PATTERNS))])
        material["specular"] = {"value": [specular] * 3}
    else:
        n = int(rng.integers(3, 11))
        regions = _regions(rng, n)
        for region, colour in zip(regions, _palette(rng, n)):
            region["diffuse"] = colour
            region["specular"] = [specular] * 3
        if strata["albedo"] == "both":
            for region in regions[: max(1, n // 2)]:
                region["albedo"] = _texture(rng, PATTERNS[1 + rng.integers(len(PATTERNS) - 1)])
        if strata["material"] == "mixed":
            kinds = ("diffuse", "plastic", "roughplastic", "phong")
            for region in regions:
                region.update(_material(rng, kinds[rng.integers(len(kinds))]))
        material["regions"] = regions
    cameras = {"count": int(rng.integers(12, 41)), "test_count": 4, "distance": 4.0, "fov": 34.0,
               "width": 256, "height": 256,
               "distribution": "table-top" if strata["cameras"] == "table-top" else "fibonacci"}
    raw = {"name": f"random-{seed:04d}", "seed": int(seed),
           "description": "random family: " + ", ".join(f"{k} {v}" for k, v in strata.items()),
           "geometry": geometry, "material": material, "illumination": _light(rng, strata["light"]),
           "cameras": cameras, "render": {"spp": 64, "integrator": "path", "max_depth": 3},
           "profiles": PROFILES}
    return raw, strata


def random_spec(seed: int, profile: str | None = None, overrides: dict | None = None) -> SceneSpec:
    """The validated spec of ``seed`` (assets resolved from the shipped ``scenes/`` folder)."""
    from harness.scene.spec import SCENES_DIR

    raw, _ = draw(seed)
    return parse_spec(raw, SCENES_DIR, profile, overrides)
