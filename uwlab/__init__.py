"""uwlab: design, calibration and validation of underwater camera systems."""

__version__ = "0.1.0"
