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
