"""Repository hygiene: CI runs exactly the README's test command; the install script pins torch."""
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_ci_runs_the_readme_test_command():
    ci_lines = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()]
    command = next(line for line in ci_lines if "pytest" in line)
    assert command in (ROOT / "README.md").read_text()


def test_install_script_pins_the_cpu_torch_build():
    script = (ROOT / "tools" / "install.sh").read_text()
    assert "torch==2.13.0" in script and "libusb-1.0-0" in script
    assert "torchvision" not in (ROOT / "setup.cfg").read_text()


# The layers of docs/architecture.md, lowest first: a module imports only from its own layer or below.
LAYERS = [
    {"errors", "rotations", "sampling", "scene", "device", "atomic", "__init__"},
    {"segment", "geometry"},
    {"pointmaps"},
    {"align"},
    {"eval"},
    {"splat"},
    {"synth"},
    {"io", "mesh", "viz"},
    {"pipeline"},
    {"cli"},
]


def _imports() -> dict[str, set[str]]:
    """Top-level part of fingersplat3d each module imports (relative and absolute), by module."""
    import ast

    package = ROOT / "fingersplat3d"
    found = {}
    for path in package.rglob("*.py"):
        parts = list(path.relative_to(package).with_suffix("").parts)
        module_parts = parts[:-1] if parts[-1] == "__init__" else parts
        targets = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level:
                base = parts[: len(parts) - node.level]  # level 1: the module's own package
                target = base + (node.module.split(".") if node.module else [])
                targets.add(target[0] if target else "__init__")
            elif isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("fingersplat3d."):
                targets.add(node.module.split(".")[1])
        found[".".join(module_parts) or "__init__"] = targets
    return found


def test_imports_run_down_the_layers_and_make_no_circle():
    layer = {name: index for index, names in enumerate(LAYERS) for name in names}
    for module, targets in _imports().items():
        own = module.split(".")[0]
        assert own in layer, f"{module}: its package {own!r} is in no layer of docs/architecture.md"
        for target in targets - {own}:
            assert target in layer, f"{module} imports {target!r}, which is in no layer"
            assert layer[target] <= layer[own], f"{module} imports {target} from a higher layer"
    layers_doc = (ROOT / "docs" / "architecture.md").read_text()
    assert all(f"`{name}`" in layers_doc for names in LAYERS for name in names - {"__init__"})
