"""Shared test fixtures.

Real data lives in ``../shared/data`` beside the repository (never copied into it).
Tests that need it use the ``shared_data`` fixture: they skip with a reason when the
folder is absent, and fail when ``NURBSKIT_REQUIRE_SHARED_DATA=1`` (set by .ci/run
whenever the folder exists) so that CI cannot pass by skipping them.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch
from hypothesis import HealthCheck, settings

# Property tests: derandomized by default (a fixed seed, no example database), so that CI
# cannot fail at random; `make fuzz` selects the "fuzz" profile (random seeds, many more
# examples). A failing case found by fuzzing is kept in the test as an explicit @example.
settings.register_profile("ci", derandomize=True, database=None, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("fuzz", derandomize=False, database=None, deadline=None, max_examples=2000,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("NURBSKIT_HYPOTHESIS_PROFILE", "ci"))

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("NURBSKIT_SHARED_DATA", REPO_ROOT.parent / "shared" / "data"))


def _require() -> bool:
    return os.environ.get("NURBSKIT_REQUIRE_SHARED_DATA", "") not in ("", "0")


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path of ../shared/data; skip without it (fail when it is required)."""
    if not SHARED_DATA.is_dir():
        if _require():
            pytest.fail(f"NURBSKIT_REQUIRE_SHARED_DATA is set but {SHARED_DATA} is missing")
        pytest.skip(f"{SHARED_DATA} not present")
    return SHARED_DATA


def shared_file(shared_data: Path, relative: str) -> Path:
    """A file under ../shared/data that must exist when the folder does."""
    path = shared_data / relative
    if not path.exists():
        pytest.fail(f"expected data file {path} is missing from ../shared/data")
    return path


# One intra-op thread: the tests' tensors are small, and on a busy 2-core machine
# OpenMP threads waiting for a core stall even tiny operations (measured: a 10k-point
# evaluation 20 ms with 1 thread, 170 ms with 2). Override with NURBSKIT_TEST_THREADS.
torch.set_num_threads(int(os.environ.get("NURBSKIT_TEST_THREADS", "1")))


@pytest.fixture(autouse=True)
def _deterministic_torch():
    torch.set_default_dtype(torch.float32)
    yield
