"""docs/extending.md's worked example runs as written: its files are written to a folder, its Python snippet and its
tests run there, and so do its command lines (``--plugin``), with this checkout's engine."""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "extending.md"
FILES = ("mygame.py", "scene.toml", "test_mygame.py")


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)


def example_files() -> dict[str, str]:
    """The example's files: the code blocks whose first line is a comment naming the file (``# mygame.py``)."""
    files = {}
    for block in _blocks("python") + _blocks("toml"):
        first, _, body = block.partition("\n")
        named = re.fullmatch(r"# ([\w.]+\.(?:py|toml))", first.strip())
        if named:
            assert named.group(1) not in files, f"{named.group(1)} appears twice in {DOC.name}"
            files[named.group(1)] = body
    return files


def _sh(command: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # the engine of this checkout, as the example's folder sees it
    return subprocess.run(command, capture_output=True, text=True, cwd=cwd, env=env, timeout=timeout)


@pytest.fixture(scope="module")
def game(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("game")
    for name, text in example_files().items():
        (folder / name).write_text(text, encoding="utf-8")
    return folder


def test_the_example_is_complete():
    assert sorted(example_files()) == sorted(FILES)


def test_the_example_tests_pass(game):
    done = _sh([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_mygame.py"], game)
    assert done.returncode == 0, done.stdout + done.stderr
    assert re.search(r"\b5 passed\b", done.stdout), done.stdout


def test_the_python_api_snippet_runs(game):
    [snippet] = [b for b in _blocks("python") if "registry.install(mygame.plugin)" in b and "def " not in b]
    done = _sh([sys.executable, "-c", snippet + "\napp.step(5)\nprint(app.state_hash())\n"], game)
    assert done.returncode == 0, done.stderr
    assert re.fullmatch(r"[0-9a-f]{32}", done.stdout.split()[-1])


def test_the_command_lines_run(game):
    lines = [line.split("#")[0].strip() for block in _blocks("sh") for line in block.splitlines()]
    commands = [line for line in lines if line.startswith("python -m engine ")]
    assert "python -m engine run scene.toml --plugin mygame" in commands
    assert "python -m engine run scene.toml --plugin mygame:MyGamePlugin" in commands
    runnable = [c for c in commands if " validate " in c or "--no-render" in c or "--print-schedule" in c]
    assert len(runnable) == 3, runnable
    hashes = []
    for command in runnable:
        argv = [sys.executable, *shlex.split(command)[1:]]
        done = _sh(argv, game)
        assert done.returncode == 0, f"{command}\n{done.stderr}"
        if "--hash" in command:
            hashes.append(done.stdout.split()[-1])
            again = _sh(argv, game)  # the same scene and seed: the same state
            assert again.stdout.split()[-1] == hashes[-1]
        if " validate " in command:
            assert "1 ok" in done.stdout
        if "--print-schedule" in command:
            assert "mygame.pulse" in done.stdout and "mygame.collect" in done.stdout
    assert len(hashes) == 1 and re.fullmatch(r"[0-9a-f]{32}", hashes[0])
    # the explicit MODULE:ATTR form names the same plugin: the same state
    explicit = _sh([sys.executable, "-m", "engine", "run", "scene.toml", "--plugin", "mygame:MyGamePlugin",
                    "--no-render", "--steps", "300", "--hash"], game)
    assert explicit.returncode == 0 and explicit.stdout.split()[-1] == hashes[0], explicit.stderr
