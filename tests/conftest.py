"""Shared test set-up: quiet Warp, and the devices the physics tests run on.

A test that takes a ``device`` argument is parametrised over devices (``pytest_generate_tests``):
always "cpu", and "cuda:0" as well when ``--cuda`` is given and Warp finds a CUDA device.  Without
``--cuda``, or with no GPU, every test runs once on the CPU exactly as before (its id gains
"cpu").  What exists on the CPU only (the slab pair schedule, CPU thread chunking and race
checks) takes no ``device``, or skips its CUDA case saying why.
"""

import os

import pytest
import warp as wp

wp.config.log_level = wp.LOG_WARNING  # no banner or per-module load lines


def pytest_addoption(parser):
    parser.addoption("--cuda", action="store_true", help="also run device-parametrised tests on cuda:0")


def devices(config) -> list[str]:
    if config.getoption("--cuda") and wp.is_cuda_available():
        return ["cpu", "cuda:0"]
    return ["cpu"]


def pytest_configure(config):
    if config.getoption("--cuda") and not wp.is_cuda_available():
        # a run asked to cover CUDA must not pass as if it had: say once that only the CPU ran
        message = "--cuda: Warp finds no CUDA device, so the device-parametrised tests run on the CPU only"
        config.issue_config_time_warning(pytest.PytestConfigWarning(message), stacklevel=2)


def pytest_generate_tests(metafunc):
    if "device" in metafunc.fixturenames:
        names = devices(metafunc.config)
        metafunc.parametrize("device", names, ids=names)


os.environ.setdefault("WARP_SIM_TEST", "1")
# no spinning workers (launch.hot): two test processes on two cores would each spin a core away
# from the other; tests/test_hot_launch.py turns them on where it checks them
os.environ.setdefault("WARP_SIM_HOT", "0")
