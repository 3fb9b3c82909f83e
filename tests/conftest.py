import pytest

from tests import render_utils


def pytest_addoption(parser):
    parser.addoption("--regen-golden", action="store_true", default=False,
                     help="rewrite the golden reference images of the render tests")


def pytest_configure(config):
    if config.getoption("--regen-golden"):
        render_utils.REGEN["on"] = True


@pytest.fixture
def gl_ctx():
    return render_utils.gl_context()
