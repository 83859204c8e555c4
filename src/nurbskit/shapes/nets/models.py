"""The encoders of the learned path: PointNet for clouds, a small CNN for silhouettes.

Both end in the paper's two-layer fully connected head (DeepSpline, section 5.1, eq. 18)
predicting the profile's control points in the canonical frame (:mod:`.data`), and both
feed :class:`~.data.SurfaceLayer`, the fixed linear layer that turns them into points of
the exact surface (eq. 19).

* :class:`PointNetEncoder`: Qi et al., "PointNet" (CVPR 2017), without the transform
  nets: a shared per-point MLP (1x1 convolutions) then a max pool over the points, so the
  prediction does not depend on the points' order or count.
* :class:`SilhouetteCNN`: four stride-2 3x3 convolutions (64 -> 4 pixels) then the head;
  a small stand-in for the paper's VGG features, sized for a CPU.

Convention: outputs are ``(B, n_outputs(kind))``; for a revolution the radii pass
through ``softplus`` (a radius is never negative), every other coordinate is linear.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from .data import N_CTRL, RES, SurfaceLayer, n_outputs

__all__ = ["PointNetEncoder", "SilhouetteCNN", "ProfileNet", "build_model"]


class PointNetEncoder(nn.Module):
    """``points (B, N, 3)`` -> features ``(B, width[-1])``: shared MLP + max pool."""

    def __init__(self, widths=(64, 128, 256)):
        super().__init__()
        layers, c = [], 3
        for i, w in enumerate(widths):
            layers.append(nn.Conv1d(c, w, 1))
            if i < len(widths) - 1:
                layers.append(nn.ReLU())
            c = w
        self.mlp = nn.Sequential(*layers)
        self.features = c

    def forward(self, points: Tensor) -> Tensor:
        # the 1x1 convolutions applied as matrix products on the channel-last points: the same
        # weights and numbers (to float rounding), about 3x faster for a batch of small clouds
        # on one CPU thread (measured: 33 clouds of 167 points, 20 -> 6.5 ms), which the
        # direction search of :func:`~.guess.initial_guess` runs
        h = points
        for layer in self.mlp:
            h = nn.functional.linear(h, layer.weight[..., 0], layer.bias) if isinstance(layer, nn.Conv1d) else layer(h)
        return h.amax(-2)


class SilhouetteCNN(nn.Module):
    """``images (B, 1, RES, RES)`` -> features ``(B, 256)``."""

    def __init__(self, channels=(16, 32, 64, 128)):
        super().__init__()
        layers, c = [], 1
        for w in channels:
            layers += [nn.Conv2d(c, w, 3, stride=2, padding=1), nn.ReLU()]
            c = w
        side = RES // 2 ** len(channels)
        self.conv = nn.Sequential(*layers, nn.Flatten(), nn.Linear(c * side * side, 256))
        self.features = 256

    def forward(self, images: Tensor) -> Tensor:
        return self.conv(images)


class ProfileNet(nn.Module):
    """Encoder + two-layer head + the fixed surface layer.

    ``forward(x)`` returns the predicted coordinates ``(B, n_outputs)``;
    :meth:`surface_points` the generated surface's points ``(B, S, 3)``.
    """

    def __init__(self, kind: str, input: str, hidden: int = 256):
        super().__init__()
        self.kind, self.input = kind, input
        self.encoder = PointNetEncoder() if input == "points" else SilhouetteCNN()
        self.head = nn.Sequential(nn.Linear(self.encoder.features, hidden), nn.ReLU(),
                                  nn.Linear(hidden, n_outputs(kind)))
        self.surface = SurfaceLayer(kind)

    def forward(self, x: Tensor) -> Tensor:
        out = self.head(self.encoder(x))
        if self.kind == "revolution":
            prof = out.reshape(out.shape[0], N_CTRL, 2)
            out = torch.stack([nn.functional.softplus(prof[..., 0]), prof[..., 1]], -1).reshape(out.shape[0], -1)
        return out

    def surface_points(self, coords: Tensor) -> Tensor:
        return self.surface(coords)


def build_model(kind: str, input: str) -> ProfileNet:
    """The network for ``kind`` ('revolution' | 'extrusion') and ``input`` ('points' | 'image')."""
    return ProfileNet(kind, input)
