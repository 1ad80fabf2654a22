"""Shared fixtures: every test that needs Taichi runs on the arch given by --arch (cpu by
default), initialised once per session through lss_kernels.kernels.backend."""
import pytest


def pytest_addoption(parser):
    parser.addoption("--arch", default="cpu", help="Taichi arch for kernel tests")
    parser.addoption("--runslow", action="store_true", help="run tests marked slow")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow: pass --runslow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def ti_arch(request):
    from lss_kernels.kernels import backend
    return backend.init(arch=request.config.getoption("--arch"))
