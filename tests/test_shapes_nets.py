"""The learned path of issue 11 (nurbskit.shapes.nets): data, surface layer, encoders, training, guess."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import torch

from _assert import assert_close
from _cli import one_line, run
from nurbskit.core.basis import basis_matrix
from nurbskit.learn import TrainConfig, batch_generator, shipped_weights, train
from nurbskit.shapes.nets import (
    KINDS, N_CTRL, SurfaceLayer, build_model, guess_surface, initial_guess, make_batch, normalise, plane_basis,
    random_profiles, sample_clouds, silhouettes,
)
from nurbskit.shapes.nets.data import DEGREE, exact_surface, profile_knots
from nurbskit.shapes.nets.guess import _frames, load_model
from nurbskit.shapes.nets.training import loss_fn, model_name

F64 = torch.float64
RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "shapes_nets.json"


def _g(seed):
    return torch.Generator().manual_seed(seed)


# ---- data ------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", KINDS)
def test_batches_are_deterministic(kind):
    images = kind == "revolution"
    a = make_batch(batch_generator(5, 3), 3, kind, 64, images=images)
    b = make_batch(batch_generator(5, 3), 3, kind, 64, images=images)
    c = make_batch(batch_generator(5, 4), 3, kind, 64, images=images)
    for key in a:
        assert torch.equal(a[key], b[key])
    assert not torch.equal(a["points"], c["points"])
    assert a["points"].shape == (3, 64, 3)
    # normalised: centred, in the unit ball, touching it
    assert_close(a["points"].mean(1), torch.zeros(3, 3), atol=1e-6)
    assert_close(a["points"].norm(dim=-1).amax(1), torch.ones(3), atol=1e-6)


def test_profiles_are_monotone_and_positive():
    rev = random_profiles(_g(0), 64, "revolution").reshape(64, N_CTRL, 2)
    assert (rev[..., 0] > 0.09).all()  # radii
    assert (rev[..., 1].diff(dim=1) > 0).all()  # heights strictly increasing: no self-intersection
    ext = random_profiles(_g(0), 64, "extrusion")
    xy, t = ext[:, : 2 * N_CTRL].reshape(64, N_CTRL, 2), ext[:, 2 * N_CTRL:]
    # monotone along some (turned) width direction: the control polygon's steps lie in an open
    # half-plane, i.e. their directions leave an angular gap wider than pi
    steps = xy.diff(dim=1)
    angles = torch.atan2(steps[..., 1], steps[..., 0]).sort(dim=1).values
    gaps = torch.cat([angles.diff(dim=1), angles[:, :1] + 2 * math.pi - angles[:, -1:]], 1)
    assert (gaps.amax(1) > math.pi).all()
    assert (t[:, 1] > t[:, 0]).all()


@pytest.mark.parametrize("kind", KINDS)
def test_clouds_lie_on_the_exact_surface(kind):
    coords = random_profiles(_g(1), 2, kind)
    pts = sample_clouds(_g(2), coords, kind, 300)
    v = torch.linspace(0, 1, 4001, dtype=F64)
    for b in range(2):
        curve = exact_surface(kind, coords[b])
        # the exact surface's profile (v at u = 0), densely: every point's profile coordinates lie on it
        prof = curve.evaluate(torch.stack([torch.zeros_like(v), v], -1))
        if kind == "revolution":
            mine = torch.stack([pts[b, :, :2].norm(dim=-1), pts[b, :, 2]], -1)
            theirs = prof[:, [0, 2]]
        else:
            mine, theirs = pts[b, :, :2], prof[:, :2]
            t0, t1 = coords[b, -2:]
            assert bool(((pts[b, :, 2] >= t0) & (pts[b, :, 2] <= t1)).all())
        assert float(torch.cdist(mine, theirs).amin(-1).max()) < 2e-3  # the dense sample's spacing


def test_silhouette_area_is_the_profiles_integral():
    coords = random_profiles(_g(3), 4, "revolution")
    pts = sample_clouds(_g(4), coords, "revolution", 500)
    _, centre, scale = normalise(pts)
    img = silhouettes(coords, centre, scale)
    pixel = (2 / 63) ** 2
    v = torch.linspace(0, 1, 4001, dtype=F64)
    dense = basis_matrix(profile_knots(), DEGREE, N_CTRL, v) @ coords.reshape(4, N_CTRL, 2)
    r, z = dense[..., 0], dense[..., 1]
    area = (2 * 0.5 * (r[:, 1:] + r[:, :-1]) * z.diff(dim=1)).sum(1) / scale**2  # integral of 2 r dz
    assert_close(img.sum((1, 2, 3)) * pixel, area, atol=0.06 * float(area.max()))


# ---- the fixed surface layer -------------------------------------------------------------

@pytest.mark.parametrize("kind", KINDS)
def test_surface_layer_is_the_core_constructor(kind):
    layer = SurfaceLayer(kind)
    coords = random_profiles(_g(5), 3, kind)
    got = layer(coords)
    for b in range(3):
        want = exact_surface(kind, coords[b]).evaluate(layer.params)
        assert_close(got[b], want, atol=1e-12)


@pytest.mark.parametrize("kind", KINDS)
def test_core_constructor_is_differentiable_and_its_jacobian_is_the_layer(kind):
    layer = SurfaceLayer(kind)
    c = random_profiles(_g(6), 1, kind)[0].requires_grad_(True)
    weights = torch.randn(layer.params.shape[0], 3, generator=_g(7), dtype=F64)
    (exact_surface(kind, c).evaluate(layer.params) * weights).sum().backward()
    assert_close(c.grad, layer.matrix.T @ weights.reshape(-1), atol=1e-10)


# ---- encoders and training ----------------------------------------------------------------

@pytest.mark.parametrize("kind,input", [("revolution", "points"), ("revolution", "image"), ("extrusion", "points")])
def test_encoders_forward_backward(kind, input):
    torch.manual_seed(0)
    model = build_model(kind, input)
    batch = make_batch(_g(8), 3, kind, 96, images=input == "image")
    loss, parts = loss_fn(model, batch)
    assert loss.shape == () and torch.isfinite(loss)
    assert_close(loss, parts["to_surface"] + parts["coverage"], atol=1e-6)
    loss.backward()
    grads = [p.grad for p in model.parameters()]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)
    assert sum(float(g.abs().sum()) for g in grads) > 0
    assert model(batch["images"] if input == "image" else batch["points"]).shape == (3, 2 * N_CTRL + (2 if kind == "extrusion" else 0))


def test_points_model_ignores_point_order():
    torch.manual_seed(0)
    model = build_model("revolution", "points").eval()
    pts = make_batch(_g(9), 2, "revolution", 128)["points"]
    perm = torch.randperm(128, generator=_g(10))
    assert_close(model(pts), model(pts[:, perm]), atol=1e-6)


@pytest.mark.parametrize("input", ["points", "image"])
def test_chamfer_training_lowers_the_loss_on_a_fixed_batch(input):
    torch.manual_seed(0)
    model = build_model("revolution", input)
    batch = make_batch(_g(11), 4, "revolution", 128, images=input == "image")
    first = float(loss_fn(model, batch)[0].detach())
    run_ = train(model, lambda g, n: batch, loss_fn, TrainConfig(steps=25, batch_size=4, lr=2e-3, log_every=5))
    last = float(loss_fn(run_.model, batch)[0].detach())
    assert last < 0.6 * first


# ---- the command ----------------------------------------------------------------------------

def test_train_command_writes_loadable_weights(tmp_path, capsys):
    out = tmp_path / "run"
    code = run(["train", "revolve", "--input", "points", "--kind", "extrusion", "--steps", "2", "--batch-size", "2",
                "--threads", "1", "--quiet", "--out", str(out)])
    assert code == 0
    model = load_model("extrusion", "points", str(out / "weights.pt"))
    assert model.kind == "extrusion" and model.input == "points"
    meta = json.loads((out / "history.json").read_text())["meta"]
    assert meta["name"] == "shapes_extrusion_points" and meta["steps"] == 2


def test_train_command_refuses_image_extrusions(tmp_path, capsys):
    code = run(["train", "revolve", "--input", "image", "--kind", "extrusion", "--out", str(tmp_path / "r")])
    assert code != 0
    assert one_line(capsys.readouterr().err)


# ---- shipped weights and the initialiser ---------------------------------------------------

SHIPPED = [(k, i) for k, i in [("revolution", "points"), ("extrusion", "points"), ("revolution", "image")]
           if model_name(k, i) in shipped_weights()]


def test_the_points_revolution_model_is_shipped():
    assert ("revolution", "points") in SHIPPED


def _fixed_batch() -> dict:
    """The fixed-batch numbers benchmarks/bench_shapes_nets.py computed and recorded."""
    return json.loads(RESULTS.read_text())["meta"]["fixed_batch"]


@pytest.mark.parametrize("kind,input", SHIPPED)
def test_shipped_weights_reproduce_the_benchmarks_fixed_batch(kind, input):
    """The shipped model on the benchmark's fixed batch (8 canonical clouds, 600 points, noise
    drawn in [0, 0.5 %]) gives the mean input-to-surface distance (% of the diagonal, true
    projection: nurbskit.metrics.surface_distances) that bench_shapes_nets.py recorded
    (results/shapes_nets.json, meta.fixed_batch), to float32 rounding: the weights and the
    forward are the benchmarked ones. It is also within 2 % of the diagonal (the issue's goal)."""
    from nurbskit.metrics import surface_distances

    want = _fixed_batch()["canonical"][model_name(kind, input)]
    model = load_model(kind, input)
    batch = make_batch(batch_generator(123, 0), 8, kind, 600, images=input == "image", max_noise=0.005)
    with torch.no_grad():
        coords = model(batch["images"] if input == "image" else batch["points"]).double()
    means = [surface_distances(exact_surface(kind, coords[b]), batch["points"][b].double(), 32)["to_surface_mean"]
             for b in range(8)]
    got = 100 * sum(means) / 8
    assert_close(torch.tensor(got, dtype=F64), torch.tensor(want, dtype=F64), atol=1e-4 * want)
    assert got < 2.0


@pytest.mark.parametrize("kind", [k for k in KINDS if (k, "points") in SHIPPED])
def test_initial_guess_reproduces_the_benchmarks_world_clouds(kind):
    """initial_guess (direction from normals, profile by the network) on the benchmark's world
    clouds 0 and 1 (bench_shapes.py's definition: seed 10000 + i, 2,000 points, 0.5 % noise)
    gives the axis error and input-to-surface mean the benchmark recorded (meta.fixed_batch)."""
    from nurbskit.metrics import surface_distances
    from nurbskit.shapes.synthetic import extrusion_cloud, vase_cloud

    for want in _fixed_batch()["world"][kind]:
        seed = 10_000 + want["cloud"]
        c = (vase_cloud(2000, 0.005, seed) if kind == "revolution"
             else extrusion_cloud(2000, 0.005, seed, "L" if seed % 2 else "smooth"))
        guess = initial_guess(c.points, kind)
        assert guess["direction_from"] == "normals"
        cos = abs(float(guess["axis_direction"] @ c.axis_direction))
        angle = math.degrees(math.acos(min(1.0, cos)))
        mean = surface_distances(guess_surface(guess, kind), c.points)["to_surface_mean"]
        assert abs(angle - want["axis_deg"]) < 1e-3
        assert_close(torch.tensor(mean, dtype=F64), torch.tensor(want["to_surface_mean"], dtype=F64),
                     atol=1e-4 * want["to_surface_mean"])
        assert mean < 0.02  # the goal: within 2 % of the diagonal


def test_pointnet_matrix_products_are_the_convolutions():
    """The encoder applies its 1x1 Conv1d weights as matrix products on channel-last points;
    the Conv1d modules themselves (channel-first) are the oracle, in float64."""
    model = build_model("revolution", "points").double().eval()
    x = torch.randn(3, 57, 3, generator=_g(21), dtype=F64)
    with torch.no_grad():
        want = model.encoder.mlp(x.transpose(1, 2)).amax(-1)
        assert_close(model.encoder(x), want, atol=1e-12)


def test_search_score_is_the_training_chamfer():
    from nurbskit.losses import chamfer_distance
    from nurbskit.shapes.nets.guess import predict_canonical

    torch.manual_seed(0)
    model = build_model("revolution", "points").eval()
    clouds = make_batch(_g(13), 3, "revolution", 100)["points"]
    coords, score = predict_canonical(model, clouds)
    with torch.no_grad():
        want = chamfer_distance(clouds, model.surface_points(coords.float()))
    assert_close(score, want.double(), atol=1e-6)


def test_frames_follow_the_contracts_plane_basis():
    dirs = torch.nn.functional.normalize(torch.randn(20, 3, generator=_g(12), dtype=F64), dim=-1)
    dirs[0] = torch.tensor([0.95, 0.1, math.sqrt(1 - 0.95**2 - 0.01)], dtype=F64)
    frames = _frames(dirs)
    for d, f in zip(dirs, frames):
        e1, e2 = plane_basis(d)
        assert_close(f[0], e1, atol=1e-12)
        assert_close(f[1], e2, atol=1e-12)
        assert_close(f @ f.T, torch.eye(3, dtype=F64), atol=1e-12)
        assert float(torch.det(f)) > 0


def _tilted_vase():
    """A clean vase (not from the training generator) in an arbitrary pose."""
    from nurbskit.shapes.synthetic import vase_cloud

    return vase_cloud(1500, 0.0, seed=0)


@pytest.mark.skipif(("revolution", "points") not in SHIPPED, reason="no shipped revolution model")
def test_initial_guess_revolution_contract_and_axis():
    """Bound: 2 degrees, above the benchmark's 95th percentile for the normals direction on
    noisy world-pose vases; measured 0.8 degree on this clean cloud."""
    vase = _tilted_vase()
    guess = initial_guess(vase.points, "revolution")
    assert {"axis_point", "axis_direction", "profile"} <= set(guess)
    assert guess["direction_from"] == "normals" and guess["chamfer"] is None
    d = guess["axis_direction"]
    assert d.shape == (3,) and d.dtype == F64
    assert_close(d.norm(), torch.tensor(1.0, dtype=F64), atol=1e-12)
    angle = math.degrees(math.acos(min(1.0, abs(float(d @ vase.axis_direction)))))
    assert angle < 2.0
    # the axis point lies on the true axis (up to the guess's error)
    off = guess["axis_point"] - vase.axis_point
    assert float((off - (off @ vase.axis_direction) * vase.axis_direction).norm()) < 0.05
    prof = guess["profile"]
    assert prof.dim == 2 and prof.control_points.dtype == F64
    assert (prof.control_points[:, 0] >= 0).all()
    # the guessed surface is near the cloud: within 2 % of the diagonal on average (the goal)
    surface = guess_surface(guess, "revolution")
    dense = surface.sample((64, 64)).reshape(-1, 3)
    diag = float((vase.points.amax(0) - vase.points.amin(0)).norm())
    assert float(torch.cdist(vase.points, dense).amin(-1).mean()) < 0.02 * diag


@pytest.mark.skipif(("revolution", "points") not in SHIPPED, reason="no shipped revolution model")
def test_normals_direction_is_the_shape_packages_estimate():
    """direction="normals" is nurbskit.shapes.axis.revolution_axis on the normals of an even
    subsample of AXIS_POINTS normalised points (the public functions, not a copy)."""
    from nurbskit.shapes.axis import revolution_axis
    from nurbskit.shapes.nets import guess as G
    from nurbskit.shapes.normals import estimate_normals

    vase = _tilted_vase()
    rel = normalise(vase.points)[0]
    sub = rel[torch.linspace(0, rel.shape[0] - 1, G.AXIS_POINTS, dtype=F64).round().long()]
    want = revolution_axis(sub, estimate_normals(sub, G.AXIS_NEIGHBOURS["revolution"]),
                           iterations=G.AXIS_ITERATIONS["revolution"]).direction
    got = initial_guess(vase.points, "revolution")["axis_direction"]
    assert_close(abs(got @ want), torch.tensor(1.0, dtype=F64), atol=1e-12)


@pytest.mark.skipif(("revolution", "points") not in SHIPPED, reason="no shipped revolution model")
def test_search_direction_recovers_the_axis():
    """direction="search" (the network alone, 54 candidates by Chamfer). Bound: 5 degrees,
    above the benchmark's 95th percentile of the search (about 4 degrees on noisy world-pose
    vases); measured 1.8 degrees on this cloud. score=True adds the training Chamfer."""
    vase = _tilted_vase()
    guess = initial_guess(vase.points, "revolution", direction="search", score=True)
    assert guess["direction_from"] == "search"
    angle = math.degrees(math.acos(min(1.0, abs(float(guess["axis_direction"] @ vase.axis_direction)))))
    assert angle < 5.0
    assert 0 < guess["chamfer"] < 0.05  # squared distances in the unit ball; measured 0.015


@pytest.mark.parametrize("kind", [k for k in KINDS if (k, "points") in SHIPPED])
def test_ambiguous_normals_direction_falls_back_to_the_search(kind):
    """A sphere: every line through its centre is an axis and its normals span all directions,
    so the normals estimate is ambiguous (spread above SPREAD_LIMIT) and the network searches."""
    from nurbskit.shapes.nets import guess as G

    sphere = torch.nn.functional.normalize(torch.randn(800, 3, generator=_g(0), dtype=F64), dim=-1) * 3 + 1
    _, spread = G._normals_direction(normalise(sphere)[0], kind)
    assert spread > G.SPREAD_LIMIT
    assert initial_guess(sphere, kind)["direction_from"] == "search"


@pytest.mark.skipif(("extrusion", "points") not in SHIPPED, reason="no shipped extrusion model")
def test_initial_guess_extrusion_contract():
    from nurbskit.shapes.synthetic import extrusion_cloud

    cloud = extrusion_cloud(1500, 0.0, seed=4)
    guess = initial_guess(cloud.points, "extrusion")
    assert {"axis_point", "axis_direction", "profile", "extent", "frame"} <= set(guess)
    t0, t1 = guess["extent"]
    assert t1 > t0
    angle = math.degrees(math.acos(min(1.0, abs(float(guess["axis_direction"] @ cloud.axis_direction)))))
    assert angle < 2.5  # the normals direction; this clean cloud: 0.23 degree
    # the profile's (x, y) are in the contract's plane_basis frame about axis_point
    e1, e2 = plane_basis(guess["axis_direction"])
    assert_close(guess["frame"]["e1"], e1, atol=1e-12)
    assert_close(guess["frame"]["e2"], e2, atol=1e-12)


def test_initial_guess_refuses_bad_input():
    from nurbskit.errors import InputError, OptionError

    with pytest.raises(InputError, match="shape"):
        initial_guess(torch.zeros(5, 2, dtype=F64), "revolution")
    with pytest.raises(OptionError, match="kind"):
        initial_guess(torch.zeros(50, 3, dtype=F64), "cone")
    with pytest.raises(OptionError, match="direction"):
        initial_guess(torch.rand(50, 3, dtype=F64), "revolution", direction="pca")
    with pytest.raises(OptionError, match="nurbskit train revolve"):
        load_model("revolution", "points", "/nonexistent/weights.pt")
