r"""translucent: how wrong and how fast are subsurface-scattering and BRDF-editing approximations.

The suite is organised one folder a concept, data flowing left to right::

    materials -> scenes -> reference -> reports
                       \-> fast      -/
    materials -> fitting -------------/

From Python, the package offers what the command line does (:mod:`translucent.api`):
``load_scene``, ``render``, ``compare``, ``approx``, ``method`` and ``fit``, with ``Image``
and ``InputError``; and ``profile`` (a scattering profile by name,
:mod:`translucent.materials.profiles`).

Importing the top-level package is cheap: those functions are imported when first used,
and Mitsuba only when a ray query or a reference render first needs it (see
:mod:`translucent.backend`).
"""

from .backend import configure_libllvm
from .errors import InputError
from .image import Image

configure_libllvm()

__version__ = "0.1.0"

#: The functions of :mod:`translucent.api`, imported on first use.
API = ("load_scene", "render", "compare", "approx", "method", "fit")

#: Functions of other modules, imported on first use: name -> module.
LAZY = {"profile": "translucent.materials.profiles.registry"}

__all__ = ["Image", "InputError", "__version__", *API, *LAZY]


def __getattr__(name):
    if name in API:
        from . import api

        return getattr(api, name)
    if name in LAZY:
        import importlib

        return getattr(importlib.import_module(LAZY[name]), name)
    raise AttributeError(f"module 'translucent' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(API) | set(LAZY))
