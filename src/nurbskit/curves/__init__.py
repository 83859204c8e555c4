"""Spline curves from images (DeepSpline, 2D): synthetic drawings and classical fitting."""
