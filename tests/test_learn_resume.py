"""`nurbskit train --resume` and interruptions: the output-folder rules, checkpoints of the
wrong kind or settings, and the truth about what an interrupted run left behind."""

from __future__ import annotations

import shutil

import pytest
import torch
from torch import nn

import nurbskit.learn
from _cli import one_line, run
from nurbskit._fs import MANIFEST, read_manifest, write_manifest
from nurbskit.cli import Terminated
from nurbskit.errors import InputError, OptionError
from nurbskit.learn import TrainConfig, train

QUICK = ["--steps", "4", "--threads", "1", "--quiet", "--checkpoint-every", "2"]


def curves(out, *extra, mode="V", steps=None):
    argv = ["train", "curves", "--mode", mode, *QUICK, "--out", str(out), *extra]
    if steps is not None:
        argv[argv.index("--steps") + 1] = str(steps)
    return run(argv)


@pytest.fixture(scope="module")
def good_run(tmp_path_factory):
    """A finished 4-step `train curves --mode V` run folder (copy it before changing it)."""
    out = tmp_path_factory.mktemp("learn_resume") / "good"
    assert curves(out) == 0
    return out


def copy_of(good_run, tmp_path, name="run"):
    dest = tmp_path / name
    shutil.copytree(good_run, dest)
    return dest


def step_of(out) -> int:
    return int(torch.load(out / "checkpoint.pt", weights_only=True)["step"])


def own(folder, names):
    """Mark ``names`` in ``folder`` as nurbskit's (a manifest listing them at their sizes)."""
    write_manifest(folder, {n: (folder / n).stat().st_size for n in names})


# ---- 1. --resume follows the output-folder rules ------------------------------------------


def test_resume_continues_a_folder_train_wrote(good_run, tmp_path):
    out = copy_of(good_run, tmp_path)
    assert curves(out, "--resume", steps=6) == 0
    assert step_of(out) == 6
    assert set(read_manifest(out.resolve())) == {"checkpoint.pt", "weights.pt", "history.json", "training.png"}


@pytest.mark.parametrize("model", [["curves", "--mode", "V"], ["revolve"]])
def test_resume_refuses_files_nurbskit_did_not_write(good_run, tmp_path, capsys, model):
    out = tmp_path / "mine"
    out.mkdir()
    shutil.copy(good_run / "checkpoint.pt", out)
    mine = {"training.png": "MY PLOT\n", "weights.pt": "x\n", "history.json": "{}\n"}
    for name, text in mine.items():
        (out / name).write_text(text)
    capsys.readouterr()
    assert run(["train", *model, *QUICK, "--steps", "8", "--resume", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert one_line(err) and f"--out {out}" in err and "did not write" in err
    assert {n: (out / n).read_text() for n in mine} == mine
    assert not (out / MANIFEST).exists()


def test_resume_refuses_a_file_added_to_a_run_folder(good_run, tmp_path, capsys):
    out = copy_of(good_run, tmp_path)
    (out / "notes.txt").write_text("keep")
    capsys.readouterr()
    assert curves(out, "--resume", steps=6) == 2
    err = capsys.readouterr().err
    assert one_line(err) and "notes.txt" in err
    assert step_of(out) == 4 and (out / "notes.txt").read_text() == "keep"


def test_resume_refuses_a_changed_checkpoint(good_run, tmp_path, capsys):
    out = copy_of(good_run, tmp_path)
    with open(out / "checkpoint.pt", "ab") as handle:
        handle.write(b"\0")
    capsys.readouterr()
    assert curves(out, "--resume", steps=6) == 2
    err = capsys.readouterr().err
    assert one_line(err) and "changed since" in err


def test_resume_refuses_another_commands_folder(good_run, tmp_path, capsys):
    out = copy_of(good_run, tmp_path)
    (out / "report.json").write_text("{}")
    own(out, [*read_manifest(out.resolve()), "report.json"])
    capsys.readouterr()
    assert curves(out, "--resume", steps=6) == 2
    err = capsys.readouterr().err
    assert one_line(err) and "report.json" in err and "another" in err
    assert (out / "report.json").exists() and step_of(out) == 4


# ---- 2. checkpoints of the wrong kind or settings ------------------------------------------


BAD_CHECKPOINTS = {
    "dict without keys": ({"a": 1}, "found a dict of a"),
    "tensor": (torch.zeros(3), "found a tensor of shape (3,)"),
    "config not json": ({"model": {}, "optimizer": {}, "step": 1, "seconds": 0.0, "history": "[]",
                         "config": "nope"}, "config is not a JSON object"),
    "no model": ({"optimizer": {}, "step": 1, "seconds": 0.0, "history": "[]", "config": "{}"}, "no model"),
    "model not tensors": ({"model": {"w": 1}, "optimizer": {}, "step": 1, "seconds": 0.0, "history": "[]",
                           "config": '{"seed": 0, "batch_size": 32}'}, "dict of tensors"),
}


@pytest.mark.parametrize("case", sorted(BAD_CHECKPOINTS))
def test_resume_from_a_checkpoint_of_the_wrong_kind(tmp_path, capsys, case):
    content, found = BAD_CHECKPOINTS[case]
    out = tmp_path / "bad"
    out.mkdir()
    torch.save(content, out / "checkpoint.pt")
    own(out, ["checkpoint.pt"])
    capsys.readouterr()
    assert curves(out, "--resume") == 2
    err = capsys.readouterr().err
    assert one_line(err), err  # no traceback, no torch warning
    assert str(out / "checkpoint.pt") in err and found in err and "unexpected" not in err


def test_resume_from_a_file_torch_cannot_read(tmp_path, capsys):
    out = tmp_path / "bad"
    out.mkdir()
    (out / "checkpoint.pt").write_text("not a checkpoint\n")
    own(out, ["checkpoint.pt"])
    capsys.readouterr()
    assert curves(out, "--resume") == 2
    err = capsys.readouterr().err
    assert one_line(err) and f"{out / 'checkpoint.pt'}: not a nurbskit training checkpoint" in err


@pytest.mark.parametrize("options, named", [
    (["--mode", "M"], "--mode M"),
    (["--mode", "MV", "--sketch", "2"], "--mode MV"),
    (["--size", "32"], "--size 32"),
    (["--input", "redrawn"], "--input redrawn"),
    (["--batch-size", "8"], "--batch-size 8"),
    (["--seed", "3"], "--seed 3"),
    (["--steps", "2"], "--steps 2"),
])
def test_resume_with_other_settings_is_refused(good_run, tmp_path, capsys, options, named):
    out = copy_of(good_run, tmp_path)
    argv = ["train", "curves", "--mode", "V", *QUICK, "--steps", "6", "--out", str(out), "--resume"]
    for i in range(0, len(options), 2):  # the later value of a repeated option wins in argparse
        argv += options[i:i + 2]
    capsys.readouterr()
    assert run(argv) == 2
    err = capsys.readouterr().err
    assert one_line(err) and err.split(": error: ", 1)[1].startswith(named), err
    assert step_of(out) == 4


def test_resume_with_another_networks_checkpoint(good_run, tmp_path, capsys):
    out = copy_of(good_run, tmp_path)
    capsys.readouterr()
    assert run(["train", "revolve", *QUICK, "--steps", "6", "--batch-size", "32", "--out", str(out),
                "--resume"]) == 2
    err = capsys.readouterr().err
    assert one_line(err) and f"{out / 'checkpoint.pt'}: not a shapes_revolution_points checkpoint" in err
    assert "curves_v" in err


def test_checkpoint_without_meta_is_checked_by_its_weights(good_run, tmp_path, capsys):
    """A checkpoint written before checkpoints recorded their network: weights.pt tells it."""
    out = copy_of(good_run, tmp_path)
    state = torch.load(out / "checkpoint.pt", weights_only=True)
    del state["meta"]
    torch.save(state, out / "checkpoint.pt")
    own(out, [n for n in read_manifest(out.resolve())])
    capsys.readouterr()
    assert curves(out, "--resume", "--size", "32", steps=6) == 2
    assert "--size 32" in capsys.readouterr().err
    assert curves(out, "--resume", steps=6) == 0 and step_of(out) == 6


def make_batch(g, n):
    x = torch.randn(n, 3, generator=g, dtype=torch.float64)
    return x, x.sum(-1, keepdim=True)


def loss_fn(model, batch):
    x, y = batch
    return ((model(x) - y) ** 2).mean(), {}


def test_library_resume_refuses_another_network(tmp_path):
    config = TrainConfig(steps=4, batch_size=4, log_every=2, checkpoint_every=2)
    torch.manual_seed(0)
    train(nn.Linear(3, 1).double(), make_batch, loss_fn, config, tmp_path / "run")
    with pytest.raises(InputError, match=r"checkpoint.pt: its network is not this one .*shape \(1, 3\) there"):
        train(nn.Linear(3, 2).double(), make_batch, loss_fn, TrainConfig(steps=6, batch_size=4), tmp_path / "run",
              resume=True)
    with pytest.raises(OptionError, match="--batch-size 8"):
        train(nn.Linear(3, 1).double(), make_batch, loss_fn, TrainConfig(steps=6, batch_size=8), tmp_path / "run",
              resume=True)


# ---- 3. interruptions say what they left; --steps is bounded ------------------------------


def interrupt_at(monkeypatch, step, signal=Terminated):
    """Make the CLI's training raise ``signal`` (SIGTERM's Terminated, Ctrl-C's KeyboardInterrupt)
    as batch ``step`` is drawn (0: before the first step)."""
    real = nurbskit.learn.train

    def train_then_stop(model, make_batch, *args, **kwargs):
        def make(generator, batch_size, _count=[0]):  # noqa: B006 - a counter for this run
            if _count[0] == step:
                raise signal
            _count[0] += 1
            return make_batch(generator, batch_size)

        return real(model, make, *args, **kwargs)

    monkeypatch.setattr(nurbskit.learn, "train", train_then_stop)


def test_terminated_run_says_what_it_kept(tmp_path, capsys, monkeypatch):
    out = tmp_path / "big"
    interrupt_at(monkeypatch, 3)
    assert curves(out, steps=10**9) == 143
    err = capsys.readouterr().err
    assert one_line(err) and "no partial output" not in err
    assert f"terminated; kept the run at step 3 of 1000000000 in {out}/" in err and "--resume" in err
    assert step_of(out) == 3
    assert set(read_manifest(out.resolve())) == {"checkpoint.pt", "weights.pt", "history.json"}
    monkeypatch.undo()
    assert curves(out, "--resume", steps=5) == 0 and step_of(out) == 5  # and it resumes


def test_interrupted_before_the_first_step_leaves_no_folder(tmp_path, capsys, monkeypatch):
    out = tmp_path / "new"
    interrupt_at(monkeypatch, 0, KeyboardInterrupt)
    assert curves(out) == 130
    err = capsys.readouterr().err
    assert one_line(err) and "interrupted; no output was left behind" in err
    assert not out.exists()


def test_interrupted_overwrite_keeps_the_earlier_run_until_its_first_checkpoint(good_run, tmp_path, capsys,
                                                                                monkeypatch):
    out = copy_of(good_run, tmp_path)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    interrupt_at(monkeypatch, 0)
    assert curves(out, "--overwrite") == 143
    err = capsys.readouterr().err
    assert one_line(err) and "as they were" in err and "step 4 of 4" in err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    monkeypatch.undo()
    interrupt_at(monkeypatch, 1)  # past its first step: its files replace the earlier run's, figure included
    assert curves(out, "--overwrite") == 143
    assert "kept the run at step 1 of 4" in capsys.readouterr().err
    assert not (out / "training.png").exists() and step_of(out) == 1
    assert set(read_manifest(out.resolve())) == {"checkpoint.pt", "weights.pt", "history.json"}


def test_steps_are_bounded(tmp_path, capsys):
    assert curves(tmp_path / "x", steps=99999999999999999999) == 2
    err = capsys.readouterr().err
    assert one_line(err) and "--steps" in err and "1000000000" in err
    assert not (tmp_path / "x").exists()
    with pytest.raises(OptionError, match="at most"):
        TrainConfig(steps=10**9 + 1)



def test_init_names_what_it_was_given(good_run, tmp_path, capsys):
    not_weights = tmp_path / "d.png"
    not_weights.write_bytes(b"\x89PNG\r\n\x1a\n")
    for init, says in ((str(not_weights), "not a nurbskit weights file (torch cannot read it as saved weights)"),
                       (str(good_run / "checkpoint.pt"), "a training checkpoint: continue it with --resume"),
                       ("nosuch", "--init no shipped weights called 'nosuch'"),
                       ("curves_m", "its weights are those of curves_m, not of curves_v")):
        assert curves(tmp_path / "o", "--init", init, steps=1) == 2
        err = capsys.readouterr().err
        assert one_line(err) and says in err and "weights_only" not in err, err


def test_a_batch_that_cannot_fit_is_refused_before_the_first_step(tmp_path, capsys, monkeypatch):
    import nurbskit._budget as budget
    from nurbskit.curves.nets.train import LOSSES, batch_maker, build
    from nurbskit.learn.trainer import step_memory

    fixed, per = step_memory(lambda: build("V", {}), batch_maker("V", 64), LOSSES["V"])
    assert per > 0 and fixed >= 0
    monkeypatch.setattr(budget, "available_bytes", lambda: int(fixed / 2 + per / 2 * 100.5))  # 100 examples fit
    assert curves(tmp_path / "o", "--batch-size", "4096", steps=1) == 2
    err = capsys.readouterr().err
    assert one_line(err) and "--batch-size 4096" in err and "--batch-size 100 fits" in err, err
    assert not (tmp_path / "o").exists()


def test_resume_refuses_another_learning_rate(good_run, tmp_path, capsys):
    run_folder = copy_of(good_run, tmp_path)
    assert curves(run_folder, "--resume", "--lr", "0.5", steps=6) == 2
    err = capsys.readouterr().err
    assert one_line(err) and "--lr 0.5: the run in" in err and "was started with --lr" in err, err
    assert step_of(run_folder) == 4
