"""Benchmarks, one module each (``translucent bench <module>``)."""
