"""Benchmarks: `python -m bench.<name>`; outputs go to bench/out (git-ignored)."""
