"""``python -m engine warm``: compile the kernels the scenes use ahead of their first run, on every core.

The effects' compiled kernels (:mod:`engine.jit`) compile on first use and are cached on disk; on a fresh
machine that first use costs about two and a half minutes of one core, spent inside whatever ran first: the demo's first
frame, or the first test that ticks an effect. This command runs each scene given to it for a few ticks, rendered
headless at a small size (the grass's frame plan is compiled in the render path), as separate processes, several at
once. Each process compiles what its scene needs; the cache's lock file (:class:`engine.jit.LockedCache`) makes
processes that compile the same helper at once safe. The scenes start in the order given.

With the cache already filled it only loads, a few seconds a scene. ``make demo`` and ``make test`` run it once per
change of the sources (a stamp file in the virtual environment).
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from engine import jit


def warm_command(scenes: list[Path], jobs: int | None, steps: int, headless: bool = True) -> int:
    """Run ``scenes`` for ``steps`` ticks each in up to ``jobs`` processes, started in the order given (list the
    dearest first, so the processes finish together; a scene that uses every effect's kernels last, so it loads
    what the others compiled instead of compiling it beside them); 0 if every run exits 0, else 1 (and the
    failing runs' last lines). The kernels stay compiled either way for the runs that got there."""
    missing = [s for s in scenes if not s.is_file()]
    if missing:
        print(f"error: no such scene: {', '.join(map(str, missing))}", file=sys.stderr)
        return 1
    if not jit.CAN_LOCK:
        jobs = 1  # no lock file on this platform: one process, as numba expects
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(scenes)))
    print(f"compiling the effects' kernels: {len(scenes)} scene(s), {steps} ticks each, {jobs} process(es) "
          "(about a minute per core on a fresh machine; seconds once cached)", flush=True)
    lock = threading.Lock()
    failures: list[str] = []
    start = time.perf_counter()

    def run(scene: Path) -> None:
        t = time.perf_counter()
        command = [sys.executable, "-m", "engine", "run", str(scene), "--steps", str(steps)]
        command += ["--headless", "--size", "160", "96"] if headless else ["--no-render"]
        done = subprocess.run(command, capture_output=True, text=True)
        with lock:
            if done.returncode == 0:
                print(f"  {scene.stem}: {time.perf_counter() - t:.1f} s", flush=True)
            else:
                tail = "\n    ".join((done.stderr or done.stdout).strip().splitlines()[-5:])
                failures.append(f"{scene}: exit {done.returncode}\n    {tail}")

    with ThreadPoolExecutor(max_workers=jobs) as pool:
        list(pool.map(run, scenes))
    if failures:
        print("warm-up runs that failed (their kernels compile on first use instead):\n  " + "\n  ".join(failures),
              file=sys.stderr)
        return 1
    print(f"kernels ready in {time.perf_counter() - start:.1f} s", flush=True)
    return 0
