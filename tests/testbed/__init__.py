"""Test beds: systems written apart from the package, for blind tests and benchmarks."""
