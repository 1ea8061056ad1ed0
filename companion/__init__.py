"""Vineyard GNC companion (after Mokrane et al., Sensors 2022)."""

__version__ = "0.1.0"
