"""Benchmarks: ``python -m benchmarks.NAME`` from the checkout root (see README.md here)."""
