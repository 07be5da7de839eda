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
    {"errors", "rotations", "robust", "sampling", "ssim", "structure_tensor", "scene", "device", "heap", "atomic",
     "__init__"},
    {"segment", "geometry"},
    {"pointmaps"},
    {"align"},
    {"eval"},
    {"splat"},
    {"synth"},
    {"io", "mesh", "viz"},
    {"pipeline", "alignment_status", "prints", "working_scale", "working_window", "unseen_skin"},
    {"batch", "experiments"},
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


def _module_graph() -> dict[str, set[str]]:
    """fingersplat3d module -> the fingersplat3d modules it imports (anywhere in its body, lazily too)."""
    import ast

    modules = {}
    for path in (ROOT / "fingersplat3d").rglob("*.py"):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        modules[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    graph = {}
    for name, (path, is_package) in modules.items():
        base = name.split(".") if is_package else name.split(".")[:-1]
        targets = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                source = ".".join(base[:len(base) - node.level + 1] + [node.module] if node.module else
                                  base[:len(base) - node.level + 1]) if node.level else (node.module or "")
                targets |= {f"{source}.{alias.name}" if f"{source}.{alias.name}" in modules else source for alias in node.names}
            elif isinstance(node, ast.Import):
                targets |= {alias.name for alias in node.names}
        graph[name] = {target for target in targets if target in modules and target != name}
    return graph


def test_the_import_graph_has_no_circle():
    graph = _module_graph()
    assert "fingersplat3d.pointmaps.prior" in graph["fingersplat3d.pointmaps"]  # the graph sees package imports
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(module: str) -> None:
        state[module] = 1
        path.append(module)
        for target in sorted(graph[module]):
            assert state.get(target) != 1, "import circle: " + " -> ".join(path[path.index(target):] + [target])
            if target not in state:
                visit(target)
        path.pop()
        state[module] = 2

    for module in sorted(graph):
        if module not in state:
            visit(module)


def test_correspondences_sit_below_the_solvers():
    """align.correspond finds correspondences; align.solve and align.register use them, never the other way."""
    graph = _module_graph()
    for module, targets in graph.items():
        if module.startswith("fingersplat3d.align.correspond"):
            upward = {t for t in targets if t.startswith(("fingersplat3d.align.solve", "fingersplat3d.align.register"))}
            assert not upward, f"{module} imports {sorted(upward)}"


def test_the_front_page_is_short_and_each_command_has_a_small_module():
    readme = (ROOT / "README.md").read_text().splitlines()
    assert len(readme) <= 250, f"README.md has {len(readme)} lines; tables and method notes belong in docs/"
    for path in sorted((ROOT / "fingersplat3d" / "cli").glob("*.py")):
        lines = len(path.read_text().splitlines())
        assert lines <= 300, f"{path.name}: {lines} lines; one command per module, shared options in options.py"
    from fingersplat3d.cli.main import COMMANDS, EVAL_ACTIONS

    assert len(COMMANDS) + len(EVAL_ACTIONS) >= 11


def _anchors(markdown: str) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces to hyphens."""
    import re

    anchors = set()
    for line in markdown.splitlines():
        if line.startswith("#"):
            text = line.lstrip("#").strip().lower()
            anchors.add(re.sub(r"[^\w\- ]", "", text).replace(" ", "-"))
    return anchors


def test_every_link_of_the_readme_and_docs_resolves():
    """Relative links (files, pictures, #anchors in other pages) point at something that exists."""
    import re

    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    for page in pages:
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
            if target.startswith(("http://", "https://", "mailto:")):
                continue
            path_part, _, anchor = target.partition("#")
            resolved = (page.parent / path_part).resolve() if path_part else page
            assert resolved.exists(), f"{page.name}: link to {target} points at nothing"
            if anchor and resolved.suffix == ".md":
                assert anchor in _anchors(resolved.read_text()), f"{page.name}: no heading for #{anchor} in {resolved.name}"


def test_every_tool_script_imports():
    """The benchmark and figure scripts import (what they take from the package and from each other still
    exists): they are run by hand, so nothing else would notice a moved function."""
    import importlib.util
    import sys

    tools = ROOT / "tools"
    sys.path.insert(0, str(tools))
    try:
        for script in sorted(tools.glob("*.py")):
            spec = importlib.util.spec_from_file_location(f"tool_{script.stem}", script)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            assert hasattr(module, "main"), f"{script.name} has no main()"
    finally:
        sys.path.remove(str(tools))


def test_a_tool_given_bad_input_says_so_in_one_sentence(tmp_path):
    """Tool scripts end as fs3d's commands do (errors.run_script): bad input is one line on stderr and exit 2."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, str(ROOT / "tools" / "bench_real.py"), "--data", str(tmp_path)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr and done.stderr.strip().count("\n") == 0
    assert done.stderr.startswith("bench_real: error:") and str(tmp_path) in done.stderr
