"""The estimator's whole configuration: every room's section, composed.

Each section is a dataclass beside the code that reads it, with its own checks
(:class:`estimator.core.settings.Section`). :class:`EstimatorConfig` inherits them all, so
its setting names are one flat namespace: the wire format of scene TOML files, suites,
``run.json``, the command line and sweep job hashes. :data:`SECTIONS` lists the sections in
field order (``tests/estimator/test_config.py`` pins every name and its order).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

from .core import sh
from .light.coat import CoatConfig
from .light.coat_map import CoatMapConfig
from .light.edge_fit import EdgeFitConfig
from .light.indirect import IndirectConfig
from .light.lobe_light import LobeLightConfig
from .light.sun import SunConfig
from .methods.clustered import ClusteredConfig
from .methods.mitsuba_ad import PeerConfig
from .methods.retinex_segmented import RegionConfig
from .methods.segmented import SegmentedConfig
from .model.reflection_models import DIFFUSE_LIGHTS, SPECULAR_MODELS
from .pipeline.exposure import ExposureConfig
from .pipeline.pose import PoseConfig
from .pipeline.prepared import PrepareConfig
from .solvers.albedo_prior import AlbedoPriorConfig
from .solvers.bilinear import COMPONENTS, BilinearConfig
from .solvers.robust import LOSSES, RobustConfig
from .solvers.segmentation import SegmentationConfig

__all__ = ["COMPONENTS", "DIFFUSE_LIGHTS", "LOSSES", "SECTIONS", "SPECULAR_MODELS", "EstimatorConfig"]


@dataclass
class EstimatorConfig(ExposureConfig, PoseConfig, PeerConfig, RegionConfig, SegmentedConfig, ClusteredConfig,
                      IndirectConfig, LobeLightConfig, CoatMapConfig, CoatConfig, SunConfig, EdgeFitConfig,
                      AlbedoPriorConfig, SegmentationConfig, RobustConfig, BilinearConfig, PrepareConfig):
    """Every setting of the estimator (defaults follow the paper where it gives one); the
    sections document them. Refused with :class:`~estimator.core.errors.InputError` naming
    the setting when a value has the wrong type or lies outside its range."""

    def check(self):
        m = sh.num_coeffs(self.sh_order)
        return [(self.retinex_max_edges >= m, f"retinex_max_edges must be at least the light's (sh_order + 1)^2 = "
                                              f"{m} coefficients: fewer edges leave the edge fit's light undetermined")]

    def to_dict(self) -> dict:
        """The flat settings, in field order (the wire format)."""
        return asdict(self)


SECTIONS = tuple(cls for cls in reversed(EstimatorConfig.__mro__[1:])
                 if "__dataclass_fields__" in cls.__dict__ and cls.__dict__.get("__annotations__"))
