"""Timing scripts, each run as `python -m benchmarks.<name>` (`--smoke`: tiny sizes)."""
