"""TWISTED: knot tying with knot-theory planning and a learned inverse model."""

__version__ = "0.1.0"
