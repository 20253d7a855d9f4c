"""wavestack: a Python driver stack for live wavefront metrology."""

__version__ = "0.1.0"
