"""The learned path of issue 11 (DeepSpline, section 5): networks predicting a profile.

A PointNet (clouds) or a small CNN (silhouettes) predicts the profile's control points in
a canonical frame; the exact surface is generated from them by a fixed linear layer
extracted from the core's constructors; training minimises the Chamfer distance to the
input with no ground truth (``nurbskit train revolve``). :func:`initial_guess` turns a
world cloud into the start of the geometric refinement (``fit_shape(init="network")``).
See ``docs/shapes_nets.md``.
"""

from .data import KINDS, N_CTRL, SurfaceLayer, make_batch, normalise, random_profiles, sample_clouds, silhouettes
from .guess import guess_surface, initial_guess, load_model, plane_basis
from .models import PointNetEncoder, ProfileNet, SilhouetteCNN, build_model

__all__ = ["KINDS", "N_CTRL", "SurfaceLayer", "make_batch", "normalise", "random_profiles", "sample_clouds",
           "silhouettes", "initial_guess", "guess_surface", "load_model", "plane_basis", "PointNetEncoder", "ProfileNet", "SilhouetteCNN", "build_model"]
