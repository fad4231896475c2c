"""physpose: physically plausible 3d human motion from monocular video."""

__version__ = "0.1.0"
