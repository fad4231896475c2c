"""The HTML report: one self-contained page with a 3d viewer, the metric table and plots.

The page inlines the viewer bundle (three.js + our code, built from web/ by `make web`) and the
result's data as JSON, so it opens offline from a single file.
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path
from string import Template

from physpose import __version__
from physpose.cache import atomic_path
from physpose.errors import PhysposeError
from physpose.reconstruction import Reconstruction
from physpose.report.data import metric_rows, report_data, summary_rows
from physpose.render.result import load_result

ASSETS = Path(__file__).resolve().parent / "assets"
BUNDLE = ASSETS / "viewer.js"
DEFAULT_NAME = "report.html"

__all__ = ["build_report", "DEFAULT_NAME"]


def build_report(result_dir: str | Path, out_html: str | Path | None = None,
                 metrics: dict | None = None) -> Path:
    """Write the report of a result folder; returns its path (default RESULT_DIR/report.html).

    metrics: {name: value} or {group: {name: value}}; default: meta['metrics'] of the result.
    """
    if not BUNDLE.is_file():
        raise PhysposeError("the report viewer bundle is missing", path=BUNDLE,
                            remedy="run `make setup` (it builds web/ with npm and esbuild)")
    rec, folder = load_result(result_dir)
    out = Path(out_html) if out_html is not None else folder / DEFAULT_NAME
    title = f"physpose · {folder.name}"
    data = report_data(rec, title=title)
    try:
        data_json = json.dumps(data, separators=(",", ":"), allow_nan=False)
    except ValueError:  # the viewer draws numbers only
        raise PhysposeError("the result holds positions that are not numbers (NaN or infinity)",
                            path=Reconstruction.file_in(folder),
                            remedy="re-run the reconstruction") from None
    columns, rows = metric_rows(rec, metrics)
    page = Template((ASSETS / "template.html").read_text()).substitute(
        version=__version__, title=html.escape(title),
        subtitle=html.escape(f"{rec.num_frames} frames at {rec.fps:g} Hz, "
                             + ("physics and kinematic motion" if rec.has_physics
                                else "kinematic motion only")),
        frames=rec.num_frames,
        summary=_table(["", ""], [list(r) for r in summary_rows(rec, folder)], header=False),
        metrics=_table(["metric"] + columns, rows) if rows else
        "<p class=\"hint\">No metrics stored with this result.</p>",
        data=_script_safe(data_json),
        script=_script_safe(BUNDLE.read_text()))
    with atomic_path(out) as tmp:
        tmp.write_text(page)
    return out


def _script_safe(text: str) -> str:
    """Text safe inside a <script> element (no closing tag or comment opener)."""
    return text.replace("</", "<\\/").replace("<!--", "<\\!--")


def _table(columns: list[str], rows: list[list], header: bool = True) -> str:
    def cell(v) -> str:
        if isinstance(v, float) and math.isfinite(v):
            return f'<td class="num">{v:.4g}</td>'
        if isinstance(v, float):  # NaN: metrics.json's null, not a number
            v = None
        if isinstance(v, int) and not isinstance(v, bool):
            return f'<td class="num">{v}</td>'
        return f"<td>{html.escape('—' if v is None else str(v))}</td>"

    head = ("<tr>" + "".join(f"<th>{html.escape(c)}</th>" for c in columns) + "</tr>"
            if header else "")
    body = "".join("<tr>" + "".join(cell(v) for v in r) + "</tr>" for r in rows)
    return f"<table>{head}{body}</table>"
