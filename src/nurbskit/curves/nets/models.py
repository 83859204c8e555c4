"""The three DeepSpline networks (seed 002, section 4), sized for a CPU.

* :class:`Encoder`: a small CNN of our own (no pretrained weights exist offline): the ink
  image ``(B, 1, S, S)`` with two coordinate channels (CoordConv: positions are what the
  decoders regress) through four 3 x 3 convolutions, the first three of stride 2, to a feature map
  ``(B, D, S/8, S/8)``; its cells are the tokens the attention reads, each with its
  centre's coordinates appended.
* :class:`PointModel` (V): one curve; a point GRU emits a control point and a stop
  probability per step (paper 4.1). Unlike the paper, which feeds a mean-pooled feature,
  every step reads the feature map through attention (paper 4.2.2), which a small CNN
  needs to localise points.
* :class:`MultiCurveModel` (M): a curve GRU with attention emits a whole curve (a fixed
  number of control points) and a curve-stop probability per step (paper 4.2); predicted
  curves are matched to the true ones by the Hungarian algorithm in the loss.
* :class:`HierarchicalModel` (MV): a curve GRU with attention emits a curve code and a
  curve-stop probability; a point GRU decodes each code into control points with a
  point-stop probability (paper 4.3).

Convention: control points live in the unit square, ``(x / W, y / H)`` in the pixel
convention of :mod:`nurbskit.curves.api`; stop logits are two classes
``{CONTINUE = 0, STOP = 1}``; the recurrences feed their own (detached) previous point
back, in training as at inference, so training sees what inference sees.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn
from torch.nn import functional as F

# The largest numbers a decoder emits at inference (training runs the targets' numbers).
MAX_CURVES = 5
MAX_POINTS = 8
MIN_POINTS = 4  # a cubic needs 4 control points: a stop before that is not taken


def _mlp(i: int, h: int, o: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(i, h), nn.ReLU(), nn.Linear(h, o))


class Encoder(nn.Module):
    """Ink image ``(B, 1, S, S)`` -> tokens ``(B, L, D)`` (``L = (S/8)^2``) and a global vector ``(B, D)``."""

    def __init__(self, width: int = 32, dim: int = 96):
        super().__init__()
        c = width
        self.convs = nn.Sequential(
            nn.Conv2d(3, c // 2, 3, stride=2, padding=1), nn.ReLU(),
            nn.Conv2d(c // 2, c, 3, stride=2, padding=1), nn.GroupNorm(4, c), nn.ReLU(),
            nn.Conv2d(c, 2 * c, 3, stride=2, padding=1), nn.GroupNorm(4, 2 * c), nn.ReLU(),
            nn.Conv2d(2 * c, 2 * c, 3, padding=1), nn.ReLU(),
        )
        self.token = nn.Linear(2 * c + 2, dim)
        self.dim = dim

    @staticmethod
    def _grid(n: int, batch: int, like: Tensor) -> Tensor:
        t = (torch.arange(n, dtype=like.dtype, device=like.device) + 0.5) / n
        y, x = torch.meshgrid(t, t, indexing="ij")
        return torch.stack([x, y]).expand(batch, 2, n, n)

    def forward(self, ink: Tensor) -> tuple[Tensor, Tensor]:
        b, _, s, _ = ink.shape
        fmap = self.convs(torch.cat([ink, self._grid(s, b, ink)], 1))  # (B, C, S/8, S/8)
        n = fmap.shape[-1]
        cells = torch.cat([fmap, self._grid(n, b, fmap)], 1).flatten(2).transpose(1, 2)  # (B, L, C + 2)
        tokens = F.relu(self.token(cells))
        return tokens, tokens.mean(1)


def pointed(where: Tensor, offset: Tensor) -> Tensor:
    """A point where an attention head looks plus an offset of at most half the image, in the unit square."""
    return (where + 0.5 * torch.tanh(offset)).clamp(0, 1)


class PointingHeads:
    """Several attention heads read a feature map in one step (M's curve step, MV's sketch).

    A mixin: :meth:`_add_heads` gives the model ``keys``, ``query``, ``score`` and ``mix``
    (the parameter names of the shipped weights); :meth:`_read_heads` scores every cell
    against the GRU state for each head and returns the heads' mixed context ``(B, D)``
    and where each head looks ``(B, S, 2)``.
    """

    def _add_heads(self, dim: int, hidden: int, heads: int) -> None:
        self.keys = nn.Linear(dim, 64)
        self.query = nn.Linear(hidden, 64, bias=False)
        self.score = nn.Linear(64, heads)
        self.mix = nn.Linear(heads * dim, dim)

    def _read_heads(self, keys: Tensor, h: Tensor, tokens: Tensor, centres: Tensor) -> tuple[Tensor, Tensor]:
        a = self.score(F.relu(keys + self.query(h)[:, None])).softmax(1)  # (B, L, S)
        ctx = F.relu(self.mix(torch.einsum("bls,bld->bsd", a, tokens).flatten(1)))
        return ctx, torch.einsum("bls,lc->bsc", a, centres)


def token_centres(tokens: Tensor) -> Tensor:
    """The centres ``(L, 2)`` in the unit square of the cells of a square feature map's tokens ``(B, L, D)``."""
    n = int(round(tokens.shape[1] ** 0.5))
    return Encoder._grid(n, 1, tokens)[0].flatten(1).T


class Attention(nn.Module):
    """Soft attention (paper eq. 11-14): weight ``a_i = softmax_i f([v_i, h])``, ``f`` a 2-layer ReLU MLP.

    ``tokens (B, L, D)``, ``h (B, H)`` -> context ``(B, D)``.
    """

    def __init__(self, dim: int, hidden: int, inner: int = 64):
        super().__init__()
        self.v = nn.Linear(dim, inner)
        self.h = nn.Linear(hidden, inner, bias=False)
        self.out = nn.Linear(inner, 1)

    def forward(self, tokens: Tensor, h: Tensor, keys: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """-> context ``(B, D)``, weights ``(B, L)``."""
        keys = self.v(tokens) if keys is None else keys
        weights = self.out(F.relu(keys + self.h(h)[:, None])).squeeze(-1).softmax(-1)  # (B, L)
        return torch.einsum("bl,bld->bd", weights, tokens), weights


class PointDecoder(nn.Module):
    """A point GRU: from a start state, control points ``(B, T, 2)`` and stop logits ``(B, T, 2)``."""

    def __init__(self, dim: int, hidden: int, code: int = 0, pointer: bool = True):
        super().__init__()
        self.pointer = pointer
        self.attend = Attention(dim, hidden)
        self.cell = nn.GRUCell(dim + code + 3, hidden)
        self.head = _mlp(hidden + dim, hidden, 4)

    def forward(self, tokens: Tensor, h: Tensor, steps: int, code: Tensor | None = None) -> tuple[Tensor, Tensor]:
        b = tokens.shape[0]
        centres = token_centres(tokens)
        keys = self.attend.v(tokens)
        prev = tokens.new_zeros(b, 3)
        prev[:, 2] = 1.0  # the start flag
        points, stops = [], []
        for _ in range(steps):
            ctx, a = self.attend(tokens, h, keys)
            x = torch.cat([ctx, prev] if code is None else [ctx, code, prev], 1)
            h = self.cell(x, h)
            out = self.head(torch.cat([h, ctx], 1))
            if self.pointer:  # where the attention looks, plus an offset: a strong prior for points near ink
                p = pointed(torch.einsum("bl,lc->bc", a, centres), out[:, :2])
            else:
                p = torch.sigmoid(out[:, :2])
            points.append(p)
            stops.append(out[:, 2:])
            prev = torch.cat([p.detach(), p.new_zeros(b, 1)], 1)
        return torch.stack(points, 1), torch.stack(stops, 1)


class PointModel(nn.Module):
    """V: one curve, a variable number of control points (paper 4.1).

    ``forward(ink (B, 1, S, S), steps) -> (points (B, steps, 2), stop logits (B, steps, 2))``.
    """

    mode = "V"

    def __init__(self, width: int = 32, dim: int = 96, hidden: int = 128, pointer: bool = True):
        super().__init__()
        self.encoder = Encoder(width, dim)
        self.init = nn.Linear(dim, hidden)
        self.points = PointDecoder(dim, hidden, pointer=pointer)

    def forward(self, ink: Tensor, steps: int) -> tuple[Tensor, Tensor]:
        tokens, g = self.encoder(ink)
        return self.points(tokens, torch.tanh(self.init(g)), steps)


class MultiCurveModel(PointingHeads, nn.Module):
    """M: several curves of ``n_points`` control points each (paper 4.2).

    Each curve step reads the feature map through ``n_points`` attention heads, one per
    control point; a point is where its head looks plus an offset (as in the point decoder).
    ``forward(ink, curves) -> (points (B, curves, n_points, 2), curve-stop logits (B, curves, 2))``.
    """

    mode = "M"

    def __init__(self, width: int = 32, dim: int = 96, hidden: int = 128, n_points: int = 5):
        super().__init__()
        self.n_points = n_points
        self.encoder = Encoder(width, dim)
        self.init = nn.Linear(dim, hidden)
        self._add_heads(dim, hidden, n_points)
        self.cell = nn.GRUCell(dim + 2 * n_points, hidden)
        self.head = _mlp(hidden + dim, hidden, 2 * n_points + 2)

    def forward(self, ink: Tensor, curves: int) -> tuple[Tensor, Tensor]:
        tokens, g = self.encoder(ink)
        b = ink.shape[0]
        centres = token_centres(tokens)
        h = torch.tanh(self.init(g))
        keys = self.keys(tokens)
        prev = tokens.new_zeros(b, 2 * self.n_points)
        points, stops = [], []
        for _ in range(curves):
            ctx, where = self._read_heads(keys, h, tokens, centres)
            h = self.cell(torch.cat([ctx, prev], 1), h)
            out = self.head(torch.cat([h, ctx], 1))
            p = pointed(where, out[:, : 2 * self.n_points].view(b, self.n_points, 2))
            points.append(p)
            stops.append(out[:, 2 * self.n_points:])
            prev = p.detach().flatten(1)
        return torch.stack(points, 1), torch.stack(stops, 1)


class HierarchicalModel(PointingHeads, nn.Module):
    """MV: several curves, each with a variable number of control points (paper 4.3).

    ``forward(ink, curves, points) -> (points (B, curves, points, 2), point-stop logits
    (B, curves, points, 2), curve-stop logits (B, curves, 2))``: every curve is decoded for
    ``points`` steps (the loss reads the steps its matched target has).

    ``sketch = S > 0`` (beyond the paper; the default 0 is the paper's model, and a weights
    file records its own in ``meta["arch"]``): each curve step reads the feature map
    through ``S`` attention heads that place a sketch of the curve (:meth:`curve_codes`).
    """

    mode = "MV"

    def __init__(self, width: int = 32, dim: int = 96, hidden: int = 128, code: int = 64, sketch: int = 0):
        super().__init__()
        self.encoder = Encoder(width, dim)
        self.init = nn.Linear(dim, hidden)
        self.code, self.sketch = code, sketch
        full = code + 2 * sketch  # what a curve hands its point decoder: the code and the sketch
        if sketch:
            self._add_heads(dim, hidden, sketch)
        else:
            self.attend = Attention(dim, hidden)
        self.cell = nn.GRUCell(dim + full, hidden)
        self.head = _mlp(hidden + (dim if sketch else 0), hidden, full + 2)
        self.point_init = nn.Linear(full, hidden)
        self.points = PointDecoder(dim, hidden, full)

    def curve_codes(self, ink: Tensor, curves: int) -> tuple[Tensor, Tensor, Tensor]:
        """Tokens ``(B, L, D)``, curve codes ``(B, curves, code + 2 sketch)``, curve-stop logits ``(B, curves, 2)``.

        With ``sketch = S > 0`` a curve step reads the feature map through ``S`` attention
        heads, as M's does, and each head places one point of a sketch of the curve (where it
        looks plus an offset): the curve at ``S`` evenly spaced parameters, which the loss
        supervises (:func:`sketch_targets`). The sketch rides in the code's last ``2 S``
        numbers (:meth:`sketch_points`), and the previous curve's sketch is fed back, as M
        feeds back its previous curve.
        """
        tokens, g = self.encoder(ink)
        b = ink.shape[0]
        h = torch.tanh(self.init(g))
        if self.sketch:
            keys, centres = self.keys(tokens), token_centres(tokens)
        else:
            keys = self.attend.v(tokens)
        prev = tokens.new_zeros(b, self.code + 2 * self.sketch)
        codes, stops = [], []
        for _ in range(curves):
            if self.sketch:
                ctx, where = self._read_heads(keys, h, tokens, centres)
                h = self.cell(torch.cat([ctx, prev], 1), h)
                out = self.head(torch.cat([h, ctx], 1))
                sketch = pointed(where, out[:, self.code: self.code + 2 * self.sketch].view(b, self.sketch, 2))
                z = torch.cat([torch.tanh(out[:, : self.code]), sketch.flatten(1)], 1)
                prev = torch.cat([z[:, : self.code], sketch.detach().flatten(1)], 1)
            else:
                h = self.cell(torch.cat([self.attend(tokens, h, keys)[0], prev], 1), h)
                out = self.head(h)
                z = prev = torch.tanh(out[:, : self.code])
            codes.append(z)
            stops.append(out[:, -2:])
        return tokens, torch.stack(codes, 1), torch.stack(stops, 1)

    def sketch_points(self, codes: Tensor) -> Tensor | None:
        """Codes ``(..., code + 2 S)`` -> the sketches ``(..., S, 2)`` in the unit square (None when ``S = 0``)."""
        return codes[..., self.code:].unflatten(-1, (self.sketch, 2)) if self.sketch else None

    def decode_points(self, tokens: Tensor, codes: Tensor, steps: int) -> tuple[Tensor, Tensor]:
        """Codes ``(B, K, code + 2 sketch)`` -> points and stop logits, each ``(B, K, steps, 2)`` (curves batched)."""
        b, k, _ = codes.shape
        flat = codes.reshape(b * k, -1)
        tok = tokens[:, None].expand(-1, k, -1, -1).reshape(b * k, *tokens.shape[1:])
        p, s = self.points(tok, torch.tanh(self.point_init(flat)), steps, flat)
        return p.view(b, k, steps, 2), s.view(b, k, steps, 2)

    def forward(self, ink: Tensor, curves: int, points: int) -> tuple[Tensor, Tensor, Tensor]:
        tokens, codes, curve_stops = self.curve_codes(ink, curves)
        p, s = self.decode_points(tokens, codes, points)
        return p, s, curve_stops


MODELS = {"V": PointModel, "M": MultiCurveModel, "MV": HierarchicalModel}


def build(mode: str, arch: dict | None = None) -> nn.Module:
    """The network of ``mode`` with architecture arguments ``arch`` (those a weights file records)."""
    return MODELS[mode](**(arch or {}))
