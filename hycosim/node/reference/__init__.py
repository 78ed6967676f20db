"""Small reference nodes for tests, examples and benchmarks."""
