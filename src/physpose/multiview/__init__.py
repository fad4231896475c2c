"""Calibrated multi-view material: Qualisys calibration, triangulation, a 3d reference."""
