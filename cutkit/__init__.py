"""cutkit: tetrahedral soft-tissue models from medical volumes, cut with a virtual scalpel.

The method follows Bielser & Gross, *Interactive Simulation of Surgical Cuts* (2000).
"""

__version__ = "0.2.0"

__all__ = ["__version__"]
