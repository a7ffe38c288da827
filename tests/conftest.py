"""Shared test set-up: quiet Warp on the CPU device (CUDA tests are opt-in with --cuda)."""

import os

import pytest
import warp as wp

wp.config.log_level = wp.LOG_WARNING  # no banner or per-module load lines


def pytest_addoption(parser):
    parser.addoption("--cuda", action="store_true", help="also run device-parametrised tests on cuda:0")


@pytest.fixture(scope="session")
def device(request):
    if request.config.getoption("--cuda") and wp.is_cuda_available():
        return "cuda:0"
    return "cpu"


os.environ.setdefault("WARP_SIM_TEST", "1")
