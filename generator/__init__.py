"""surfgen.generator: formulas, constituent functions, equation (13), evaluation and meshing.

This package imports nothing from ``surfgen.filters`` or ``surfgen.pipelines``.
"""

__version__ = "0.1.0"
