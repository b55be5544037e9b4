"""Bench: metrics, the runner (local or Dask), the leaderboard and report writers."""
from bench.errors import BenchError

__all__ = ["BenchError"]
