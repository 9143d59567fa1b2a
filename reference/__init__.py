"""Ground truth: Mitsuba 3 volumetric path tracing and exact-BRDF reference renders."""
