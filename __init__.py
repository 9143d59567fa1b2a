r"""translucent: how wrong and how fast are subsurface-scattering and BRDF-editing approximations.

The suite is organised one folder a concept, data flowing left to right::

    materials -> scenes -> reference -> reports
                       \-> fast      -/
    materials -> fitting -------------/

Importing the top-level package is cheap: Mitsuba is loaded only when a ray query or a
reference render first needs it (see :mod:`translucent.backend`).
"""

from .backend import configure_libllvm
from .errors import InputError
from .image import Image

configure_libllvm()

__version__ = "0.1.0"

__all__ = ["Image", "InputError", "__version__"]
