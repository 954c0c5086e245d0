"""The package's layers (docs/architecture.md): every import of a parcelfit module points to its
own layer or one below; the optimisers know nothing of simulators or studies."""

import ast
import os
import subprocess
import sys
from pathlib import Path

import parcelfit

PACKAGE = Path(parcelfit.__file__).parent

# bottom up; within the foundation, application and presentation layers modules may import each
# other, in the others a package imports only itself and the layers below
LAYERS = [
    {"__init__", "errors", "atomic", "schema", "config", "figures", "progress"},
    {"runs", "data"},
    {"metrics", "stats", "doe"},
    {"tracking", "sim", "optimize"},
    {"study"},
    {"analysis", "synth", "simulate", "demo", "report"},
    {"cli", "__main__"},
]
RANK = {unit: k for k, layer in enumerate(LAYERS) for unit in layer}
SHARED = {0, 5, 6}


def _unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _imports(path: Path) -> list[str]:
    """Every parcelfit module ``path`` imports, at the top or inside a function."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("parcelfit"):
            if node.module == "parcelfit":
                out += [f"parcelfit.{a.name}" for a in node.names if a.name != "__version__"]
                out += ["parcelfit"] * any(a.name == "__version__" for a in node.names)
            else:
                out.append(node.module)
        elif isinstance(node, ast.Import):
            out += [a.name for a in node.names if a.name.startswith("parcelfit")]
    return out


def _modules() -> list[tuple[str, Path]]:
    return [
        (_unit("parcelfit." + ".".join(p.relative_to(PACKAGE).with_suffix("").parts)), p)
        for p in sorted(PACKAGE.rglob("*.py"))
    ]


def test_every_unit_has_a_layer():
    assert {unit for unit, _ in _modules()} <= set(RANK)


def test_imports_point_to_the_same_layer_or_below():
    wrong = []
    for unit, path in _modules():
        for target in _imports(path):
            to = _unit(target)
            if to == unit or RANK[to] < RANK[unit]:
                continue
            if RANK[to] == RANK[unit] and RANK[unit] in SHARED:
                continue
            wrong.append(f"{path.relative_to(PACKAGE)} imports {target}")
    assert not wrong


def test_optimize_imports_nothing_of_sim_or_study():
    for path in sorted((PACKAGE / "optimize").glob("*.py")):
        assert [t for t in _imports(path) if _unit(t) in ("sim", "study")] == [], path.name
    # and nothing reaches it indirectly: importing the optimisers loads no simulator or study
    code = (
        "import sys\n"
        "import parcelfit.optimize, parcelfit.optimize.bo, parcelfit.optimize.sampler\n"
        "import parcelfit.optimize.space, parcelfit.optimize.optuna_sampler\n"
        "print(sorted(m for m in sys.modules if m.startswith"
        "(('parcelfit.sim', 'parcelfit.study', 'mujoco', 'parcelfit.metrics', 'parcelfit.runs'))))\n"
    )
    path = [str(PACKAGE.parent), os.environ.get("PYTHONPATH", "")]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in path if p)}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    ).stdout
    assert out.strip() == "[]"
