"""Tools on top of the public API: demo, benchmarks, evaluations, soak and load tests."""
