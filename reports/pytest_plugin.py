"""pytest plugin: image-metric checks for any project's test suite.

Installed with ``translucent`` and registered through the ``pytest11`` entry point, so a
project's tests need no conftest. It offers:

``assert_image_close(test, reference, metric="hdr_flip", max=...)``
    Fails when a metric of :mod:`translucent.reports.metrics` is beyond its bound
    (``max`` for errors, ``min`` for psnr and ssim) and writes the error maps
    (:func:`~translucent.reports.metrics.maps.write_error_maps`) into a folder the
    message names. Where the reference carries its variance, the message gives the
    metric's noise floor and verdict, and a bound tighter than the floor warns
    (:class:`ReferenceNoiseWarning`).
``assert_render_consistent(test, reference_mean, reference_variance, spp=...)``
    Mitsuba 3's per-pixel z-test with Šidák correction
    (:func:`~translucent.reports.metrics.statistics.z_test`); on failure writes the p-value
    image, the rejected pixels, both images and their difference.

Both are importable functions (``from translucent.reports.pytest_plugin import
assert_image_close``) and methods of the ``image_checks`` fixture, which files each
test's artifacts under its own folder. Images may be :class:`~translucent.image.Image`,
``H x W x 3`` arrays or paths to OpenEXR files.

``reference_image(path, producer)`` (fixture) returns the reference stored at ``path``
(relative paths are taken from the test file's folder), calling ``producer()`` and
writing its result there when the file is missing or ``--translucent-regenerate`` is
given; the run's summary lists what was regenerated.

Options: ``--translucent-artifacts DIR`` (default ``translucent-artifacts`` under
pytest's base temporary folder) and ``--translucent-regenerate``.
"""

from __future__ import annotations

import os
import re
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest

__all__ = ["assert_image_close", "assert_render_consistent", "ImageChecks",
           "ReferenceNoiseWarning", "artifacts_root"]


class ReferenceNoiseWarning(UserWarning):
    """A check's bound is tighter than what the reference's own noise resolves."""

#: Passes a reference for assert_render_consistent should have: with fewer, the Student's
#: t of its estimated variance lets only large differences fail (at the Sidak alpha of a
#: 32 x 32 image: 61 standard errors at 4 passes, 11 at 8, 6.5 at 16; 4.4 with a known
#: variance).
RECOMMENDED_REFERENCE_PASSES = 16


#: The configs of the pytest runs in progress, innermost last (pytester nests runs).
_CONFIGS: list = []

#: Paths regenerated in this run, per config, for the terminal summary.
_REGENERATED = pytest.StashKey[list]()


def pytest_addoption(parser):
    """Register ``--translucent-artifacts`` and ``--translucent-regenerate``."""
    group = parser.getgroup("translucent", "image-metric checks (translucent)")
    group.addoption("--translucent-artifacts", default=None, metavar="DIR",
                    help="folder for the error maps of failed image checks (default: "
                         "translucent-artifacts under pytest's base temporary folder)")
    group.addoption("--translucent-regenerate", action="store_true", default=False,
                    help="rewrite every reference image requested through the "
                         "reference_image fixture by calling its producer")


def pytest_configure(config):
    """Remember the run so that the module-level assertions find its artifacts folder."""
    config.stash[_REGENERATED] = []
    _CONFIGS.append(config)


def pytest_unconfigure(config):
    """Forget the run."""
    if config in _CONFIGS:
        _CONFIGS.remove(config)


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """List the reference images regenerated in this run."""
    regenerated = config.stash.get(_REGENERATED, [])
    if regenerated:
        terminalreporter.section("translucent: references regenerated")
        for path in regenerated:
            terminalreporter.write_line(str(path))


def artifacts_root(config=None) -> Path:
    """Return the folder under which failed image checks leave their artifacts.

    Parameters
    ----------
    config : pytest.Config, optional
        The run; default the innermost run in progress.

    Returns
    -------
    Path
        ``--translucent-artifacts`` when given (a relative folder is taken from where
        pytest was started); otherwise ``translucent-artifacts`` under
        pytest's base temporary folder, or under the system temporary folder outside
        pytest.
    """
    config = config if config is not None else (_CONFIGS[-1] if _CONFIGS else None)
    if config is not None:
        chosen = config.getoption("translucent_artifacts", default=None)
        if chosen:
            # relative to where pytest was started, not to a folder a test moved into
            return (Path(config.invocation_params.dir) / Path(chosen).expanduser()).resolve()
        factory = getattr(config, "_tmp_path_factory", None)
        if factory is not None:
            return factory.getbasetemp() / "translucent-artifacts"
    return Path(tempfile.gettempdir()) / "translucent-artifacts"


def _folder_name(text: str) -> str:
    """Return ``text`` as a safe folder name (node ids hold ``/``, ``::`` and brackets)."""
    return re.sub(r"[^\w.-]+", "_", text).strip("_")[-150:] or "_"


def _current_test() -> str:
    """Return the running test's node id as a folder name (``outside-pytest`` outside)."""
    return _folder_name(os.environ.get("PYTEST_CURRENT_TEST", "outside-pytest")
                        .rsplit(" (", 1)[0])


def _new_folder(parent: Path, label: str) -> Path:
    """Return a folder ``parent/label`` not used before (``label-2``, ... after it)."""
    label = _folder_name(label)
    candidate, count = parent / label, 1
    while candidate.exists():
        count += 1
        candidate = parent / f"{label}-{count}"
    return candidate


def _as_image(value, role: str):
    from ..image import Image, read_exr

    if isinstance(value, Image):
        return value
    if isinstance(value, (str, os.PathLike)):
        return read_exr(value)
    if isinstance(value, (np.ndarray, list, tuple)):
        return Image(np.asarray(value, dtype=np.float32))
    raise TypeError(f"{role} must be a translucent Image, an H x W x 3 array or an OpenEXR "
                    f"path; got {type(value).__name__}")


def assert_image_close(test, reference, metric: str = "hdr_flip", max: float | None = None,
                       min: float | None = None, *, artifacts=None,
                       name: str | None = None) -> float:
    """Assert that ``test`` is within a metric's bound of ``reference``.

    Parameters
    ----------
    test, reference : Image, array_like (H, W, 3) or path
        The image judged and the reference (linear radiance; a reference's variance is
        discounted from relmse).
    metric : str
        A name of :data:`translucent.reports.metrics.table.METRICS` (hdr_flip, ldr_flip,
        relative_mse, relative_mse_raw, rmse, psnr, ssim, ciede2000) or an earlier spelling
        (flip, hdr-flip, relmse).
    max : float, optional
        Upper bound, for the error metrics.
    min : float, optional
        Lower bound, for psnr and ssim.
    artifacts : str or PathLike, optional
        Folder under which a failure's error maps go; default
        ``artifacts_root()/<test id>``.
    name : str, optional
        Name of the failure's sub-folder (default the metric's name).

    Returns
    -------
    float
        The metric's value (so a test can log it).

    Warns
    -----
    ReferenceNoiseWarning
        When the reference carries a variance and the bound is tighter than the metric's
        noise floor (:func:`~translucent.reports.metrics.noise_floor`): even a perfect
        image would score about the floor, so the check judges the reference's noise.

    Raises
    ------
    AssertionError
        When the value is beyond the bound (or NaN); the message gives the value, its noise
        floor and verdict where the reference has a variance, the bound and the folder
        holding the error maps.
    InputError
        Bad images (different sizes, NaN pixels, an unreadable file), an unknown metric or
        a bound that is not a finite number.
    TypeError
        A missing bound, or a bound on the wrong side for the metric.
    """
    __tracebackhide__ = True
    from .metrics.compute import error_scale, evaluate, noise_floor, noise_verdict
    from .metrics.table import metric as metric_definition

    definition = metric_definition(metric)
    bound_name, bound = ("max", max) if definition.lower_is_better else ("min", min)
    other = min if definition.lower_is_better else max
    if bound is None or other is not None:
        kind = "an error" if definition.lower_is_better else "a similarity"
        raise TypeError(f"assert_image_close(metric={definition.name!r}) needs {bound_name}= "
                        f"and only that bound ({definition.name} is {kind})")
    if isinstance(bound, bool) or not isinstance(bound, (int, float, np.integer, np.floating)) \
            or not np.isfinite(bound):
        from ..errors import InputError

        raise InputError("must be a finite number", field=bound_name, value=bound)
    test_image, reference_image = _as_image(test, "test"), _as_image(reference, "reference")
    comparison = evaluate(reference_image, test_image)
    value = getattr(comparison.metrics, definition.field)
    floor = noise_floor(reference_image)
    noise_text = ""
    if floor is not None:
        floor_value = getattr(floor, definition.field)
        verdict = noise_verdict(definition.field, value, floor_value)
        noise_text = f" (noise floor {floor_value:.4g}: {verdict})"
        if error_scale(definition.field, bound) < error_scale(definition.field, floor_value):
            warnings.warn(ReferenceNoiseWarning(
                f"{definition.name} bound {bound:g} is tighter than the reference's noise "
                f"floor {floor_value:.4g}: a perfect image would miss it; render the "
                "reference with more passes"), stacklevel=2)
    if definition.within(value, bound):
        return value
    from .metrics.maps import write_error_maps

    parent = Path(artifacts) if artifacts is not None else artifacts_root() / _current_test()
    folder = _new_folder(parent, name or definition.name)
    write_error_maps(reference_image, test_image, folder, comparison=comparison)
    relation = "above the maximum" if definition.lower_is_better else "below the minimum"
    raise AssertionError(f"{definition.name} = {value:.6g}{noise_text}, {relation} {bound:g} "
                         f"({test_image.shape[1]} x {test_image.shape[0]} pixels); "
                         f"error maps in {folder}")


def assert_render_consistent(test, reference_mean, reference_variance=None,
                             spp: int | None = None,
                             *, significance: float | None = None,
                             required_fraction: float | None = None, artifacts=None,
                             name: str | None = None):
    """Assert that a Monte Carlo render is consistent with a reference mean and variance.

    Mitsuba 3's per-pixel z-test with Šidák correction
    (:func:`translucent.reports.metrics.statistics.z_test`).

    Parameters
    ----------
    test : Image, array_like (H, W, 3) or path
        The render judged: a mean of ``spp`` samples per pixel.
    reference_mean : Image, array_like or path
        The converged reference.
    reference_variance : Image, array_like or path, optional
        The reference's per-sample variance (radiance squared), not the variance of its
        mean; the reference is then taken as converged (Mitsuba's test). Default: from
        ``reference_mean`` itself, a reference written by the suite (``translucent
        render``, a committed reference): its stored variance of the mean times its
        samples per pixel (``spp x passes`` of its metadata), and its own noise counts
        too (Student's t over its passes: :func:`translucent.reports.metrics.statistics.z_test`,
        each pixel's variance pooled over its 3 x 3 neighbourhood), so that an honest
        render is not failed for the reference's noise; and the image's 8 x 8 pixel
        block means must agree as well
        (:func:`~translucent.reports.metrics.statistics.z_test_blocks`), which a render too
        bright or too dark as a whole cannot pass.
    spp : int, optional
        Samples per pixel of ``test``; default ``test.metadata["spp"]``.
    significance, required_fraction : float, optional
        Override the z-test's 0.01 and 0.9975.
    artifacts : str or PathLike, optional
        Folder under which a failure's images go; default ``artifacts_root()/<test id>``.
    name : str, optional
        Name of the failure's sub-folder (default ``z-test``).

    Returns
    -------
    ZTestResult
        The test's outcome (when it passed).

    Raises
    ------
    AssertionError
        When fewer pixel channels than required are accepted, or a block mean is
        rejected; the message gives the fraction, alpha and the folder holding the
        p-value image.
    """
    __tracebackhide__ = True
    from .metrics.statistics import TEST_BLOCK, z_test, z_test_blocks

    test_image = _as_image(test, "test")
    if spp is None:
        spp = test_image.metadata.get("spp")
        if spp is None:
            raise TypeError("assert_render_consistent needs spp= (the test image's "
                            "metadata has no 'spp')")
    reference_image = _as_image(reference_mean, "reference_mean")
    per_sample = _per_sample_variance(reference_image, reference_variance)
    options = {key: value for key, value in (("significance", significance),
                                             ("required_fraction", required_fraction))
               if value is not None}
    if reference_variance is None:  # the reference's own noise, from its passes, counts
        passes = reference_image.metadata["passes"]
        options.update(reference_samples=reference_image.metadata["spp"] * passes,
                       reference_passes=passes)
        if passes < RECOMMENDED_REFERENCE_PASSES:
            from scipy.stats import t

            from .metrics.statistics import sidak_alpha

            pixels = reference_image.shape[0] * reference_image.shape[1]
            bound = t.isf(sidak_alpha(pixels) / 2, passes - 1)
            warnings.warn(ReferenceNoiseWarning(
                f"a reference of {passes} passes: its variance is known so roughly that "
                f"only differences beyond {bound:.3g} standard errors can fail the test; "
                f"render it with at least {RECOMMENDED_REFERENCE_PASSES} passes"),
                stacklevel=2)
    result = z_test(test_image.rgb, reference_image.rgb, per_sample, spp, **options)
    blocks = None
    if reference_variance is None:
        blocks = z_test_blocks(test_image.rgb, reference_image.rgb, per_sample, spp,
                               reference_samples=options["reference_samples"],
                               reference_passes=options["reference_passes"],
                               **({"significance": significance} if significance else {}))
    if result.passed and (blocks is None or blocks.passed):
        return result
    from .metrics.maps import write_z_test_maps

    parent = Path(artifacts) if artifacts is not None else artifacts_root() / _current_test()
    folder = _new_folder(parent, name or "z-test")
    write_z_test_maps(result, folder, test=test_image, reference=reference_image)
    summary = result.summary()
    if blocks is not None:
        summary += f"; {TEST_BLOCK} x {TEST_BLOCK} pixel blocks: {blocks.summary()}"
    raise AssertionError(f"{summary}; p-value image and maps in {folder}")


def _per_sample_variance(reference, reference_variance) -> np.ndarray:
    """Return the reference's per-sample variance: given, or from its stored variance."""
    from ..errors import InputError

    if reference_variance is None:
        samples = (reference.metadata.get("spp"), reference.metadata.get("passes"))
        if reference.variance is None or not all(isinstance(n, int) and n > 0
                                                 for n in samples):
            raise InputError("give reference_variance (the per-sample variance), or a "
                             "reference whose file holds its variance of the mean and its "
                             "spp and passes (as translucent render writes it)",
                             field="reference_variance", value=None)
        return reference.variance.astype(np.float64) * samples[0] * samples[1]
    if reference_variance is reference or (
            isinstance(reference_variance, np.ndarray)
            and np.shares_memory(reference_variance, reference.rgb)):
        raise InputError("is the reference image itself, not a variance",
                         field="reference_variance", value="the reference")
    variance = _as_image(reference_variance, "reference_variance")
    if variance.variance is not None or variance.metadata.get("producer") == "reference":
        # a reference EXR holds radiance in R, G, B: taken as a variance, every test passes
        raise InputError("is a reference image (radiance, with variance channels of its "
                         "own), not a per-sample variance; pass the reference as "
                         "reference_mean and leave reference_variance out to use its "
                         "stored variance", field="reference_variance",
                         value=variance.metadata.get("scene", "an image"))
    if np.array_equal(variance.rgb, reference.rgb):
        raise InputError("equals the reference's radiance, not a variance",
                         field="reference_variance", value="the reference's pixels")
    return variance.rgb


class ImageChecks:
    """The assertions, filing a test's artifacts under its own folder (fixture ``image_checks``).

    Parameters
    ----------
    artifacts : Path
        This test's folder (created only when a check fails).
    """

    def __init__(self, artifacts: Path):
        self.artifacts = Path(artifacts)

    def assert_image_close(self, test, reference, metric: str = "hdr_flip",
                           max: float | None = None, min: float | None = None, *,
                           name: str | None = None) -> float:
        """Run :func:`assert_image_close` with this test's artifacts folder."""
        __tracebackhide__ = True
        return assert_image_close(test, reference, metric, max, min, artifacts=self.artifacts,
                                  name=name)

    def assert_render_consistent(self, test, reference_mean, reference_variance=None,
                                 spp: int | None = None, *, name: str | None = None, **options):
        """Run :func:`assert_render_consistent` with this test's artifacts folder."""
        __tracebackhide__ = True
        return assert_render_consistent(test, reference_mean, reference_variance, spp,
                                        artifacts=self.artifacts, name=name, **options)


@pytest.fixture
def image_checks(request) -> ImageChecks:
    """Image assertions whose failures leave their maps under this test's folder."""
    return ImageChecks(artifacts_root(request.config) / _folder_name(request.node.nodeid))


@pytest.fixture
def reference_image(request):
    """Return ``get(path, producer) -> Image``: the stored reference, regenerated when asked.

    ``producer()`` returns an Image or an ``H x W x 3`` array; it is called, and its result
    written to ``path`` atomically, when the file is missing or ``--translucent-regenerate``
    is given. Relative paths are taken from the test file's folder.
    """
    from ..image import read_exr

    regenerate = request.config.getoption("translucent_regenerate", default=False)
    base = Path(request.node.path).parent

    def get(path, producer):
        path = Path(path)
        path = path if path.is_absolute() else base / path
        if regenerate or not path.exists():
            image = _as_image(producer(), "producer()")
            image.write(path)
            request.config.stash[_REGENERATED].append(path)
            return image
        return read_exr(path)

    return get
