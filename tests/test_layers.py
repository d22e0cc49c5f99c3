"""The package's layers: data flows one way, morphology → env → replay → synergy and
networks → agent → training → viz → the command line → benchmarks → commands, and no
module imports one above it.

Every import is read from the source (``ast``, those inside functions too), so a lazy
import cannot hide a cycle."""

import ast
from pathlib import Path

from tests.conftest import REPO

PACKAGE = REPO / "solar_jax"

LAYERS = (
    ("support", ("solar_jax", "solar_jax.config", "solar_jax.xla",
                 "solar_jax.stats", "solar_jax.files")),
    ("morphology", ("solar_jax.morphology",)),
    ("env", ("solar_jax.env",)),
    ("replay", ("solar_jax.replay",)),
    ("synergy", ("solar_jax.synergy",)),
    ("networks", ("solar_jax.networks",)),
    ("agent", ("solar_jax.agent",)),
    ("training", ("solar_jax.training",)),
    ("viz", ("solar_jax.viz",)),
    ("command line", ("solar_jax.cli", "solar_jax.experiments")),
    ("benchmarks", ("solar_jax.bench",)),
    ("commands", COMMANDS := ("solar_jax.train", "solar_jax.sweep", "solar_jax.rollout",
                              "solar_jax.plot", "solar_jax.evaluate",
                              "solar_jax.morphology.__main__",
                              "solar_jax.bench.__main__")),
)  # fmt: skip
"""Lowest first; a module is in the layer of its longest matching name."""


def _layer(module: str) -> int:
    matches = [
        (len(name), index)
        for index, (_, names) in enumerate(LAYERS)
        for name in names
        if module == name or module.startswith(name + ".")
    ]
    assert matches, f"{module} is in no layer of tests/test_layers.py"
    return max(matches)[1]


def _module(path: Path) -> str:
    parts = path.relative_to(REPO).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found.add(node.module)
    return {name for name in found if name.split(".")[0] == "solar_jax"}


def test_no_module_imports_one_above_it_and_commands_import_no_command():
    problems = []
    modules = sorted(PACKAGE.rglob("*.py"))
    assert len(modules) > 50
    for path in modules:
        module = _module(path)
        own = _layer(module)
        for imported in _imports(path):
            if _layer(imported) > own:
                above = LAYERS[_layer(imported)][0]
                problems.append(f"{module} ({LAYERS[own][0]}) imports {imported} ({above})")
            elif module in COMMANDS and imported in COMMANDS and imported != module:
                problems.append(f"command {module} imports command {imported}")
    assert not problems, "\n".join(problems)


def test_the_configuration_is_a_leaf():
    assert _imports(PACKAGE / "config.py") == set()


def test_the_check_sees_a_lazy_import_from_above(tmp_path):
    path = tmp_path / "solar_jax" / "env" / "bad.py"
    path.parent.mkdir(parents=True)
    path.write_text("def f():\n    from solar_jax.training.trainer import Trainer\n")
    assert _imports(path) == {"solar_jax.training.trainer"}
    assert _layer("solar_jax.training.trainer") > _layer("solar_jax.env.bad")
