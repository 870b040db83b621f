"""The layout of docs/architecture.md, checked on the source: imports point downwards, a codec
family imports no other family, the coding building blocks know nothing of motions, and no
module takes another module's private names."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

PACKAGE = Path(__file__).parent.parent / "src" / "mocodec"

# the layers of docs/architecture.md, lowest first: a module imports only from its own area
# (a top-level module or package of mocodec) or from areas of lower layers
LAYERS = [
    {"version", "errors", "limits", "jsonable", "data", "kernels"},
    {"extras", "sandbox", "rotations", "bodyparts", "crowd"},
    {"skeleton"},
    {"kinematics"},
    {"motion", "perception"},
    {"human", "reexpress", "mannequin"},
    {"formats", "metrics", "coding", "analysis"},
    {"codecs"},
    {"moc"},
    {"ratecontrol"},
    {"scene"},
    {"stream", "bench", "capture", "numcodecs"},
    {"zarr3"},
    {"viewer"},
    {"cli"},
    {"__init__", "__main__"},
]
LAYER = {area: k for k, group in enumerate(LAYERS) for area in group}
SHARED_BY_FAMILIES = {"base", "registry", "shared"}  # what every codec family may import


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        yield name, path, ast.parse(path.read_text(), str(path))


def _imports(tree):
    """(module imported from, name) of every ``from mocodec... import`` in ``tree``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module and node.module.startswith("mocodec"):
            for alias in node.names:
                yield node.module, alias.name
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("mocodec"):
                    yield alias.name, ""


def _target(module: str, name: str) -> str:
    """The module an import reaches: ``module.name`` when that is a module, else ``module``."""
    full = f"{module}.{name}"
    rel = Path(*full.split(".")[1:])
    return full if (PACKAGE / rel).with_suffix(".py").exists() or (PACKAGE / rel).is_dir() else module


def _area(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


MODULES = list(_modules())


def test_every_area_has_a_layer():
    assert {_area(name) for name, _, _ in MODULES} <= set(LAYER)


@pytest.mark.parametrize("name,path,tree", MODULES, ids=[m[0] for m in MODULES])
def test_imports_point_downwards(name, path, tree):
    area = _area(name)
    for module, imported in _imports(tree):
        target = _area(_target(module, imported))
        assert target == area or LAYER[target] < LAYER[area], f"{name} imports {module}.{imported}"


@pytest.mark.parametrize("name,path,tree", MODULES, ids=[m[0] for m in MODULES])
def test_codec_families_import_no_other_family(name, path, tree):
    parts = name.split(".")
    if len(parts) < 4 or parts[1] != "codecs":
        return
    family = parts[2]
    for module, imported in _imports(tree):
        target = _target(module, imported).split(".")
        if len(target) > 2 and target[1] == "codecs" and len(target) > 2:
            assert target[2] in SHARED_BY_FAMILIES | {family}, f"{name} imports {'.'.join(target)}"


#: The tests and benchmarks keep to the rule too: what they reach is public.
TESTS = [
    (str(p.relative_to(PACKAGE.parent.parent)), p, ast.parse(p.read_text(), str(p)))
    for folder in ("tests", "benchmarks")
    for p in sorted((PACKAGE.parent.parent / folder).rglob("*.py"))
]


@pytest.mark.parametrize("name,path,tree", MODULES + TESTS, ids=[m[0] for m in MODULES + TESTS])
def test_no_private_names_across_modules(name, path, tree):
    for module, imported in _imports(tree):
        if module != name and imported.startswith("_") and not imported.startswith("__"):
            pytest.fail(f"{name} imports the private {module}.{imported}")
        if module != name and module.split(".")[-1].startswith("_") and module.split(".")[-1] != "__init__":
            pytest.fail(f"{name} imports the private module {module}")
    imported_modules = {alias for module, alias in _imports(tree) if _target(module, alias) != module}
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in imported_modules
            and node.attr.startswith("_")
            and not node.attr.startswith("__")
        ):
            pytest.fail(f"{name}:{node.lineno} uses the private {node.value.id}.{node.attr}")


NETWORK = {"asyncio", "aiohttp", "nats", "socket"}


@pytest.mark.parametrize("name,path,tree", MODULES, ids=[m[0] for m in MODULES])
def test_the_relay_core_has_no_network_code(name, path, tree):
    """Only the relay's server and its workers speak to the network: its core, state, cutting,
    retention and limits are plain code that tests, the fuzzer and the tick benchmark drive."""
    if not name.startswith("mocodec.stream.relay") or name.rsplit(".", 1)[-1] in ("server", "workers"):
        return
    for node in ast.walk(tree):
        names = (
            [alias.name for alias in node.names]
            if isinstance(node, ast.Import)
            else [node.module or ""]
            if isinstance(node, ast.ImportFrom)
            else []
        )
        for imported in names:
            assert imported.split(".")[0] not in NETWORK, f"{name} imports {imported}"
            assert not imported.startswith(("mocodec.stream.relay.server", "mocodec.stream.relay.workers")), name


def test_the_picture_names_every_module():
    """docs/architecture.md draws the layout: every package and module of mocodec is named in
    its picture."""
    doc = (PACKAGE.parent.parent / "docs" / "architecture.md").read_text()
    picture = doc.split("```")[1]
    words = set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", picture))
    missing = []
    for path in sorted(PACKAGE.rglob("*.py")):
        name = path.parent.name if path.stem == "__init__" else path.stem
        if name not in words and path.stem not in ("__init__", "__main__"):
            missing.append(str(path.relative_to(PACKAGE)))
    for path in sorted(p for p in PACKAGE.rglob("*") if p.is_dir() and (p / "__init__.py").exists()):
        if path.name not in words:
            missing.append(str(path.relative_to(PACKAGE)) + "/")
    assert not missing, f"not in docs/architecture.md's picture: {missing}"
