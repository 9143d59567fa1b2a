"""The Dr.Jit backend of splatting: one fused kernel per bucket of samples (LLVM or CUDA)."""

from __future__ import annotations

import functools

import numpy as np

from ...errors import InputError

__all__ = ["DrJitKernel"]


@functools.lru_cache(maxsize=1)
def _jit():
    """Dr.Jit and its array types: CUDA where a GPU is usable, else LLVM (libLLVM set up first)."""
    from ...backend import configure_libllvm

    configure_libllvm()
    import drjit as dr

    if dr.has_backend(dr.JitBackend.CUDA):
        import drjit.cuda as types
    elif dr.has_backend(dr.JitBackend.LLVM):
        import drjit.llvm as types
    else:
        raise InputError("Dr.Jit has neither a CUDA nor an LLVM backend here; use "
                         "backend = \"numpy\"", field="backend", value="drjit")
    return dr, types


class DrJitKernel:
    """The Dr.Jit kernel of :func:`splat_level`: one fused kernel per bucket of samples.

    Each pair (sample, offset) is one lane: gather the pixel's surface point and texel,
    test the distance against :math:`[R^k_{min}, R^k_{max})`, evaluate Eq. 8-9 and
    scatter-add into the exitance (float32 on the device, LLVM on the CPU or CUDA).
    Sizes enter as opaque values so that a kernel compiles once per material layout.
    """

    def __init__(self, samples, bounds_low, bounds_high, level, level_texel, material,
                 mm_per_unit, scale):
        dr, t = _jit()
        self.dr, self.t = dr, t
        self.height, self.width = level.shape
        valid = level.valid.reshape(-1)
        texel = np.where(valid, level_texel.reshape(-1), -1).astype(np.int32)
        position = level.position.reshape(-1, 3).astype(np.float32)
        self.pixel_position = [t.Float(np.ascontiguousarray(position[:, c])) for c in range(3)]
        self.texel_out = t.Int32(texel)
        self.table = t.Float(np.ascontiguousarray(material.flat_log_profile, np.float32)
                             .reshape(-1))
        self.segments = material.segments
        self.step_inverse = material.segments / (material.r_s / mm_per_unit)
        sample_position = samples.position.astype(np.float32)
        self.sample_position = [t.Float(np.ascontiguousarray(sample_position[:, c]))
                                for c in range(3)]
        flux = (samples.flux * scale).astype(np.float32)
        self.flux = [t.Float(np.ascontiguousarray(flux[:, c])) for c in range(3)]
        self.texel_in = t.Int32(samples.texel.astype(np.int32))
        self.low = t.Float(bounds_low.astype(np.float32))
        self.high = t.Float(bounds_high.astype(np.float32))
        self.exitance = [dr.zeros(t.Float, self.height * self.width) for _ in range(3)]

    def splat(self, index, column, row, dx, dy):
        """Splat samples ``index`` centred on pixels (column, row) over offsets (dx, dy)."""
        lanes = len(index) * len(dx)
        for start in range(0, lanes, 1 << 30):  # lane indices stay within UInt32
            self._launch(index, column, row, dx, dy, start, min(lanes, start + (1 << 30)))

    def _launch(self, index, column, row, dx, dy, start, stop):
        dr, t = self.dr, self.t
        count = dr.opaque(t.UInt32, len(dx))
        lane = dr.arange(t.UInt32, stop - start) + dr.opaque(t.UInt32, start)
        local = lane // count
        offset = lane - local * count
        sample = dr.gather(t.UInt32, t.UInt32(index.astype(np.uint32)), local)
        x = dr.gather(t.Int32, t.Int32(column.astype(np.int32)), local) + \
            dr.gather(t.Int32, t.Int32(dx.astype(np.int32)), offset)
        y = dr.gather(t.Int32, t.Int32(row.astype(np.int32)), local) + \
            dr.gather(t.Int32, t.Int32(dy.astype(np.int32)), offset)
        width = dr.opaque(t.Int32, self.width)
        active = (x >= 0) & (x < width) & (y >= 0) & (y < dr.opaque(t.Int32, self.height))
        pixel = t.UInt32(dr.select(active, y * width + x, 0))
        texel_out = dr.gather(t.Int32, self.texel_out, pixel, active)
        active &= texel_out >= 0
        squared = t.Float(0.0)
        for c in range(3):
            difference = dr.gather(t.Float, self.pixel_position[c], pixel, active) - \
                dr.gather(t.Float, self.sample_position[c], sample, active)
            squared = dr.fma(difference, difference, squared)
        distance = dr.sqrt(squared)
        active &= (distance >= dr.gather(t.Float, self.low, sample, active)) & \
            (distance < dr.gather(t.Float, self.high, sample, active))
        position = distance * dr.opaque(t.Float, self.step_inverse)
        segments = dr.opaque(t.Int32, self.segments)
        active &= position < t.Float(segments)
        k = dr.minimum(t.Int32(position), segments - 1)
        weight = position - t.Float(k)
        stride = (segments + 1) * 3
        texel_in = dr.gather(t.Int32, self.texel_in, sample, active)
        base_in = t.UInt32(texel_in * stride + k * 3)
        base_out = t.UInt32(texel_out * stride + k * 3)
        for c in range(3):
            first = dr.gather(t.Float, self.table, base_in + c, active) + \
                dr.gather(t.Float, self.table, base_out + c, active)
            second = dr.gather(t.Float, self.table, base_in + 3 + c, active) + \
                dr.gather(t.Float, self.table, base_out + 3 + c, active)
            value = dr.exp(0.5 * dr.fma(weight, second - first, first)) * \
                dr.gather(t.Float, self.flux[c], sample, active)
            dr.scatter_reduce(dr.ReduceOp.Add, self.exitance[c], value, pixel, active)
        dr.eval(self.exitance)

    def result(self) -> np.ndarray:
        """Return the accumulated exitance, (H * W, 3), float64."""
        return np.stack([np.asarray(channel, dtype=np.float64) for channel in self.exitance],
                        axis=-1)


