"""Benchmarks of translucent for airspeed velocity (asv): see docs/history.md."""
