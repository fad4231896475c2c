"""Benchmark results: aggregation and the `results.json` / `results.md` files."""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

from physpose.cache import atomic_path
from physpose.json_text import strict_json

# (column title, key in a result's "metrics" or "ground" dict, format); the paper's Table 2 order.
COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("MPJPE-G (mm)", "mpjpe_g_mm", "{:.0f}"),
    ("MPJPE (mm)", "mpjpe_mm", "{:.0f}"),
    ("MPJPE-PA (mm)", "mpjpe_pa_mm", "{:.0f}"),
    ("MPJPE-2d (px)", "mpjpe_2d_px", "{:.1f}"),
    ("Velocity (m/s)", "velocity_error_mps", "{:.2f}"),
    ("Foot skate (%)", "foot_skate_pct", "{:.0f}"),
    ("Float (%)", "float_pct", "{:.0f}"),
    ("Penetration (mm)", "penetration_mean_mm", "{:.1f}"),
    ("Jitter (m/s²)", "jitter_mps2", "{:.1f}"),
    ("Fallen (%)", "fallen_pct", "{:.0f}"),
    ("Restarts", "restarts", "{:.1f}"),
    ("Ground normal err (deg)", "normal_angle_error_deg", "{:.1f}"),
    ("Camera height err (%)", "camera_height_error_pct", "{:.0f}"),
    ("Camera height (m)", "camera_height_m", "{:.2f}"),
    ("Camera tilt (deg)", "camera_tilt_deg", "{:.1f}"),
)
# Columns shown per kind of material (those without ground truth cannot have the 3d errors).
KIND_COLUMNS: dict[str, tuple[str, ...]] = {
    "mocap": ("mpjpe_g_mm", "mpjpe_mm", "mpjpe_pa_mm", "mpjpe_2d_px", "velocity_error_mps",
              "foot_skate_pct", "float_pct", "penetration_mean_mm", "jitter_mps2", "fallen_pct",
              "restarts", "normal_angle_error_deg", "camera_height_error_pct"),
    "multiview": ("mpjpe_g_mm", "mpjpe_mm", "mpjpe_pa_mm", "mpjpe_2d_px", "velocity_error_mps",
                  "foot_skate_pct", "float_pct", "penetration_mean_mm", "jitter_mps2",
                  "fallen_pct", "restarts", "normal_angle_error_deg", "camera_height_error_pct"),
    "video": ("mpjpe_2d_px", "foot_skate_pct", "float_pct", "penetration_mean_mm", "jitter_mps2",
              "fallen_pct", "restarts", "camera_height_m", "camera_tilt_deg"),
}
KIND_TITLES = {"mocap": "Motion capture through the detector simulator",
               "multiview": "Multi-view reference, scored from each single view",
               "video": "Real videos (no 3d ground truth)"}


def record_figures(result: dict) -> dict[str, float]:
    """A per-clip record's figures: its metrics and its ground-plane figures together."""
    return {**result.get("metrics", {}), **result.get("ground", {})}


def aggregate(results: list[dict]) -> dict[str, dict[str, dict[str, float]]]:
    """kind -> variant -> mean of every numeric figure over the clips (NaNs ignored)."""
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for r in results:
        groups[(r["kind"], r["variant"])].append(r)
    out: dict[str, dict[str, dict[str, float]]] = defaultdict(dict)
    for (kind, variant), rows in groups.items():
        sums: dict[str, list[float]] = defaultdict(list)
        for r in rows:
            for key, value in record_figures(r).items():
                if isinstance(value, (int, float)) and math.isfinite(value):
                    sums[key].append(float(value))
            for stage, seconds in r.get("time_s", {}).items():
                sums[f"time_s.{stage}"].append(float(seconds))
        agg = {key: sum(v) / len(v) for key, v in sums.items()}
        agg["clips"] = len(rows)
        out[kind][variant] = agg
    return dict(out)


def _fmt(value, spec: str) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return spec.format(value)


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines


def _columns(kind: str) -> list[tuple[str, str, str]]:
    keys = KIND_COLUMNS[kind]
    return [c for c in COLUMNS if c[1] in keys]


def _time(values: dict, prefix: str = "") -> str:
    total = sum(v for k, v in values.items() if k.startswith(prefix))
    return f"{total:.1f}"


def _mean_over(by_variant: dict[str, dict]) -> str:
    """What a kind's means are taken over: one clip count, or each variant's where they differ
    (a variant that failed on a clip is averaged without it)."""
    counts = {variant: agg["clips"] for variant, agg in by_variant.items()}
    if len(set(counts.values())) == 1:
        return f"Mean over {next(iter(counts.values()))} clip(s)."
    each = ", ".join(f"{variant} {n}" for variant, n in counts.items())
    return (f"Means over each variant's own clips ({each}): a variant that failed on a clip is "
            "averaged without it, so compare them in the paired table, which pairs like with "
            "like.")


def render_markdown(doc: dict) -> str:
    """The results as markdown: one Table-2-shaped table per kind, the paired differences
    against the base variant (with two or more variants), then per-clip tables."""
    lines = ["# physpose benchmark", "",
             f"Command: `{doc['command']}`  ", f"Machine: {doc['machine']}", ""]
    slow = doc.get("config", {}).get("material", {}).get("slow_motion", 1)
    if slow != 1:
        lines += [f"Motion capture played as {slow}x slow footage, not declared to the "
                  f"variants; one frame in {slow} scored, on the real clock.", ""]
    pending = doc.get("pending", [])
    if pending:
        lines += [f"**Incomplete**: written while the run went on, before {len(pending)} more "
                  f"piece(s) of material: {', '.join(pending)}. Run the same command again "
                  "for all of it (the stage caches keep the work done).", ""]
    for message in doc.get("skipped", []):
        lines.append(f"- skipped: {message}")
    for failure in doc.get("failures", []):
        lines.append(f"- failed: {failure['variant']} on {failure['clip']}: {failure['error']}")
    lines.append("")
    for kind, by_variant in doc["aggregate"].items():
        cols = _columns(kind)
        lines += [f"## {KIND_TITLES[kind]}", "", _mean_over(by_variant)
                  + " Time: seconds per clip (variant only / with observation).", ""]
        rows = [[variant] + [_fmt(agg.get(key), spec) for _, key, spec in cols]
                + [_fmt(agg.get("time_s.variant"), "{:.2f}") + " / " + _time(agg, "time_s.")]
                for variant, agg in by_variant.items()]
        lines += _table(["Variant"] + [c[0] for c in cols] + ["Time (s)"], rows) + [""]
    if doc.get("paired"):
        lines += render_paired(doc["paired"], doc["paired_against"])
    for kind in doc["aggregate"]:
        cols = _columns(kind)
        lines += [f"### Per clip: {kind}", ""]
        rows = []
        for r in doc["results"]:
            if r["kind"] == kind:
                values = record_figures(r)
                rows.append([r["clip"], r["variant"], str(r["frames"])]
                            + [_fmt(values.get(key), spec) for _, key, spec in cols]
                            + [_fmt(r["time_s"].get("variant"), "{:.2f}")])
        lines += _table(["Clip", "Variant", "Frames"] + [c[0] for c in cols] + ["Time (s)"],
                        rows) + [""]
    return "\n".join(lines)


def _finer(spec: str) -> str:
    """A signed format one decimal finer than a report column's ("{:.0f}" -> "{:+.1f}")."""
    digits = int(spec.split(".")[1][0]) if "." in spec else 0
    return "{:+.%df}" % (digits + 1)


def render_paired(paired: dict, base: str) -> list[str]:
    """Markdown of `paired.paired_differences`: one table per kind, a cell per figure
    "base -> variant (difference +- standard error)"."""
    lines: list[str] = []
    title = {key: name for name, key, _ in COLUMNS}
    # Means as in the report's columns (percentages one decimal finer), differences finer still.
    mean_spec = {key: ("{:.1f}" if key.endswith("_pct") else spec) for _, key, spec in COLUMNS}
    for kind, by_variant in paired.items():
        keys = list(dict.fromkeys(k for figures in by_variant.values() for k in figures))
        rows = []
        for name, figures in by_variant.items():
            cells = []
            for key in keys:
                f = figures.get(key)
                if f is None:
                    cells.append("–")
                    continue
                diff = _finer(mean_spec[key])
                se = ("" if f["standard_error"] is None
                      else " +- " + diff.replace("+", "").format(f["standard_error"]))
                cells.append(f"{mean_spec[key].format(f['base'])} -> "
                             f"{mean_spec[key].format(f['variant'])} "
                             f"({diff.format(f['difference'])}{se})")
            clips = max(f["clips"] for f in figures.values())
            groups = max(f.get("groups", f["clips"]) for f in figures.values())  # older runs
            rows.append([name, str(clips) if groups == clips else f"{clips} ({groups} groups)"]
                        + cells)
        lines += [f"## Paired against `{base}`: {KIND_TITLES.get(kind, kind)}", "",
                  "Per clip, the variant's figure minus the base's on the same clip; mean +- "
                  "standard error over the clips both have (within about two standard errors "
                  "of zero is within the noise; where clips come in groups, such as one clip "
                  "under several seeds, the standard error is over the groups).", ""]
        lines += _table(["Variant", "Clips"] + [title[k] for k in keys], rows) + [""]
    return lines


def write_results(doc: dict, out_dir: str | Path) -> tuple[Path, Path]:
    """Write `results.json` and `results.md` into out_dir; returns their paths."""
    out = Path(out_dir)
    json_path, md_path = out / "results.json", out / "results.md"
    for path, text in ((json_path, results_json(doc)), (md_path, render_markdown(doc))):
        with atomic_path(path) as tmp:  # makes out; rewritten as the run goes: never half a file
            tmp.write_text(text + "\n")
    return json_path, md_path


def results_json(doc) -> str:
    """The document as strict JSON text: non-finite floats as null, NumPy values as lists or
    numbers."""
    return strict_json(doc, indent=1)
