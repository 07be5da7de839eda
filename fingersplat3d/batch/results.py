"""The results of a dataset run: ``results.csv`` (one row per capture) and ``report.html`` (a thumbnail row each).

Both are rebuilt from what is on disk (each complete capture's ``batch.json``, each failure's
``.failed/<capture>.json``), so they always describe exactly the finished work, also after an
interrupted run; both are written atomically. The HTML page is self-contained apart from the
thumbnails, which it links by relative path inside the output folder (photos, depth maps, novel
views), so the folder can be moved or served as it is.
"""
from __future__ import annotations

import csv
import html
import io
import json
import statistics
from pathlib import Path

from ..atomic import atomic_path
from .task import FAILED, ROW_FILE

__all__ = ["COLUMNS", "collect_rows", "write_results", "summary", "find_browser", "browser_check"]

COLUMNS = ("capture", "status", "reason", "seconds", "peak_rss_mb", "residual_px", "focal_px", "views", "gaussians",
           "rig_angles_deg")


def collect_rows(out: Path, names: list[str] | None = None) -> list[dict]:
    """One row per capture found in ``out`` (complete or failed): ``names``' order first (this run's
    dataset order), then any others from earlier runs, sorted."""
    out = Path(out)
    rows = {}
    for path in sorted(out.glob(f"*/{ROW_FILE}")):
        if not path.parent.name.startswith("."):
            rows[path.parent.name] = json.loads(path.read_text())
    for path in sorted((out / FAILED).glob("*.json")):
        rows.setdefault(path.stem, json.loads(path.read_text()))
    order = [name for name in (names or []) if name in rows]
    return [rows[name] for name in order + sorted(set(rows) - set(order))]


def summary(rows: list[dict]) -> dict:
    done = [r for r in rows if r["status"] == "done"]
    seconds = [r["seconds"] for r in rows if r.get("seconds") is not None]
    return {"captures": len(rows), "done": len(done), "not_registered": sum(r["status"] == "not_registered" for r in rows),
            "failed": sum(r["status"] == "failed" for r in rows),
            "median_seconds": statistics.median(seconds) if seconds else None,
            "max_peak_rss_mb": max((r["peak_rss_mb"] for r in rows if r.get("peak_rss_mb") is not None), default=None)}


def _csv_text(rows: list[dict]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({key: json.dumps(value) if isinstance(value, dict) else ("" if value is None else value)
                         for key, value in row.items()})
    return buffer.getvalue()


def _images(out: Path, name: str) -> list[tuple[str, str]]:
    """(relative path, caption) of the capture's thumbnails: the fuse's overview, photos, depth maps, a few novel
    views."""
    folder = out / name
    pictures = [(folder / "overview.png", "overview")] if (folder / "overview.png").is_file() else []
    pictures += [(p, f"photo {p.stem}") for p in sorted((folder / "thumbs").glob("*.png"))]
    pictures += [(p, f"depth {p.stem[:-6]}") for p in sorted((folder / "depth").glob("*_color.png"))]
    renders = sorted(p for p in (folder / "renders").glob("arc_*.png") if not p.stem.endswith("_alpha"))
    if renders:
        pictures += [(p, f"novel {p.stem}") for p in (renders[0], renders[len(renders) // 2], renders[-1])]
    return [(str(p.relative_to(out)), caption) for p, caption in pictures]


def _html_text(out: Path, rows: list[dict], info: dict) -> str:
    head = summary(rows)
    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8"><title>fs3d batch report</title>',
             "<style>body{font-family:sans-serif;margin:1em}table{border-collapse:collapse}td,th{border:1px solid #ccc;"
             "padding:4px;vertical-align:top}img{height:120px;margin:2px}figure{display:inline-block;margin:0 4px}"
             "figcaption{font-size:11px;text-align:center}.failed{background:#fee}.not_registered{background:#ffe}</style>",
             "</head><body>", "<h1>fs3d batch report</h1>",
             "<p>" + html.escape(", ".join(f"{k.replace('_', ' ')}: {v}" for k, v in {**head, **info}.items())) + "</p>",
             "<table><tr><th>capture</th><th>status</th><th>time (s)</th><th>peak RSS (MB)</th><th>residual (px)</th>"
             "<th>pictures</th></tr>"]
    for row in rows:
        pictures = "".join(f'<figure><img src="{html.escape(src)}" alt="{html.escape(caption)}"><figcaption>'
                           f"{html.escape(caption)}</figcaption></figure>" for src, caption in _images(out, row["capture"]))
        status = html.escape(row["status"] + (f": {row['reason']}" if row.get("reason") else ""))
        cells = [html.escape(row["capture"]), status] + ["" if row.get(k) is None else html.escape(f"{row[k]:.2f}" if isinstance(row[k], float) else str(row[k]))
                                                         for k in ("seconds", "peak_rss_mb", "residual_px")]
        parts.append(f'<tr class="{html.escape(row["status"])}">' + "".join(f"<td>{c}</td>" for c in cells) + f"<td>{pictures}</td></tr>")
    parts += ["</table>",
              # for a headless-browser check (tools/check_report.py): how many pictures failed to load
              "<script>window.addEventListener('load', () => { document.body.dataset.brokenImages = "
              "[...document.images].filter(i => !i.complete || i.naturalWidth === 0).length; "
              "document.body.dataset.images = document.images.length; });</script>",
              "</body></html>", ""]
    return "\n".join(parts)


def write_results(out: Path, names: list[str] | None = None, info: dict | None = None) -> list[dict]:
    """Rewrite ``results.csv`` and ``report.html`` in ``out`` from the captures on disk; returns the rows."""
    out = Path(out)
    rows = collect_rows(out, names)
    with atomic_path(out / "results.csv") as temporary:
        temporary.write_text(_csv_text(rows), encoding="utf-8")
    with atomic_path(out / "report.html") as temporary:
        temporary.write_text(_html_text(out, rows, info or {}), encoding="utf-8")
    return rows


def find_browser(name: str | None = None) -> str | None:
    """A headless-capable browser on the PATH (chromium first), or None."""
    import shutil

    for candidate in ([name] if name else ["chromium", "chromium-browser", "google-chrome", "chrome"]):
        if candidate and shutil.which(candidate):
            return shutil.which(candidate)
    return None


def browser_check(report: Path, browser: str) -> tuple[int, int]:
    """Load ``report`` in ``browser`` (headless) and return (pictures, pictures that failed to load).

    The page's own script counts them once loaded; the browser prints the resulting DOM.
    """
    import re
    import subprocess

    command = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--allow-file-access-from-files",
               "--virtual-time-budget=5000", "--dump-dom", Path(report).resolve().as_uri()]
    dom = subprocess.run(command, capture_output=True, text=True, timeout=120).stdout
    images = re.search(r'data-images="(\d+)"', dom)
    broken = re.search(r'data-broken-images="(\d+)"', dom)
    if not images or not broken:
        raise RuntimeError("the page's check did not run (no data-images / data-broken-images on <body>)")
    return int(images.group(1)), int(broken.group(1))

