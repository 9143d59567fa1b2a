"""The fast-method contract, written once: what a method offers the command line and the report.

Every other statement of the contract is derived from :data:`CONTRACT`: the registry's
check of a method (:func:`translucent.fast.registry.contract_problems`), the typed
interface :class:`FastMethod` that type checkers read, and the two tables of
docs/methods.md (:func:`contract_table`, kept equal to the page by a test).

A method is a module (or any object) with the required parts and any of the optional
ones. Its state renders interactively (:class:`~translucent.fast.base.PrecomputedState`).
Progress is the suite's, not a method's: a method shows its bars with
:func:`translucent.progress.progress_bar` (or :class:`~translucent.fast.base.StageProgress`),
which the command line's ``--no-progress`` and the report's workers hide, so no method has
a knob for it.

Examples
--------
>>> [part.name for part in CONTRACT if part.required and part.kind != "state"]
['applies_to', 'precompute', 'DEFAULT_KNOBS']
>>> print(contract_table(required=True).splitlines()[0])
| name | what it is |
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

__all__ = ["CONTRACT", "ContractPart", "FastMethod", "OPTIONAL", "REQUIRED", "contract_table"]


@dataclass(frozen=True)
class ContractPart:
    """One part of the contract.

    Parameters
    ----------
    name : str
        The attribute's name on the method's module or object.
    kind : {"function", "dict", "knob spec", "rule", "state"}
        What it must be: a callable, a dict with str keys, a
        :class:`~translucent.fast.knobs.KnobSpec`, a key of
        :data:`~translucent.materials.profiles.HETEROGENEOUS_RULES`, or a part of the state
        ``precompute`` returns (documented, checked by the conformance suite).
    required : bool
    signature : str
        How it is called or what it holds, as the tables show it.
    summary : str
        One line for the registry's error messages.
    description : str
        The docs' sentence.
    """

    name: str
    kind: str
    required: bool
    signature: str
    summary: str
    description: str


#: The contract. Order is the tables' order.
CONTRACT: tuple[ContractPart, ...] = (
    ContractPart(
        "applies_to", "function", True, "applies_to(scene)",
        "a function applies_to(scene) returning None or a Refusal",
        "`None` when the method can render the scene; otherwise why not, as a "
        "`translucent.fast.base.Refusal(code, sentence)` (the conformance check `refusal` "
        "asks for one; the codes the built-in methods share are in `translucent.fast.base`). "
        "The report shows the sentence as \"not applicable\"; programs branch on the code."),
    ContractPart(
        "precompute", "function", True, "precompute(scene, **knobs)",
        "a function precompute(scene, **knobs) returning a state",
        "the slow step; returns a state. An unknown knob raises "
        "`translucent.errors.InputError` (`KNOBS.resolve(knobs)` below does it, or "
        "`translucent.fast.base.with_defaults(knobs, DEFAULT_KNOBS)`). Ask "
        "`translucent.fast.base.applicability(applies_to, scene)` rather than "
        "`applies_to(scene)`: the report has asked already, and the answer is passed on. "
        "Store it with `translucent.fast.base.load_or_precompute` (one lock, one cache note)."),
    ContractPart(
        "state.render", "state", True, "state.render(lights=None, material=None)",
        "the state's render(lights=None, material=None) -> Image",
        "one frame, a `translucent.image.Image` of the camera's size: linear radiance, "
        "finite, non-negative. New lights relight and a new material edits *without "
        "precomputing again*."),
    ContractPart(
        "DEFAULT_KNOBS", "dict", True, "DEFAULT_KNOBS",
        "a dict of the knobs and their defaults",
        "the knobs and their defaults."),
    ContractPart(
        "scored_objects", "function", False, "scored_objects(scene)",
        "a function scored_objects(scene) -> list of object names",
        "the objects the method renders (others left black): the report scores it on "
        "their pixels only and says so."),
    ContractPart(
        "model_name", "function", False, "model_name(knobs)",
        "a function model_name(knobs) -> the name of the model the method approximates",
        "the model the method approximates at these knobs, as the reference renders it "
        "exactly: the report splits the method's error into the model's and the method's "
        "own against that render (docs/report.md). Without it a method with a `profile` "
        "knob stands on its profile (a radial profile, rendered by the BSSRDF path "
        "tracer); BRDF editing returns `brdf_pca_kK`, its K-term PCA BRDF."),
    ContractPart(
        "HETEROGENEOUS_RULE", "rule", False, "HETEROGENEOUS_RULE",
        "a key of translucent.materials.profiles.HETEROGENEOUS_RULES",
        "how the method mixes the media of a heterogeneous (solid) object into the profile "
        "between two points, a key of `translucent.materials.profiles.HETEROGENEOUS_RULES` "
        "(`geometric_mean`: Chen et al. 2012, Eq. 8; `segment_mix`: Sheng et al. 2014, "
        "Eq. 16): the report renders the rule exactly (the BSSRDF path tracer) and splits "
        "the method's error on a solid scene into the rule's and the method's own."),
    ContractPart(
        "KNOBS", "knob spec", False, "KNOBS",
        "a translucent.fast.knobs.KnobSpec declaring the knobs (validation, flags, cache "
        "key, ladders)",
        "a `translucent.fast.knobs.KnobSpec`: the knobs declared once (below). "
        "`DEFAULT_KNOBS = KNOBS.defaults`."),
    ContractPart(
        "QUICK_KNOBS", "dict", False, "QUICK_KNOBS",
        "a dict of cheap knobs for smoke runs and the conformance checks",
        "cheap knobs for smoke runs and the conformance checks."),
    ContractPart(
        "LADDERS", "dict", False, "LADDERS",
        "a dict of ladder name -> list of knob dicts for `bench tradeoff`",
        "`{ladder name: [knob dict, ...]}`, cheap to dear: the quality ladders of "
        "`translucent bench tradeoff` and the report (without it, those of `KNOBS`; "
        "without either, ladders are generated from integer quality knobs)."),
    ContractPart(
        "approx", "function", False, "approx(scene, args)",
        "a function approx(scene, args) -> Image for `translucent approx`",
        "the method's own `translucent approx` rendering, with the options of "
        "`add_approx_arguments`. Without them the command takes a flag per knob of "
        "`KNOBS`, or without `KNOBS` `--knob NAME=VALUE` (repeatable; the value is read "
        "as the type of the knob's default), and renders "
        "`precompute(scene, **knobs).render()`."),
    ContractPart(
        "add_approx_arguments", "function", False, "add_approx_arguments(parser)",
        "a function add_approx_arguments(parser)",
        "the method's own `translucent approx` options (with `approx`)."),
    ContractPart(
        "state.log", "state", False, "state.log",
        "the state's StageLog",
        "a `translucent.fast.base.StageLog`: what the method skipped and why, seconds per "
        "stage; the report shows them."),
)

#: The module-level attributes every method has, and what each must be.
REQUIRED = {part.name: part.summary for part in CONTRACT
            if part.required and part.kind != "state"}

#: The module-level attributes a method may have.
OPTIONAL = {part.name: part.summary for part in CONTRACT
            if not part.required and part.kind != "state"}


@runtime_checkable
class FastMethod(Protocol):
    """The typed interface of a fast method's module or object (the required parts).

    ``isinstance(module, FastMethod)`` says whether the required attributes are there;
    :func:`translucent.fast.registry.contract_problems` says what is wrong, part by part.
    """

    DEFAULT_KNOBS: dict[str, Any]

    def applies_to(self, scene) -> Any:
        """None, or why the method cannot render ``scene`` (a Refusal)."""

    def precompute(self, scene, **knobs) -> Any:
        """Return a state whose ``render(lights=None, material=None)`` is a frame (slow)."""


def contract_table(required: bool) -> str:
    """Return the Markdown table of the required (or optional) parts, as docs/methods.md has it.

    Parameters
    ----------
    required : bool
        The required parts (columns "name | what it is") or the optional ones ("name |
        what it is for"); ``approx`` and ``add_approx_arguments`` share one row.
    """
    head = "what it is" if required else "what it is for"
    rows = [f"| name | {head} |", "| --- | --- |"]
    parts = [part for part in CONTRACT if part.required == required]
    for part in parts:
        if part.name == "add_approx_arguments":
            continue
        signature = f"`{part.signature}`"
        if part.name == "approx":
            signature += ", `add_approx_arguments(parser)`"
        rows.append(f"| {signature} | {part.description} |")
    return "\n".join(rows)
