"""The brute-force exitance every splatting setting is checked against."""

from __future__ import annotations

import numpy as np

from ...materials.subedit import SubEditProfiles
from .buffers import SurfaceBuffer
from .knobs import PAIR_CHUNK
from .selection import IrradianceSamples
from .splats import evaluate_pairs, subedit_segment_table


def brute_force_exitance(samples: IrradianceSamples, buffer: SurfaceBuffer,
                         material: SubEditProfiles, *, mm_per_unit: float,
                         backend: str = "numba") -> np.ndarray:
    r"""Eq. 5 of Chen et al. 2012 by brute force: every sample to every valid pixel.

    :math:`B(x_o) = \sum_{x_i} \sqrt{P_{x_i}(r)P_{x_o}(r)}E(x_i)\Delta A_{x_i}` over all
    given samples (the finest level, unselected, for the ground truth) with the profile's
    full support :math:`r < r_s`. Cost: pixels x samples.

    Returns
    -------
    ndarray (H, W, 3)
    """
    height, width = buffer.shape
    exitance = np.zeros((height * width, 3))
    pixels = np.flatnonzero(buffer.valid.reshape(-1))
    if not len(pixels) or not len(samples):
        return exitance.reshape(height, width, 3)
    position = buffer.position.reshape(-1, 3)[pixels]
    texel_out = material.texel_index(buffer.uv.reshape(-1, 2)[pixels])
    if backend in ("numba", "cuda"):
        if backend == "cuda":
            from .backend_cuda import gather_samples
        else:
            from .backend_numba import gather_samples

        gathered = np.zeros((len(pixels), 3))
        gather_samples(gathered, np.ascontiguousarray(position.T, dtype=np.float32),
                       texel_out.astype(np.int32), subedit_segment_table(material),
                       np.float32(material.segments / (material.r_s / mm_per_unit)),
                       np.ascontiguousarray(samples.position.T, dtype=np.float32),
                       samples.texel.astype(np.int32),
                       np.ascontiguousarray(samples.flux.T, dtype=np.float32))
        exitance[pixels] = gathered * mm_per_unit**2
        return exitance.reshape(height, width, 3)
    table = material.flat_log_profile.astype(np.float32)
    step_inverse = material.segments / (material.r_s / mm_per_unit)
    per_chunk = max(1, PAIR_CHUNK // len(samples))
    for start in range(0, len(pixels), per_chunk):
        part = slice(start, start + per_chunk)
        offset = position[part][:, None, :] - samples.position[None, :, :]
        distance = np.sqrt(np.einsum("ijk,ijk->ij", offset, offset)).reshape(-1)
        texel_o = np.repeat(texel_out[part], len(samples))
        texel_i = np.tile(samples.texel, len(position[part]))
        value = evaluate_pairs(table, step_inverse, material.segments, distance, texel_i,
                                texel_o)
        value = value.reshape(-1, len(samples), 3) * samples.flux[None, :, :]
        exitance[pixels[part]] = value.sum(axis=1) * mm_per_unit**2
    return exitance.reshape(height, width, 3)


