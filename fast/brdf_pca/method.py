"""The BRDF-editing method's contract: applicability, precomputation, the command line."""

from __future__ import annotations

import time

from ...errors import InputError
from ...image import Image
from ...materials.brdfs import AnalyticBRDF
from ...materials.homogeneous import Lambertian
from ..base import (
    NOTHING_TO_EDIT,
    UNSUPPORTED_LIGHT,
    UNSUPPORTED_MATERIAL,
    Refusal,
    applicability,
    load_or_precompute,
    refuse_inapplicable,
)
from .knobs import FORMAT_VERSION, KNOBS
from .lighting import check_lights
from .state import BRDFPCAState
from .transfer import Precomputation, compute_precomputation, is_glossy_material

__all__ = ["add_approx_arguments", "applies_to", "approx", "model_name", "precompute"]


def applies_to(scene) -> Refusal | None:
    """None when every object is Lambertian or an analytic BRDF and one is an analytic BRDF.

    Nguyen et al. 2010 edit analytic BRDFs of opaque surfaces lit by point-like and area
    lights; translucent media, environment lights and scenes with nothing to edit are not
    theirs.
    """
    for obj in scene.objects:
        if not isinstance(obj.material, (AnalyticBRDF, Lambertian)):
            return Refusal(UNSUPPORTED_MATERIAL,
                           f"object '{obj.name}' has a {type(obj.material).__name__} "
                           "material; the BRDF-editing method takes opaque surfaces "
                           "(Lambertian or analytic BRDFs)")
    if not any(is_glossy_material(o.material) for o in scene.objects):
        return Refusal(NOTHING_TO_EDIT,
                       "no object has an analytic BRDF: there is nothing to edit")
    try:
        check_lights(scene.lights)
    except InputError as error:
        return Refusal(UNSUPPORTED_LIGHT, str(error))
    return None


def model_name(knobs: dict) -> str:
    """Return the model the method approximates: its PCA BRDF carried by its gather transport.

    The K-term PCA of its BRDFs (Eq. 10) with the transport it converges to: the first
    surface by its (PCA) BRDF, the next ``bounces + 1`` diffusely (Sect. 5.2, Eq. 17). The
    reference renders it exactly (``brdf_pca_kK+lambertian_gatherN``,
    :func:`~translucent.materials.brdf_pca.pca_model_name`): against the exact-BRDF
    reference that is the PCA's and the Lambertian gather's error (the report splits the
    two where ``brdf_pca_kK`` is committed); the method against it, the gather samples',
    the wavelets', the sub-areas' and the one-ray G-buffer's. With ``gather_reflection``
    "brdf" the gather samples reflect their direct light by their BRDF
    (``brdf_pca_kK+glossy_gatherN``).
    """
    from ...materials.brdf_pca import GLOSSY_GATHER, LAMBERTIAN_GATHER, pca_model_name

    resolved = KNOBS.resolve(knobs)
    transport = GLOSSY_GATHER if resolved["gather_reflection"] == "brdf" else LAMBERTIAN_GATHER
    return pca_model_name(resolved["n_basis"], resolved["bounces"], transport)


def _resolve_knobs(knobs: dict) -> dict:
    return KNOBS.resolve(knobs)


def _structure_key(scene) -> list:
    """Return what the precomputation depends on besides geometry and camera.

    Which objects are glossy and their fixed-term parameters: never gamma, rho_s, rho_d
    or the lights.
    """
    out = []
    for obj in scene.objects:
        material = obj.material
        if is_glossy_material(material):
            out.append([obj.name, material.model, material.f0, list(material.lafortune_c)])
        else:
            out.append([obj.name, "diffuse"])
    return out


def precompute(scene, **knobs) -> BRDFPCAState:
    r"""Precompute the transfers of Sects. 3-5 of Nguyen et al. 2010; cached on disk.

    The cache key holds the geometry, the camera, the knobs and which objects carry which
    BRDF model (and its fixed-term parameters ``f0``, ``lafortune_c``) -- never gamma,
    :math:`\rho_s`, :math:`\rho_d` or the lights, which the state edits interactively.

    Parameters
    ----------
    scene : Scene
    **knobs
        See :data:`DEFAULT_KNOBS`.

    Returns
    -------
    BRDFPCAState

    Raises
    ------
    InputError
        When the method does not apply (:func:`applies_to`), or a knob is unknown or out
        of range.
    """
    from ...cache import content_hash

    refuse_inapplicable(scene, applicability(applies_to, scene),
                        "the BRDF-editing method does not apply")
    resolved = _resolve_knobs(knobs)
    key = content_hash("brdf_pca", FORMAT_VERSION, scene.geometry_key(),
                       scene.camera.cache_key(), KNOBS.keyed(resolved), _structure_key(scene))

    def make():
        started = time.perf_counter()
        data = compute_precomputation(scene, resolved)
        data.log.seconds["total"] = time.perf_counter() - started
        return data

    data, _ = load_or_precompute("brdf_pca", key, make, what="the BRDF-editing precomputation",
                                 log_of=lambda value: value.log,
                                 valid=lambda value: isinstance(value, Precomputation))
    return BRDFPCAState(scene, data, run_knobs={name: resolved[name] for name in KNOBS.unkeyed})


# ---------------------------------------------------------------------------------------
# the interactive state


# ---------------------------------------------------------------------------------------
# command line


def add_approx_arguments(parser) -> None:
    """Add the options of ``translucent approx brdf_pca SCENE``."""
    parser.add_argument("--object", default=None,
                        help="object whose gamma to set (default: the only glossy object)")
    parser.add_argument("--gamma", type=float, default=None,
                        help="editing parameter of --object, in its model's range")
    KNOBS.add_arguments(parser)


def approx(scene, args) -> Image:
    """Precompute (or load) and render ``scene`` for ``translucent approx brdf_pca``."""
    started = time.perf_counter()
    # the edit is checked against the scene before the (slow) precomputation
    glossy = [o.name for o in scene.objects if is_glossy_material(o.material)]
    name = args.object
    if name is None and args.gamma is not None:
        if len(glossy) != 1:
            raise InputError("several objects have an analytic BRDF: name one with --object "
                             f"({', '.join(glossy)})", field="object", value=None)
        name = glossy[0]
    if name is not None and args.gamma is None:
        raise InputError("--object needs --gamma", field="gamma", value=None)
    if name is not None:
        if name not in glossy:
            raise InputError(f"not an object with an analytic BRDF; editable: "
                             f"{', '.join(glossy)}", field="object", value=name)
        scene.object(name).material.with_gamma(args.gamma)  # range-checked
    state = precompute(scene, **KNOBS.from_arguments(args))
    image = state.edit(name, args.gamma) if name is not None else state.render()
    for sentence in state.log.skipped:
        print(f"skipped: {sentence}")
    return image.with_metadata(seconds=time.perf_counter() - started,
                               precompute_seconds=dict(state.log.seconds))
