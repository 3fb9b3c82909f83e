"""The kernels' disk cache is read and written under a lock file (engine.jit.LockedCache), so several processes can
compile at once; ``python -m engine warm`` compiles the scenes' kernels in parallel processes."""

from __future__ import annotations

import fcntl
import importlib.util
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
from numba.core import caching

from engine import jit
from engine.cli import main

ROOT = Path(__file__).resolve().parents[2]


def _kernel_module(folder: Path, name: str):
    """A module of its own (numba caches per source file) with one cached kernel, ``scale``."""
    path = folder / f"{name}.py"
    path.write_text(textwrap.dedent("""
        from engine.jit import kernel

        @kernel
        def scale(x, k):
            out = x.copy()
            for i in range(x.shape[0]):
                out[i] = x[i] * k
            return out
        """))
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _held(folder: str) -> str:
    """How the lock file in ``folder`` is held by someone else right now: "exclusive", "shared" or "free"."""
    fd = os.open(os.path.join(folder, jit.LOCK_NAME), os.O_RDWR | os.O_CREAT)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return "exclusive"
        fcntl.flock(fd, fcntl.LOCK_UN)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return "shared"
        return "free"
    finally:
        os.close(fd)


def test_the_index_is_written_under_an_exclusive_lock_and_read_under_a_shared_one(tmp_path, monkeypatch):
    module = _kernel_module(tmp_path, "ecsfx_locked_kernel")
    assert isinstance(module.scale._cache, jit.LockedCache)
    folder = module.scale._cache.cache_path
    seen: list[tuple[str, str]] = []
    save_index, load_index = caching.IndexDataCacheFile._save_index, caching.IndexDataCacheFile._load_index

    def saving(self, overloads):
        seen.append(("save", _held(folder)))
        return save_index(self, overloads)

    def loading(self):
        if os.path.isdir(folder):
            seen.append(("load", _held(folder)))
        return load_index(self)

    monkeypatch.setattr(caching.IndexDataCacheFile, "_save_index", saving)
    monkeypatch.setattr(caching.IndexDataCacheFile, "_load_index", loading)
    assert np.array_equal(module.scale(np.arange(3.0), 2.0), [0.0, 2.0, 4.0])  # compiles and saves
    assert ("save", "exclusive") in seen
    assert all(held == "exclusive" for what, held in seen if what == "save")
    seen.clear()
    again = jit.kernel(module.scale.py_func)  # a fresh dispatcher: loads what was saved
    assert np.array_equal(again(np.arange(3.0), 3.0), [0.0, 3.0, 6.0])
    assert again.stats.cache_hits and not again.stats.cache_misses
    assert seen and all(held == "shared" for _, held in seen)
    assert _held(folder) == "free"


def test_processes_compiling_other_signatures_of_one_kernel_at_once_keep_both(tmp_path):
    # Each process compiles one signature of the same kernel (float64 and int64 arrays) while the other does. The
    # index must end up with both, each pointing at its own machine code: a third process loads them and gets
    # the right results without compiling.
    _kernel_module(tmp_path, "ecsfx_shared_kernel")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    env.pop("NUMBA_CACHE_DIR", None)
    compile_one = "import numpy as np, ecsfx_shared_kernel as m; print(m.scale(np.arange(4, dtype={}), 3).sum())"
    runs = [subprocess.Popen([sys.executable, "-c", compile_one.format(t)], env=env, stdout=subprocess.PIPE,
                             text=True) for t in ("np.float64", "np.int64")]
    assert [r.communicate(timeout=120)[0].strip() for r in runs] == ["18.0", "18"]
    check = textwrap.dedent("""
        import numpy as np, ecsfx_shared_kernel as m
        a, b = m.scale(np.arange(4.0), 3), m.scale(np.arange(4), 3)
        assert a.dtype == np.float64 and b.dtype == np.int64, (a.dtype, b.dtype)
        assert a.tolist() == [0.0, 3.0, 6.0, 9.0] and b.tolist() == [0, 3, 6, 9]
        print(sum(m.scale.stats.cache_hits.values()), sum(m.scale.stats.cache_misses.values()))
        """)
    done = subprocess.run([sys.executable, "-c", check], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["2", "0"]  # both loaded, none compiled


def test_warm_runs_each_scene_in_the_order_given_and_reports(capsys):
    scenes = [ROOT / "configs" / "scenes" / name for name in ("sandbox.toml", "dust_devil_showcase.toml")]
    assert main(["warm", *map(str, scenes), "--steps", "2", "--no-render", "--jobs", "1"]) == 0
    out = capsys.readouterr().out
    assert "2 scene(s), 2 ticks each, 1 process(es)" in out and "kernels ready" in out
    assert out.index("sandbox:") < out.index("dust_devil_showcase:")
    scenes.reverse()
    assert main(["warm", *map(str, scenes), "--steps", "2", "--no-render", "--jobs", "1"]) == 0
    out = capsys.readouterr().out
    assert out.index("dust_devil_showcase:") < out.index("sandbox:")
    assert main(["warm", str(scenes[1]), "--steps", "2", "--no-render", "--jobs", "2"]) == 0
    assert "1 scene(s), 2 ticks each, 1 process(es)" in capsys.readouterr().out  # never more processes than scenes


def test_warm_names_a_missing_scene_and_a_failing_run(tmp_path, capsys):
    assert main(["warm", str(tmp_path / "nope.toml")]) == 1
    assert "no such scene" in capsys.readouterr().err
    broken = tmp_path / "broken.toml"
    broken.write_text("[scene\n")
    assert main(["warm", str(broken), "--steps", "1", "--no-render"]) == 1
    err = capsys.readouterr().err
    assert "warm-up runs that failed" in err and "broken.toml" in err
