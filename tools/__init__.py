"""Tools: coefficient generators, calibration and checks, ``python -m tools.NAME`` (README.md)."""
