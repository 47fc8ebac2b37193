"""pimann: physics-informed MANN trajectory generation for ergoCub (D'Elia et al., IROS 2025).

The stages are its subpackages (README: layout).
"""

__version__ = "0.1.0"
