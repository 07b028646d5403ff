"""The package's folders are layers: a module imports only from its own folder or from below."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "montecarlo"

LAYERS = (
    ("units", "errors", "lsq", "jit"),
    ("geometry",),
    ("seed000", "seed001", "seed003", "camera_calibration"),
    ("io",),
    ("engine",),
    ("discrepancy",),
    ("systems",),
    ("output",),
    ("design",),
    ("tools",),
    ("cli", "api"),
    ("__init__", "__main__"),
)
"""Bottom to top. Folders on one line are peers: they import neither each other nor above."""
RANK = {name: i for i, names in enumerate(LAYERS) for name in names}


def _unit(module: str) -> str:
    """Layer unit of a dotted module name below ``montecarlo``: its folder or top module."""
    return module.split(".")[1] if "." in module else "__init__"


def _imports(source: str, module: str, is_package: bool = False) -> list[tuple[int, str]]:
    """(line, absolute module) of every montecarlo import in ``source``, lazy ones included."""
    package = module if is_package else module.rsplit(".", 1)[0]
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                name = ".".join([*base, node.module] if node.module else base)
            else:
                name = node.module or ""
            targets = [f"{name}.{a.name}" for a in node.names] if name == "montecarlo" \
                else [name]
        elif isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        else:
            continue
        found += [(node.lineno, t) for t in targets if t.split(".")[0] == "montecarlo"]
    return found


def _module(path: Path) -> str:
    return ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)


FILES = sorted(PACKAGE.rglob("*.py"))


def test_every_folder_and_top_module_has_a_layer():
    units = {p.parent.name if p.parent != PACKAGE else p.stem for p in FILES}
    assert units <= set(RANK), units - set(RANK)


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_go_down_only(path):
    own = path.parent.name if path.parent != PACKAGE else path.stem
    bad = []
    for line, target in _imports(path.read_text(), _module(path), path.name == "__init__.py"):
        unit = _unit(target)
        if unit == "__version__" or (target == "montecarlo" and own != "__init__"):
            continue
        if unit != own and RANK[unit] >= RANK[own]:
            bad.append(f"line {line}: {target}")
    assert not bad, f"{path.relative_to(PACKAGE)} imports from its layer or above: {bad}"


def test_the_check_sees_relative_lazy_and_aliased_imports():
    """A check that cannot fail is none: the parser must see every form of import."""
    source = ("def f():\n    from montecarlo.engine import runner as r\n"
              "from ..cli import main\nfrom montecarlo import units\nimport montecarlo.io.files\n")
    found = sorted(t for _, t in _imports(source, "montecarlo.geometry.probe"))
    assert found == ["montecarlo.cli", "montecarlo.engine", "montecarlo.io.files",
                     "montecarlo.units"]
