"""Metrics, error maps, benchmarks, stress runs, the HTML report and the command line."""
