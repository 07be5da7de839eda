"""Open an ``fs3d batch`` report in a real headless browser and check that every picture loads.

    python3 tools/check_report.py OUT/report.html [--browser chromium]

Chromium (Debian: ``apt-get install chromium``) loads the page from disk, runs its one script
(which counts the pictures that failed to load) and prints the resulting DOM
(:func:`fingersplat3d.batch.results.browser_check`); exits 0 when the page has pictures and none is
broken, 1 otherwise, 2 when no browser is found. ``tests/test_batch.py`` runs the same check when a
browser is installed.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fingersplat3d.batch.results import browser_check, find_browser
from fingersplat3d.errors import run_script


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("report", type=Path)
    parser.add_argument("--browser")
    args = parser.parse_args()
    browser = find_browser(args.browser)
    if browser is None:
        print("check_report: no headless browser found (install chromium)", file=sys.stderr)
        return 2
    images, broken = browser_check(args.report, browser)
    print(f"{args.report}: {images} pictures, {broken} broken ({Path(browser).name})")
    return 0 if images and not broken else 1


if __name__ == "__main__":
    sys.exit(run_script(main))
