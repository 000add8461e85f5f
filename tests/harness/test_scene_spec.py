import os

import pytest

from harness.scene.spec import SpecError, load_spec, parse_spec, resolve_scene, shipped_scenes


def test_shipped_scenes_load_with_every_profile():
    scenes = shipped_scenes()
    assert {"earth-specular", "sparse-colored", "probe-envmap"} <= set(scenes)
    for path in scenes.values():
        spec = load_spec(path)
        for profile in spec.profiles:
            load_spec(path, profile=profile)


def _base(tmp_path):
    return {"name": "t", "illumination": {"type": "directional", "lights": [{"to_light": [0, 1, 0]}]}}


@pytest.mark.parametrize("patch,message", [
    ({"cameras": {"widht": 64}}, "cameras.widht"),
    ({"colour": 1}, "spec.colour"),
    ({"cameras": {"width": 0}}, "cameras.width"),
    ({"cameras": {"fov": 200.0}}, "cameras.fov"),
    ({"render": {"spp": 0}}, "render.spp"),
    ({"material": {"exponent": -2.0}}, "material.exponent"),
    ({"material": {"specular": {"texture": "nope.png"}}}, "material.specular.texture"),
    ({"material": {"diffuse": {"value": [1, 2]}}}, "material.diffuse.value"),
    ({"illumination": {"type": "envmap", "file": "missing.hdr"}}, "illumination.file"),
    ({"illumination": {"type": "laser"}}, "illumination.type"),
    ({"illumination": {"type": "directional", "lights": [{"position": [0, 1, 0]}]}}, "illumination.lights[0]"),
    ({"geometry": {"type": "mesh"}}, "geometry.file"),
    ({"render": {"integrator": "direct"}, "illumination": {"type": "envmap", "file": "a.hdr"}}, "illumination.file"),
    ({"name": 5}, "spec.name must be a non-empty string, got 5"),
    ({"material": {"regions": [{"name": "base", "ranges": [[0.0, 1.0]]}]}}, "material.regions[0] is the base"),
    ({"material": {"regions": [{"name": "base"}, {"name": "top"}]}}, "material.regions[1].ranges is empty"),
    ({"material": {"regions": [{"name": "base"}, {"name": "top", "ranges": []}]}}, "material.regions[1].ranges"),
])
def test_bad_specs_name_the_key(tmp_path, patch, message):
    raw = _base(tmp_path)
    for key, value in patch.items():
        if isinstance(value, dict) and isinstance(raw.get(key), dict):
            raw[key] = {**raw[key], **value} if key != "illumination" else value
        else:
            raw[key] = value
    with pytest.raises(SpecError, match=message.replace("[", r"\[").replace("]", r"\]")):
        parse_spec(raw, str(tmp_path))


def test_direct_integrator_refused_for_envmap(tmp_path):
    (tmp_path / "a.hdr").write_bytes(b"")
    raw = {"name": "t", "illumination": {"type": "envmap", "file": "a.hdr"}, "render": {"integrator": "direct"}}
    with pytest.raises(SpecError, match="render.integrator"):
        parse_spec(raw, str(tmp_path))


def test_missing_and_broken_files(tmp_path):
    with pytest.raises(SpecError, match="not found"):
        load_spec(tmp_path / "none.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("name = \n")
    with pytest.raises(SpecError, match="not valid TOML"):
        load_spec(bad)
    with pytest.raises(SpecError, match="shipped"):
        resolve_scene("no-such-scene")
    with pytest.raises(SpecError, match="profile"):
        load_spec(resolve_scene("earth-specular"), profile="huge")


def test_relative_assets_resolve_against_the_spec_folder():
    spec = load_spec(resolve_scene("earth-specular"))
    assert os.path.isfile(spec.material.specular.texture)
    assert spec.illumination.file.endswith(os.path.join("scenes", "assets", "grace.hdr"))


def test_uv_textures_from_a_mesh_file(tmp_path):
    import numpy as np
    import trimesh

    from harness.scene.generate import prepare

    # a quad whose UVs cover the left half of a texture that is red on the left, blue on the right
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    uv = np.array([[0.0, 0.0], [0.5, 0.0], [0.5, 1.0], [0.0, 1.0]]) * [0.98, 1] + [0.01, 0]
    mesh = trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], visual=trimesh.visual.TextureVisuals(uv=uv), process=False)
    mesh.export(tmp_path / "quad.obj")
    from harness.io.exr import write_exr
    tex = np.zeros((4, 8, 3))
    tex[:, :4] = [1.0, 0.0, 0.0]
    tex[:, 4:] = [0.0, 0.0, 1.0]
    write_exr(tmp_path / "tex.exr", tex)
    raw = {"name": "uv", "geometry": {"type": "mesh", "file": "quad.obj"},
           "material": {"diffuse": {"texture": "tex.exr", "mapping": "uv"}},
           "illumination": {"type": "directional", "lights": [{"to_light": [0, 0, 1]}]}}
    scene = prepare(parse_spec(raw, str(tmp_path)))
    assert scene.mesh.num_faces == 2
    np.testing.assert_allclose(scene.diffuse[:, 0], 1.0, atol=0.05)   # all red: the UVs stay left
    np.testing.assert_allclose(scene.diffuse[:, 2], 0.0, atol=0.05)
    raw["geometry"] = {"type": "icosphere"}
    with pytest.raises(SpecError, match="mapping = 'uv'"):
        parse_spec(raw, str(tmp_path))


@pytest.mark.parametrize("broken, needle", [("face", "face indices"), ("vertex", "NaN or Inf")])
def test_a_spec_mesh_that_fails_its_checks_is_named(tmp_path, broken, needle):
    """A mesh file a spec names, whose faces index no vertex or whose vertices are not finite:
    the error names the file, not only what is wrong."""
    import numpy as np

    from estimator import InputError
    from harness.scene.generate import prepare

    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    faces = np.array([[0, 1, 2]])
    if broken == "face":
        faces = np.array([[0, 1, 7]])
    else:
        vertices[1, 0] = np.nan
    path = tmp_path / "bad.ply"
    body = "".join(f"{x} {y} {z}\n" for x, y, z in vertices) + "".join(f"3 {a} {b} {c}\n" for a, b, c in faces)
    path.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                    "element face 1\nproperty list uchar int vertex_indices\nend_header\n" + body)
    raw = {"name": "m", "geometry": {"type": "mesh", "file": "bad.ply"},
           "illumination": {"type": "directional", "lights": [{"to_light": [0, 0, 1]}]}}
    with pytest.raises(InputError, match=needle) as caught:
        prepare(parse_spec(raw, str(tmp_path)))
    assert str(path) in str(caught.value)


def test_overrides_naming_an_unknown_top_level_key_are_refused(tmp_path):
    raw = _base(tmp_path)
    with pytest.raises(SpecError, match="spec.bogus"):
        parse_spec(raw, str(tmp_path), overrides={"bogus": 3})
    raw["profiles"] = {"p": {"bogus.x": 1}}
    with pytest.raises(SpecError, match="spec.bogus"):
        parse_spec(raw, str(tmp_path), profile="p")
    assert parse_spec(_base(tmp_path), str(tmp_path), overrides={"cameras.width": 32}).cameras.width == 32


@pytest.mark.parametrize("material, key", [
    ({"diffuse": {"value": [0.5, 1.2, 0.5]}}, "material.diffuse"),
    ({"specular": {"value": [3.0, 3.0, 3.0]}}, "material.specular"),
    ({"diffuse": {"pattern": "checks", "colors": [[0.1, 0.1, 0.1], [0.9, 0.9, 0.9]], "scale": 2.0}},
     "material.diffuse"),
    ({"regions": [{"name": "base", "diffuse": [0.5, 0.5, 0.5]},
                  {"name": "top", "diffuse": [1.5, 0.1, 0.1], "ranges": [[0.5, 1.0]]}]}, "material.regions[1].diffuse"),
])
def test_an_albedo_above_one_is_refused_by_its_key(tmp_path, material, key):
    """A reflectance is at most 1: a value, a pattern's colours times its scale, or a region's
    albedo above it would be a ground truth of no surface, and generation names the key."""
    from harness.scene.generate import prepare

    spec = parse_spec({**_base(tmp_path), "geometry": {"type": "icosphere", "subdivisions": 1},
                       "material": material}, str(tmp_path))
    with pytest.raises(SpecError, match=key.replace("[", r"\[").replace("]", r"\]") + " gives albedos up to"):
        prepare(spec)
