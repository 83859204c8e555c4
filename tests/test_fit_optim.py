"""The fitting loop's L-BFGS (nurbskit.fit.optim): torch's iterates on a fixed objective,
secant pairs from one objective when it changes, and a direction without host reads."""

from __future__ import annotations

import torch
from _assert import assert_close

from nurbskit._opcount import OperationCounter
from nurbskit.fit.optim import LBFGS

F64 = torch.float64


def _rosenbrock(x: torch.Tensor) -> torch.Tensor:
    return ((1 - x[:-1]).square() + 100 * (x[1:] - x[:-1].square()).square()).sum()


def _closure(opt, x, f):
    def closure():
        opt.zero_grad()
        loss = f(x)
        loss.backward()
        return loss
    return closure


def test_on_a_fixed_objective_it_takes_torchs_lbfgs_steps():
    # With nothing refreshed between steps, the pair from the line search's ends is the
    # pair torch forms from consecutive starts: the same iterates, up to rounding.
    start = torch.tensor([-1.2, 1.0, -0.5, 0.8, 1.5], dtype=F64)
    ours = start.clone().requires_grad_()
    theirs = start.clone().requires_grad_()
    a = LBFGS([ours], lr=1.0, history_size=5)
    b = torch.optim.LBFGS([theirs], lr=1.0, max_iter=1, max_eval=25, history_size=5, line_search_fn="strong_wolfe",
                          tolerance_grad=1e-14, tolerance_change=1e-16)
    for _ in range(25):
        la = a.step(_closure(a, ours, _rosenbrock))
        lb = b.step(_closure(b, theirs, _rosenbrock))
        assert_close(la.detach(), lb.detach(), atol=1e-10)
        assert_close(ours.detach(), theirs.detach(), atol=1e-9)
    assert float(_rosenbrock(ours.detach())) < 1.0  # it does descend (from 355.7)


def test_pairs_come_from_one_objective_when_it_changes_between_steps():
    # f_k(x) = 0.5 x^T A x - b_k^T x with b_k moving every step (as foot points move in a
    # fit): every stored pair must satisfy the secant equation of the true Hessian,
    # y = A s, which a pair of gradients of two different objectives does not.
    g = torch.Generator().manual_seed(3)
    Q = torch.linalg.qr(torch.randn(6, 6, generator=g, dtype=F64))[0]
    A = Q @ torch.diag(torch.tensor([1.0, 2.0, 4.0, 8.0, 16.0, 32.0], dtype=F64)) @ Q.T
    x = torch.zeros(6, dtype=F64, requires_grad=True)
    opt = LBFGS([x], lr=1.0)
    for k in range(8):
        b = torch.randn(6, generator=g, dtype=F64)
        opt.step(_closure(opt, x, lambda x, b=b: 0.5 * x @ A @ x - b @ x))
    opt._remember(*opt._pending)
    assert len(opt._s) == 8
    for s, y in zip(opt._s, opt._y):
        assert_close(y, A @ s, atol=1e-12)


def test_the_direction_reads_nothing_back_to_the_host():
    x = torch.tensor([-1.2, 1.0, -0.5, 0.8], dtype=F64, requires_grad=True)
    opt = LBFGS([x], lr=1.0)
    for _ in range(6):
        opt.step(_closure(opt, x, _rosenbrock))
    opt._remember(*opt._pending)
    grad = torch.ones(4, dtype=F64)
    with OperationCounter() as count:
        d = opt._direction(grad)
    assert count.host_reads == 0, count.host_read_names()
    assert float(d @ grad) < 0  # a descent direction: H stays positive definite


def test_a_pair_without_positive_curvature_drops_out():
    # y . s <= 0 (a concave stretch): the pair is kept with rho = 0, so the direction is
    # the one without it.
    x = torch.zeros(3, dtype=F64, requires_grad=True)
    opt = LBFGS([x])
    opt._remember(torch.tensor([1.0, 0.0, 0.0], dtype=F64), torch.tensor([1.0, 0.5, 0.0], dtype=F64))
    grad = torch.tensor([0.3, -0.2, 0.7], dtype=F64)
    before = opt._direction(grad.clone())
    opt._remember(torch.tensor([0.0, 1.0, 0.0], dtype=F64), torch.tensor([0.0, -2.0, 1.0], dtype=F64))
    assert_close(opt._direction(grad.clone()), before, atol=1e-15)


def test_it_imports_neither_torch_dynamo_nor_sympy():
    # Both cost a command from a fresh process: torch._dynamo 0.75 s (torch.optim.Optimizer's
    # constructor: the loop's optimiser is a plain class), sympy 0.3 s (torch.broadcast_shapes
    # on first use, with torch 2.13). Checked after the optimiser alone, then after a default
    # fit and the report's Chamfer.
    import subprocess
    import sys

    code = (
        "import sys, numpy as np, torch, nurbskit\n"
        "from nurbskit.fit.optim import LBFGS\n"
        "x = torch.tensor([-1.2, 1.0], dtype=torch.float64, requires_grad=True)\n"
        "opt = LBFGS([x])\n"
        "def closure():\n"
        "    opt.zero_grad()\n"
        "    loss = ((1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2)\n"
        "    loss.backward()\n"
        "    return loss\n"
        "for _ in range(5):\n"
        "    opt.step(closure)\n"
        "print('torch._dynamo' in sys.modules)\n"
        "t = np.linspace(0, 1, 20)\n"
        "u, v = np.meshgrid(t, t)\n"
        "cloud = np.stack([u, v, np.sin(3 * u) * v], -1).reshape(-1, 3)\n"
        "nurbskit.fit_surface(cloud)\n"
        "from nurbskit.losses import chamfer_distance\n"
        "chamfer_distance(torch.rand(5, 3), torch.rand(6, 3))  # the report's metric\n"
        "print('torch._dynamo' in sys.modules, 'sympy' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-2:] == ["False", "False False"], out.stdout + out.stderr


def test_it_refuses_parameter_groups_and_empty_lists():
    import pytest

    x = torch.zeros(2, requires_grad=True)
    with pytest.raises(ValueError, match="one parameter group"):
        LBFGS([{"params": [x]}])
    with pytest.raises(ValueError, match="empty"):
        LBFGS([])


def test_run_takes_the_iterations_of_one_torch_lbfgs_step():
    # run(max_iter) is one step of torch.optim.LBFGS(max_iter=...) with the strong Wolfe
    # search and torch's defaults: the same iterates, evaluation budget and early stops.
    start = torch.tensor([-1.2, 1.0, -0.5, 0.8, 1.5], dtype=F64)
    cases = [(100, 5, None), (100, 20, None), (100, 60, None), (100, 40, 12), (100, 200, None), (3, 200, None)]
    for history, max_iter, max_eval in cases:
        ours = start.clone().requires_grad_()
        theirs = start.clone().requires_grad_()
        a = LBFGS([ours], lr=1.0, history_size=history)
        b = torch.optim.LBFGS([theirs], lr=1.0, max_iter=max_iter, max_eval=max_eval, history_size=history,
                              line_search_fn="strong_wolfe")
        evals = {"a": 0, "b": 0}

        def counted(name, opt, x):
            inner = _closure(opt, x, _rosenbrock)

            def closure():
                evals[name] += 1
                return inner()
            return closure

        la = a.run(counted("a", a, ours), max_iter, max_eval)
        lb = b.step(counted("b", b, theirs))
        assert_close(la.detach(), lb.detach(), atol=0.0)
        assert evals["a"] == evals["b"], (max_iter, evals)
        assert torch.equal(ours.detach(), theirs.detach()), (history, max_iter, max_eval)  # to the last bit
        if max_iter == 200:  # converged: the early stops (a loss change under 1e-9) ended both
            assert float(_rosenbrock(ours.detach())) < 1e-8
