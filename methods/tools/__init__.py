"""Helpers around the methods: synthetic depth for tests and benchmarks, the default-parameter sweep."""
