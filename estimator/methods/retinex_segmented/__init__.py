"""``retinex-segmented``, the default method, as stages: the edges' hypothesis
(:mod:`.edges`), the coat's (:mod:`.coat`) and the lobe's (:mod:`.lobe`), the decision among
them (:mod:`.decision`), and the estimate of the chosen light (:mod:`.result`), run by
:class:`RetinexSegmented` (:mod:`.method`)."""
from .method import RegionConfig, RetinexSegmented

__all__ = ["RegionConfig", "RetinexSegmented"]
