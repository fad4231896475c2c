"""The outputs stage: metrics without ground truth, report, overlay video and exports of a result.

`summarize` scores each motion of a result folder on what needs no ground truth: agreement of
the projected landmark sites with the detections (MPJPE-2d, px, weighted by the detector's
confidence) and plausibility (foot skate, float, ground penetration, jitter; docs/metrics.md).
Both motions use the 5 mm contact threshold, as the benchmark does (docs/metrics.md: the
simulated body's heel and toe joints are its box soles, so the paper's -15 mm would never count
a resting foot as in contact). `write_outputs` writes metrics.json, stores the metrics (and the video's image size when
the result lacks it) in reconstruction.npz's meta, then the report, the overlay video with one
PNG frame and the exports, all into the result folder.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from physpose import video as videolib
from physpose.cache import atomic_path, leftover_temp_files
from physpose.errors import PhysposeError
from physpose.export import DEFAULT_NAMES, FORMATS, export
from physpose.json_text import strict_json
from physpose.metrics import CONTACT_PRESETS, evaluate, project
from physpose.reconstruction import Reconstruction
from physpose.render.overlay import DEFAULT_NAME as OVERLAY_NAME
from physpose.render.result import available_motions, load_result
from physpose.report import DEFAULT_NAME as REPORT_NAME
from physpose.report.data import METRIC_LABELS

_log = logging.getLogger(__name__)
METRICS_FILE = "metrics.json"
OVERLAY_PNG = "overlay.png"
DEFAULT_FORMATS = ("bvh", "glb", "csv", "forces")

__all__ = ["summarize", "write_outputs", "metrics_table", "METRICS_FILE", "DEFAULT_FORMATS"]


def _landmarks(rec: Reconstruction, motion: str) -> np.ndarray:
    return rec.landmarks_kinematic if motion == "kinematic" else rec.landmarks_physics


def motion_metrics(rec: Reconstruction, motion: str) -> dict[str, float]:
    """The metrics of one motion ('kinematic' or 'physics'), keyed as in METRIC_LABELS."""
    joints = rec.joints_kinematic if motion == "kinematic" else rec.joints("physics")
    if not np.isfinite(joints).all():  # metrics.evaluate would raise a bare ValueError
        raise PhysposeError(f"the {motion} motion holds positions that are not numbers (NaN or "
                            "infinity)", remedy="re-run the reconstruction")
    kwargs = {}
    landmarks = _landmarks(rec, motion)
    if landmarks is not None:
        est = project(rec.as_filmed(landmarks, motion), rec.camera_K,
                      rec.camera_T_world2cam)  # (T, 33, 2) px
        valid = np.isfinite(est).all(axis=-1)
        weight = np.where(valid, rec.keypoints2d[..., 2], 0.0)
        if weight.sum() > 0:
            kwargs = {"est_2d": np.where(valid[..., None], est, 0.0),
                      "target_2d": rec.keypoints2d[..., :2], "confidence_2d": weight}
    values = evaluate(joints, fps=rec.fps, contact=CONTACT_PRESETS["kinematics"],
                      joint_names=rec.joint_names, **kwargs)
    return {k: float(values[k]) for k in METRIC_LABELS if k in values}


def summarize(result_dir: str | Path) -> dict[str, dict[str, float]]:
    """{motion: {metric: value}} for every motion the result holds (kinematic, physics)."""
    rec, _ = load_result(result_dir)
    return {m: motion_metrics(rec, m) for m in available_motions(rec)}


def metrics_table(metrics: dict[str, dict[str, float]]) -> str:
    """The metrics as an aligned text table, one column per motion."""
    motions = list(metrics)
    width = max(len(v) for v in METRIC_LABELS.values())
    lines = [f"  {'metric':<{width}}" + "".join(f"{m:>12}" for m in motions)]
    for key, label in METRIC_LABELS.items():
        if any(key in metrics[m] for m in motions):
            cells = "".join(f"{metrics[m][key]:>12.3g}" if _defined(metrics[m].get(key))
                            else f"{'-':>12}" for m in motions)  # null: not a number
            lines.append(f"  {label:<{width}}{cells}")
    return "\n".join(lines)


def _defined(value) -> bool:
    return value is not None and math.isfinite(value)


def _source_image_size(rec: Reconstruction, video: Path | None) -> list[int] | None:
    """(width, height) of the given or recorded source video, when it is a readable video."""
    path = video if video is not None else Path(rec.meta.get("source") or "")
    if not (str(path) and path.is_file() and path.suffix.lower() in videolib.VIDEO_EXTENSIONS):
        return None
    return list(videolib.probe(path).image_size)


def _store_in_meta(folder: Path, rec: Reconstruction, metrics: dict,
                   video: Path | None) -> Reconstruction:
    meta = dict(rec.meta, metrics=metrics)
    if not meta.get("image_size"):
        size = _source_image_size(rec, video)
        if size is not None:
            meta["image_size"] = size
    rec = rec.replace(meta=meta)
    rec.save(folder / "reconstruction.npz")
    return rec


def write_outputs(result_dir: str | Path, *, video: str | Path | None = None,
                  formats: tuple[str, ...] = DEFAULT_FORMATS, report: bool = True,
                  overlay: bool = True, progress: bool = True) -> dict[str, Path]:
    """Write metrics.json, report.html, overlay.mp4 + overlay.png and the exports into the folder.

    video: the source video for the overlay (default: the one recorded in the result).
    formats: any of physpose.export.FORMATS; 'forces' is skipped for a result without
    simulated forces (a kinematic fit). Returns {name: path} of what was written, names
    'metrics', 'report', 'overlay', 'overlay_png' and the formats. The folder's
    reconstruction.npz has just been written: these outputs of an earlier run, made from
    another one, are removed first (logged where this call does not write them again), and
    so are temporary files a killed run left.
    """
    unknown = [f for f in formats if f not in FORMATS]
    if unknown:
        raise PhysposeError(f"unknown export format(s) {', '.join(map(repr, unknown))}",
                            remedy=f"choose from {', '.join(FORMATS)}")
    rec, folder = load_result(result_dir)
    _clear_earlier_outputs(folder, {METRICS_FILE, *(DEFAULT_NAMES[f] for f in formats)}
                           | ({REPORT_NAME} if report else set())
                           | ({OVERLAY_NAME, OVERLAY_PNG} if overlay else set()))
    video = None if video is None else Path(video)
    metrics = {m: motion_metrics(rec, m) for m in available_motions(rec)}
    written: dict[str, Path] = {}
    with atomic_path(folder / METRICS_FILE) as tmp:
        tmp.write_text(strict_json(metrics, indent=2) + "\n")
    written["metrics"] = folder / METRICS_FILE
    rec = _store_in_meta(folder, rec, metrics, video)
    if report:
        from physpose.report import build_report  # noqa: PLC0415 (reads the viewer bundle)

        written["report"] = build_report(folder)  # the metrics just stored in its meta
    if overlay:
        from physpose.render.overlay import render_overlay, save_overlay_png  # noqa: PLC0415

        written["overlay"] = render_overlay(folder, video=video, progress=progress).path
        written["overlay_png"] = save_overlay_png(folder, rec.num_frames // 2,
                                                  folder / OVERLAY_PNG, video=video)
    for fmt in formats:
        if fmt == "forces" and rec.grf_physics is None:
            continue
        written[fmt] = export(folder, fmt, folder / DEFAULT_NAMES[fmt])
    return written


def _clear_earlier_outputs(folder: Path, rewritten: set[str]) -> None:
    """Remove what write_outputs writes, as an earlier run left it in `folder`, and temporary
    files of killed runs; say which files go for good (not in `rewritten`)."""
    names = {METRICS_FILE, REPORT_NAME, OVERLAY_NAME, OVERLAY_PNG, *DEFAULT_NAMES.values()}
    gone = sorted(n for n in names - rewritten if (folder / n).is_file())
    for name in names:
        if (folder / name).is_file():
            (folder / name).unlink()
    for temp in leftover_temp_files(folder):
        temp.unlink(missing_ok=True)
    if gone:
        _log.warning("%s: removed %s, written there by an earlier run from another "
                     "reconstruction (not asked for this time)", folder, ", ".join(gone))
