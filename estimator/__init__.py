"""pseudolight estimator: texture map and pseudo illumination from multiple views.

Math on in-memory arrays only: no file formats, no CLI, no plotting. This module is the
public API that ``harness``, ``reports``, tests and benchmarks import; the rooms below it
(``core`` < ``rays`` < ``model`` < ``solvers`` < ``light`` < ``pipeline`` <
``diagnostics`` < ``methods`` < ``api``) are described in ``docs/architecture.md``.
"""
from .api import DEFAULT_METHOD, EXPONENT_CANDIDATES, estimate
from .config import COMPONENTS, DIFFUSE_LIGHTS, LOSSES, SPECULAR_MODELS, EstimatorConfig
from .core import camera, latlong, sh
from .core.atlas import uv_atlas
from .core.camera import Camera, gl_to_mitsuba, look_at, mitsuba_sensor, mitsuba_to_gl, multijitter_count
from .core.data import MultiViewData, TriangleMesh, View
from .core.errors import InputError
from .core.gauge import unit_dc
from .core.interrupt import StopRequested, clear_stop, request_stop, stop_signals_handled
from .core.psnr import PSNR_CAP_DB, psnr_db
from .core.sh import axis_angle_matrix, fibonacci_sphere
from .diagnostics.trust import warnings_for
from .diagnostics.validation import cross_validate, cross_validation_warnings, holdout_indices, prediction_scores
from .methods import REGISTRY, Method, get_method, register_method
from .model.estimate import Estimate
from .model.forward import Predictor
from .model.reflection import diffuse_matrix, fresnel_dielectric
from .model.reflection_models import MitsubaMaterial, NoMitsubaEquivalent, reflection_model
from .pipeline.pose import outline_offsets, reprojection_error
from .rays import backend
from .rays.backend import VARIANTS
from .rays.raycast import RayCaster, mitsuba_mesh
from .rays.visibility import SphereSampling, Visibility, compute_visibility, sphere_sampling

__all__ = [
    "StopRequested",
    "clear_stop",
    "request_stop",
    "stop_signals_handled",
    "COMPONENTS",
    "DEFAULT_METHOD",
    "DIFFUSE_LIGHTS",
    "EXPONENT_CANDIDATES",
    "LOSSES",
    "REGISTRY",
    "PSNR_CAP_DB",
    "SPECULAR_MODELS",
    "psnr_db",
    "unit_dc",
    "uv_atlas",
    "VARIANTS",
    "axis_angle_matrix",
    "diffuse_matrix",
    "fresnel_dielectric",
    "fibonacci_sphere",
    "Camera",
    "Estimate",
    "EstimatorConfig",
    "InputError",
    "Method",
    "MitsubaMaterial",
    "MultiViewData",
    "NoMitsubaEquivalent",
    "Predictor",
    "RayCaster",
    "SphereSampling",
    "TriangleMesh",
    "View",
    "Visibility",
    "backend",
    "camera",
    "compute_visibility",
    "cross_validate",
    "cross_validation_warnings",
    "estimate",
    "get_method",
    "gl_to_mitsuba",
    "holdout_indices",
    "latlong",
    "look_at",
    "mitsuba_mesh",
    "mitsuba_sensor",
    "multijitter_count",
    "mitsuba_to_gl",
    "outline_offsets",
    "prediction_scores",
    "reflection_model",
    "register_method",
    "reprojection_error",
    "sh",
    "sphere_sampling",
    "warnings_for",
]
