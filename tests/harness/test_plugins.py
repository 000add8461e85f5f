"""Plugin properties are validated, parameters traversable, the scene XML writer loads in Mitsuba."""
import numpy as np
import pytest

from harness import plugins

plugins.register_all()
import mitsuba as mi  # noqa: E402

from harness.scene.xml import scene_xml  # noqa: E402


@pytest.mark.parametrize("plugin", [plugins.DIFFUSE_MIRROR, plugins.PHONG])
def test_bsdf_properties_are_validated_and_traversed(plugin):
    bsdf = mi.load_dict({"type": plugin, "diffuse_reflectance": [0.2, 0.3, 0.4], "specular_reflectance": 0.1})
    params = mi.traverse(bsdf)
    assert any(k.startswith("diffuse_reflectance") for k in params.keys())
    assert any(k.startswith("specular_reflectance") for k in params.keys())
    with pytest.raises(Exception, match="diffuse_reflectance"):
        mi.load_dict({"type": plugin, "diffuse_reflectance": -0.5})


def test_plugin_classes_live_at_module_level():
    from harness.plugins.diffuse_mirror_bsdf import DiffuseMirrorBSDF
    from harness.plugins.direct_integrator import DirectDeltaIntegrator
    from harness.plugins.phong_bsdf import PhongBSDF

    assert issubclass(PhongBSDF, mi.BSDF) and issubclass(DiffuseMirrorBSDF, mi.BSDF)
    assert issubclass(DirectDeltaIntegrator, mi.SamplingIntegrator)


def test_scene_xml_loads_in_mitsuba(tmp_path):
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2, "hide_emitters": True},
        "light": {"type": "constant"},
        "sensor": {"type": "perspective", "fov": 30.0, "to_world": np.diag([-1.0, 1.0, -1.0, 1.0]) @ np.eye(4),
                   "film": {"type": "hdrfilm", "width": 8, "height": 6, "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 4}},
    }
    path = tmp_path / "scene.xml"
    path.write_text(scene_xml(scene, "test"))
    loaded = mi.load_file(str(path))
    assert tuple(loaded.sensors()[0].film().size()) == (8, 6)
    assert "max_depth = 2" in str(loaded.integrator())
    with pytest.raises(ValueError, match="no XML form"):
        scene_xml({"type": "scene", "bad": np.zeros((2, 2))})
