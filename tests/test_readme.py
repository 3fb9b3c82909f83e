"""The README's examples run as written: its headless-testing example is executed and its tests called."""

import os
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _section_code(title: str) -> str:
    text = (ROOT / "README.md").read_text()
    section = text.split(f"## {title}\n", 1)[1].split("\n## ", 1)[0]
    (code,) = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    return code


def test_the_headless_testing_example_passes(monkeypatch):
    monkeypatch.chdir(ROOT)  # the example names the scene from the repository's root, as a user's test would
    namespace: dict = {"__name__": "readme_example"}
    exec(compile(_section_code("Testing a game headless"), "README.md", "exec"), namespace)
    tests = [f for name, f in namespace.items() if name.startswith("test_") and callable(f)]
    assert len(tests) == 3
    for test in tests:
        test()
    assert os.getcwd() == str(ROOT)
