"""Simulation code computes its transcendental functions with engine.exact, never numpy's or the C library's.

numpy picks SIMD code for ``np.exp``, ``np.arctan2``, ``np.power`` and others by the CPU, and ``np.sin`` or
``math.sin`` are the C library's: their last bits differ between machines, and a state hash with them. Products of
vectors and matrices through BLAS (``@``, ``np.dot``, ``np.linalg``) differ by CPU too (OpenBLAS picks its kernels
by it). Every module that decides state (positions, velocities, contacts, what a pointer picks, the game's rules)
is scanned here for such a call; the rendering modules (pictures only)
and the grass field (it draws, it keeps no state that is hashed) are not.
"""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

FUNCTIONS = {"sin", "cos", "tan", "hypot", "exp", "exp2", "expm1", "log", "log2", "log10", "log1p", "power", "pow",
             "float_power", "cbrt", "arcsin", "arccos", "arctan", "arctan2", "asin", "acos", "atan", "atan2",
             "sinh", "cosh", "arcsinh", "arccosh", "arctanh", "asinh", "acosh", "atanh", "erf", "gamma", "lgamma"}
DRAWING = {"render.py", "extract.py", "mesh.py", "display.py", "textures.py", "images.py", "gallery.py", "docgen.py",
           "exact.py"}  # files of the scanned folders that only draw or document (exact.py: the functions themselves)


def _state_modules() -> list[Path]:
    paths = [*ROOT.glob("engine/*.py"), ROOT / "engine" / "render" / "components.py",
             ROOT / "engine" / "render" / "lighting.py", *ROOT.glob("components/*.py"), *ROOT.glob("game_demo/**/*.py")]
    for effect in ("energy_wave", "toon_smoke", "water_surface", "dust_devil"):
        paths += ROOT.glob(f"systems/{effect}/*.py")
    return sorted(p for p in paths if p.name not in DRAWING)


BLAS = {"dot", "matmul", "inner", "vdot", "tensordot"}  # numpy calls that hand work to BLAS


def _calls(path: Path, root: Path = ROOT) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        where = f"{path.relative_to(root)}:{getattr(node, 'lineno', 0)}"
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult):
            found.append(f"{where}: @")
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)):
            continue
        owner, name = node.func.value, node.func.attr
        if isinstance(owner, ast.Name) and owner.id in ("np", "numpy", "math") and name in FUNCTIONS:
            found.append(f"{where}: {owner.id}.{name}")
        elif isinstance(owner, ast.Name) and owner.id in ("np", "numpy") and name in BLAS:
            found.append(f"{where}: {owner.id}.{name}")
        elif isinstance(owner, ast.Attribute) and owner.attr == "linalg":  # LAPACK and BLAS through OpenBLAS
            if not (name == "norm" and any(k.arg == "axis" for k in node.keywords)):  # along an axis: a reduction
                found.append(f"{where}: linalg.{name}")
    return found


def test_state_code_uses_engine_exact_for_transcendental_functions_and_products():
    modules = _state_modules()
    assert len(modules) > 40 and any(p.name == "tornado.py" for p in modules)
    found = [call for path in modules for call in _calls(path)]
    assert found == [], "use engine.exact's function instead:\n" + "\n".join(found)


def test_the_scan_finds_such_a_call(tmp_path):
    path = tmp_path / "probe.py"
    path.write_text("import math\nimport numpy as np\nx = np.sin(1.0) + math.atan2(1.0, 2.0) + np.sqrt(2.0)\n"
                    "m = np.linalg.pinv(np.eye(2)) @ np.dot(np.ones(2), np.ones(2)) + np.multiply(2.0, 3.0)\n")
    assert sorted(c.split(": ")[-1] for c in _calls(path, tmp_path)) == ["@", "linalg.pinv", "math.atan2", "np.dot",
                                                                          "np.sin"]
