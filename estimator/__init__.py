"""pseudolight estimator: texture map and pseudo illumination from multiple views.

Math on in-memory arrays only: no file formats, no CLI, no plotting.
"""

from .methods import REGISTRY, estimate  # noqa: E402,F401
