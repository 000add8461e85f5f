"""Mitsuba scene dictionaries (the ``mi.load_dict`` form) written as Mitsuba 3 XML.

Mitsuba 3.9.1 ships no dict-to-XML writer (Mitsuba 2's ``WriteXML`` was not
ported), so this is a small serializer over :mod:`xml.etree.ElementTree`:
nested plugin dictionaries become elements whose tag follows from their plugin
type, and values become the typed property elements of Mitsuba's format.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

# plugin type -> XML tag, for the plugins pseudolight writes
PLUGIN_TAGS = {
    "path": "integrator",
    "direct": "integrator",
    "prb": "integrator",
    "ply": "shape",
    "obj": "shape",
    "envmap": "emitter",
    "constant": "emitter",
    "directional": "emitter",
    "point": "emitter",
    "sunsky": "emitter",
    "perspective": "sensor",
    "hdrfilm": "film",
    "box": "rfilter",
    "gaussian": "rfilter",
    "independent": "sampler",
    "multijitter": "sampler",
    "mesh_attribute": "texture",
    "bitmap": "texture",
    "diffuse": "bsdf",
    "conductor": "bsdf",
    "roughconductor": "bsdf",
    "blendbsdf": "bsdf",
    "plastic": "bsdf",
    "roughplastic": "bsdf",
    "pseudolight_phong": "bsdf",
    "pseudolight_diffuse_mirror": "bsdf",
}


class _NumpyTransforms:
    """Stands in for the mitsuba module where a dict builder only wraps matrices
    (``mi.ScalarTransform4f``): the dicts then hold plain 4x4 arrays, which this writer
    takes, and nothing of Mitsuba is loaded."""

    @staticmethod
    def ScalarTransform4f(matrix):  # noqa: N802 (Mitsuba's name)
        return np.asarray(matrix, dtype=np.float64)


NUMPY_TRANSFORMS = _NumpyTransforms()

# properties whose three numbers are a direction or a position, not a colour
VECTOR_PROPERTIES = {"direction", "sun_direction"}
POINT_PROPERTIES = {"position"}


def _property(parent: ET.Element, name: str, value) -> None:
    if hasattr(value, "matrix"):        # a Mitsuba ScalarTransform4f
        value = np.array(value.matrix, dtype=np.float64)
    if isinstance(value, dict) and value.get("type") == "rgb":
        ET.SubElement(parent, "rgb", name=name, value=" ".join(f"{float(v):.9g}" for v in np.ravel(value["value"])))
    elif isinstance(value, dict):
        _plugin(parent, value, name)
    elif isinstance(value, bool):
        ET.SubElement(parent, "boolean", name=name, value="true" if value else "false")
    elif isinstance(value, (int, np.integer)):
        ET.SubElement(parent, "integer", name=name, value=str(int(value)))
    elif isinstance(value, (float, np.floating)):
        ET.SubElement(parent, "float", name=name, value=f"{float(value):.9g}")
    elif isinstance(value, str):
        ET.SubElement(parent, "string", name=name, value=value)
    else:
        array = np.asarray(value, dtype=np.float64)
        if array.shape == (4, 4):
            transform = ET.SubElement(parent, "transform", name=name)
            ET.SubElement(transform, "matrix", value=" ".join(f"{v:.9g}" for v in array.ravel()))
        elif array.shape == (3,) and name in VECTOR_PROPERTIES | POINT_PROPERTIES:
            tag = "vector" if name in VECTOR_PROPERTIES else "point"
            ET.SubElement(parent, tag, name=name, **{k: f"{v:.9g}" for k, v in zip("xyz", array)})
        elif array.shape == (3,):
            ET.SubElement(parent, "rgb", name=name, value=" ".join(f"{v:.9g}" for v in array))
        else:
            raise ValueError(f"scene_xml: property {name!r} has no XML form (shape {array.shape})")


def _plugin(parent: ET.Element, plugin: dict, name: str | None) -> None:
    kind = plugin.get("type")
    if kind not in PLUGIN_TAGS:
        raise ValueError(f"scene_xml: plugin type {kind!r} is not in PLUGIN_TAGS")
    element = ET.SubElement(parent, PLUGIN_TAGS[kind], type=kind)
    if name is not None and PLUGIN_TAGS[kind] == "texture":
        element.set("name", name)
    for key, value in plugin.items():
        if key != "type":
            _property(element, key, value)


def scene_xml(scene: dict, comment: str | None = None) -> str:
    """The XML text of a scene dictionary ``{'type': 'scene', name: plugin dict, ...}``.

    Plugin dictionaries nest as in ``mi.load_dict``; values may be bool, int,
    float, str, an RGB triple (or ``{'type': 'rgb', 'value': ...}``), a direction or
    position triple (names in ``VECTOR_PROPERTIES`` / ``POINT_PROPERTIES``) or a 4x4
    matrix or ``ScalarTransform4f`` (a ``to_world`` transform).
    """
    if scene.get("type") != "scene":
        raise ValueError("scene_xml: the top-level dictionary must have type 'scene'")
    root = ET.Element("scene", version="3.0.0")
    if comment:
        root.append(ET.Comment(f" {comment} "))
    for key, value in scene.items():
        if key == "type":
            continue
        if isinstance(value, dict):
            _plugin(root, value, key)
        else:
            _property(root, key, value)
    ET.indent(root, space="    ")
    return ET.tostring(root, encoding="unicode") + "\n"
