"""The engine runs BLAS on one thread unless ECSFX_BLAS_THREADS says otherwise (checked in fresh processes)."""

import json
import subprocess
import sys

CHECK = """
import json, threadpoolctl
from engine import exact
from engine.app import App
App()
exact.sin(1.0)  # a compiled kernel's first call loads numba's BLAS (scipy's OpenBLAS): limited too
print(json.dumps([pool["num_threads"] for pool in threadpoolctl.threadpool_info() if pool["user_api"] == "blas"]))
"""


def _blas_threads(env_value: str | None) -> list[int]:
    import os

    env = {k: v for k, v in os.environ.items() if k not in ("ECSFX_BLAS_THREADS", "OPENBLAS_NUM_THREADS",
                                                            "OMP_NUM_THREADS")}
    if env_value is not None:
        env["ECSFX_BLAS_THREADS"] = env_value
    out = subprocess.run([sys.executable, "-c", CHECK], capture_output=True, text=True, env=env, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_an_app_limits_blas_to_one_thread():
    assert _blas_threads(None) and set(_blas_threads(None)) == {1}


def test_the_environment_overrides_the_limit():
    import os

    assert set(_blas_threads("2")) == {2}
    if (os.cpu_count() or 1) > 1:
        assert max(_blas_threads("auto")) > 1  # left alone: OpenBLAS's own default, one per core
