"""The one training loop (nurbskit.learn): determinism, resume, files, refusals."""

from __future__ import annotations

import json

import pytest
import torch
from torch import nn

from _cli import one_line, run
from nurbskit.errors import InputError, OptionError
from nurbskit.learn import TrainConfig, batch_generator, load_weights, train

TRUE = torch.tensor([[2.0, -1.0, 0.5]], dtype=torch.float64)


def make_batch(g: torch.Generator, n: int):
    x = torch.randn(n, 3, generator=g, dtype=torch.float64)
    return x, x @ TRUE.T + 0.25


def loss_fn(model, batch):
    x, y = batch
    err = model(x) - y
    return (err**2).mean(), {"max_abs": err.abs().max()}


def model():
    torch.manual_seed(0)
    return nn.Linear(3, 1).double()


def config(**kw):
    return TrainConfig(**{"steps": 40, "batch_size": 16, "lr": 0.05, "log_every": 5, "checkpoint_every": 10, **kw})


def test_batches_depend_on_seed_and_step_only():
    a = make_batch(batch_generator(3, 7), 4)[0]
    assert torch.equal(a, make_batch(batch_generator(3, 7), 4)[0])
    assert not torch.equal(a, make_batch(batch_generator(3, 8), 4)[0])
    assert not torch.equal(a, make_batch(batch_generator(4, 7), 4)[0])


def test_training_learns_the_linear_map():
    run_ = train(model(), make_batch, loss_fn, config(steps=300))
    w = run_.model.weight.detach()
    assert (w - TRUE).abs().max() < 1e-2
    assert run_.history[-1]["loss"] < 1e-3 * run_.history[0]["loss"]
    assert [r["step"] for r in run_.history] == list(range(5, 301, 5))


def test_interrupted_then_resumed_equals_uninterrupted(tmp_path):
    straight = train(model(), make_batch, loss_fn, config(), tmp_path / "a")

    def stop_at_17(step, steps, values):
        if step == 17:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train(model(), make_batch, loss_fn, config(), tmp_path / "b", progress=stop_at_17)
    assert torch.load(tmp_path / "b" / "checkpoint.pt", weights_only=True)["step"] == 17
    resumed = train(nn.Linear(3, 1).double(), make_batch, loss_fn, config(), tmp_path / "b", resume=True)
    assert resumed.step == 40
    for p, q in zip(straight.model.parameters(), resumed.model.parameters()):
        assert torch.equal(p, q)


def test_run_folder_files_and_weights(tmp_path):
    out = tmp_path / "run"
    train(model(), make_batch, loss_fn, config(), out, meta={"name": "toy", "arch": {"in": 3}})
    names = {p.name for p in out.iterdir()}
    assert {"checkpoint.pt", "weights.pt", "history.json", "training.png", ".nurbskit-manifest.json"} <= names
    state, meta = load_weights(out / "weights.pt")
    assert meta["name"] == "toy" and meta["steps"] == 40 and meta["config"]["seed"] == 0
    again = nn.Linear(3, 1).double()
    again.load_state_dict(state)
    history = json.loads((out / "history.json").read_text())
    assert history["history"][-1]["step"] == 40


def test_refusals(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(OptionError, match="no checkpoint.pt"):
        train(model(), make_batch, loss_fn, config(), out, resume=True)
    train(model(), make_batch, loss_fn, config(steps=5), out)
    with pytest.raises(OptionError, match="--overwrite"):
        train(model(), make_batch, loss_fn, config(steps=5), out)
    (out / "mine.txt").write_text("keep")
    with pytest.raises(OptionError, match="did not write"):
        train(model(), make_batch, loss_fn, config(steps=5), out, overwrite=True)
    (out / "mine.txt").unlink()
    train(model(), make_batch, loss_fn, config(steps=5), out, overwrite=True)
    with pytest.raises(OptionError, match="seed"):
        train(model(), make_batch, loss_fn, config(steps=8, seed=1), out, resume=True)
    with pytest.raises(InputError, match="no shipped weights"):
        load_weights("no_such_model")
    with pytest.raises(OptionError):
        TrainConfig(steps=0)


def test_train_command_needs_a_model(capsys):
    assert run(["train"]) == 2
    assert one_line(capsys.readouterr().err)
