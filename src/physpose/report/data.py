"""The report's data: motions, body, contacts, metric rows and plot series, as JSON-able dicts."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from physpose.diagnostics import warning_lines
from physpose.reconstruction import GRF_PARTS, Reconstruction
from physpose.render.bodymotion import (BodyMotion, GeomShape, body_weight, load_model,
                                        reconstruction_motion)
from physpose.render.result import available_motions, joints_of
from physpose.render.skeleton import (FEET, edge_indices, foot_contacts, foot_heights,
                                      lowest_foot_points)
from physpose.skeleton import DOF_NAMES, NUM_DOF

# Metric keys of `evaluate` in the order and with the labels of the summary and report tables.
METRIC_LABELS = {
    "mpjpe_2d_px": "MPJPE-2d vs detections (px)",
    "foot_skate_pct": "foot skate (% frames)",
    "float_pct": "float (% frames)",
    "penetration_mean_mm": "penetration mean (mm)",
    "penetration_max_mm": "penetration max (mm)",
    "jitter_mps2": "jitter (m/s^2)",
}
_DECIMALS = 4  # metres: 0.1 mm in the page's data
# Plot colours per (motion, foot); the viewer uses the same blue/orange per motion.
_SERIES_COLORS = {("physics", "left"): "#2f6fd6", ("physics", "right"): "#7fa8ea",
                  ("kinematic", "left"): "#f08a24", ("kinematic", "right"): "#f5b877"}
_TERM_COLORS = ("#2f6fd6", "#f08a24", "#2a9d4b", "#c03a8a", "#8a5cc2", "#6b7280", "#b08900")
_LOG_RANGE = 100.0  # plot window losses on a log axis when they span more than this factor


def _r(a: np.ndarray) -> list:
    return np.round(np.asarray(a, dtype=float), _DECIMALS).reshape(-1).tolist()


def _r_gaps(a: np.ndarray) -> list:
    """As _r, with None (a gap in the plot) for values that are not finite."""
    return [v if math.isfinite(v) else None for v in _r(a)]


def _geom_dict(g: GeomShape) -> dict:
    return {"name": g.name, "body": g.body, "kind": g.kind, "size": list(g.size),
            "pos": list(g.pos), "quat": list(g.quat), "rgba": list(g.rgba)}


def report_data(rec: Reconstruction, title: str = "physpose result") -> dict:
    """Everything the page shows, computed from one result."""
    motions, bodies = {}, {}
    for name in available_motions(rec):
        joints = joints_of(rec, name)
        body = reconstruction_motion(rec, name)
        bodies[name] = body
        feet = lowest_foot_points(joints, rec.joint_names)               # (T, 2, 3)
        motions[name] = {
            "joints": _r(joints),
            "body_pos": None if body is None else _r(body.pos),
            "body_quat": None if body is None else _r(body.quat),
            "feet_xy": np.round(feet[..., :2], _DECIMALS).reshape(-1, 2).tolist(),
            "contacts": foot_contacts(feet[..., 2]).astype(int).reshape(-1).tolist(),
        }
    tree = next((b.tree for b in bodies.values() if b is not None), None)
    best = "physics" if rec.has_physics else "kinematic"
    all_joints = joints_of(rec, best)
    center = all_joints[:, 0].mean(axis=0)
    return {
        "title": title, "fps": rec.fps, "frames": rec.num_frames,
        "joint_names": list(rec.joint_names), "edges": edge_indices(rec.joint_names).tolist(),
        "default_motion": best, "motions": motions,
        "body": None if tree is None else {
            "names": list(tree.names), "parents": list(tree.parents),
            "geoms": [_geom_dict(g) for g in tree.geoms],
            "scene": [_geom_dict(g) for g in tree.scene]},
        "center": [float(center[0]), float(center[1]), 0.0],
        "extent": float(np.abs(all_joints[..., :2] - center[:2]).max()),
        "plots": _plots(rec, bodies),
    }


def _plots(rec: Reconstruction, bodies: dict[str, BodyMotion | None]) -> list[dict]:
    time = _r(np.arange(rec.num_frames) / rec.fps)
    plots = []
    series, bands = [], []
    for name in available_motions(rec):
        heights = foot_heights(joints_of(rec, name), rec.joint_names)
        contacts = foot_contacts(heights)
        for k, foot in enumerate(FEET):
            color = _SERIES_COLORS[(name, foot)]
            series.append({"name": f"{name} {foot}", "y": _r(heights[:, k]), "color": color,
                           "dash": name == "kinematic"})
            bands.append({"name": f"{name} {foot} contact", "on": contacts[:, k].tolist(),
                          "color": color})
    plots.append({"id": "feet", "title": "Foot height and contacts", "xlabel": "time (s)",
                  "ylabel": "m", "x": time, "series": series, "bands": bands, "cursor": True})
    com = [{"name": name, "y": _r(body.com[:, 2]), "color": _SERIES_COLORS[(name, "left")],
            "dash": name == "kinematic"} for name, body in bodies.items() if body is not None]
    if com:
        plots.append({"id": "com", "title": "Centre of mass height", "xlabel": "time (s)",
                      "ylabel": "m", "x": time, "series": com, "cursor": True})
    if rec.has_physics:
        gap = np.linalg.norm(rec.joints_physics - rec.joints_kinematic, axis=-1).mean(axis=1)
        undetected = rec.undetected
        bands = [{"name": "restart from the estimate (a jump)", "on": rec.restart_flags.tolist(),
                  "color": "#c0392b"}]
        if undetected.any():
            bands.append({"name": "no person detected", "on": undetected.tolist(),
                          "color": "#7f8c8d"})
        plots.append({"id": "gap", "title": "Physics vs kinematic (mean joint distance)",
                      "xlabel": "time (s)", "ylabel": "cm", "x": time, "cursor": True,
                      "series": [{"name": "distance", "y": _r(100 * gap), "color": "#444"}],
                      "bands": bands})
    forces = grf_plot(rec)
    if forces is not None:
        plots.append(forces)
    losses = window_losses(rec.meta, rec.fps)
    if losses is not None:
        plots.append(losses)
    return plots


_GRF_LABELS = {"l_foot": "left foot", "r_foot": "right foot", "body": "rest of the body"}
_GRF_COLORS = {"l_foot": "#2f6fd6", "r_foot": "#7fa8ea", "body": "#2a9d4b"}
SATURATED = 0.99  # a joint whose frame-mean torque is this share of its servo's limit is at it


def forces_summary(rec: Reconstruction) -> str | None:
    """One line on the simulation's forces: the peak vertical ground reaction force on each
    foot (body weights) and the share of frames in which some joint's torque reaches its
    servo's torque limit (where the simulated body works at the end of its strength); None
    without recorded forces or body model."""
    if rec.grf_physics is None or rec.torques_physics is None or rec.body_mjcf is None \
            or not np.isfinite(rec.grf_physics).any():
        return None
    model = load_model(rec.body_mjcf)
    peaks = np.nanmax(rec.grf_physics[:, :2, 2], axis=0) / body_weight(model)
    line = (f"peak vertical ground reaction force {peaks[0]:.2f} (left foot) and "
            f"{peaks[1]:.2f} (right foot) body weights")
    if model.nu < NUM_DOF or not model.actuator_forcelimited[:NUM_DOF].all():
        return line  # a body model without physpose's torque-limited servos
    limits = model.actuator_forcerange[:NUM_DOF, 1]
    saturated = np.abs(rec.torques_physics) >= SATURATED * limits  # NaN compares False
    if not saturated.any():
        return line + "; no joint at its servo's torque limit"
    worst = DOF_NAMES[int(np.argmax(saturated.sum(axis=0)))]
    return (line + f"; a joint at its servo's torque limit in "
            f"{100 * saturated.any(axis=1).mean():.0f} % of frames (most often {worst})")


def grf_plot(rec: Reconstruction) -> dict | None:
    """The simulation's vertical ground reaction force on each foot (and on the rest of the
    body where anything else touches the floor or an obstacle), in body weights when the body
    model is stored (else newtons); None without recorded forces."""
    if rec.grf_physics is None or not np.isfinite(rec.grf_physics).any():
        return None
    weight = None if rec.body_mjcf is None else body_weight(load_model(rec.body_mjcf))
    vertical = rec.grf_physics[..., 2] / (weight or 1.0)
    series = [{"name": _GRF_LABELS[part], "y": _r_gaps(vertical[:, k]),
               "color": _GRF_COLORS[part]}
              for k, part in enumerate(GRF_PARTS)
              if part != "body" or np.nanmax(np.abs(vertical[:, k]), initial=0.0) > 0.01]
    return {"id": "grf", "title": "Ground reaction force, vertical (simulated)",
            "xlabel": "time (s)", "ylabel": "body weights" if weight else "N",
            "x": _r(np.arange(rec.num_frames) / rec.fps), "series": series, "cursor": True}


def window_losses(meta: dict, fps: float | None = None) -> dict | None:
    """Plot spec of the per-term loss of each dynamics window, from meta['dynamics']['windows'].

    Each window is a dict with its terms under 'terms_final' (as the dynamics stage writes
    them), 'terms' or 'losses' ({name: value}); its start time is frames[0] / fps when the
    window lists its frames, else a numeric 'start' (s), else the window index. Terms absent
    from a window leave a gap; None when no window has any term.
    """
    windows = [w for w in (meta.get("dynamics") or {}).get("windows") or [] if isinstance(w, dict)]
    rows = [w.get("terms_final") or w.get("terms") or w.get("losses") or {} for w in windows]
    names = sorted({k for r in rows for k, v in r.items() if _finite(v)})
    if not names:
        return None
    starts = [_window_start(w, fps) for w in windows]
    has_start = all(s is not None for s in starts)
    x = [s if has_start else float(i) for i, s in enumerate(starts)]
    series = [{"name": n, "y": [float(r[n]) if _finite(r.get(n)) else None for r in rows],
               "color": _TERM_COLORS[k % len(_TERM_COLORS)], "markers": True}
              for k, n in enumerate(names)]
    values = [v for s in series for v in s["y"] if v is not None]
    log = min(values) > 0 and max(values) / min(values) > _LOG_RANGE
    return {"id": "losses", "title": "Loss per window and term" + (" (log)" if log else ""),
            "xlabel": "window start (s)" if has_start else "window", "ylabel": "loss",
            "x": x, "series": series, "log_y": log, "cursor": has_start}


def _window_start(window: dict, fps: float | None) -> float | None:
    """Start time (s) of a dynamics window, or None when it does not say."""
    frames = window.get("frames")
    if fps and isinstance(frames, list) and frames and _finite(frames[0]):
        return float(frames[0]) / fps
    return float(window["start"]) if _finite(window.get("start")) else None


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def metric_rows(rec: Reconstruction, metrics: dict | None) -> tuple[list, list]:
    """(columns, rows) of the metric table: {name: value} or {group: {name: value}}, the
    result's stored metrics where None; a name in METRIC_LABELS is shown by its label."""
    if metrics is None:
        metrics = rec.meta.get("metrics") or {}
    if metrics and all(isinstance(v, dict) for v in metrics.values()):
        columns = list(metrics)
        names = list(dict.fromkeys(k for v in metrics.values() for k in v))
        return columns, [[METRIC_LABELS.get(n, n)] + [metrics[c].get(n) for c in columns]
                         for n in names]
    return ["value"], [[METRIC_LABELS.get(k, k), v] for k, v in metrics.items()]


def slow_motion_note(rec: Reconstruction) -> str:
    """What a slow-motion (or sped-up) footage's factor means for the result's times."""
    return (f"the footage plays {rec.slow_motion:g}x slower than real time; the frame rate, "
            "times, speeds and forces here are on the real clock")


def video_span(rec: Reconstruction) -> str | None:
    """Where the result lies in its video ("0.40-1.56 s (frames 24-94)"), or None where the
    result does not record it. Other times of a result count from its first frame."""
    times, frames = rec.video_times, rec.video_frames
    if times is None:
        return None
    span = f"{times[0]:.2f}-{times[-1]:.2f} s"
    return span if frames is None else f"{span} (frames {frames[0]}-{frames[-1]})"


def summary_rows(rec: Reconstruction, folder: Path) -> list[tuple[str, str]]:
    """Facts about the result shown above the metrics."""
    rows = [("result", str(folder)), ("frames", str(rec.num_frames)),
            ("frame rate", f"{rec.fps:g} Hz"),
            ("duration", f"{rec.num_frames / rec.fps:.2f} s"),
            ("motions", ", ".join(available_motions(rec)))]
    if rec.slow_motion != 1.0:
        rows.insert(4, ("slow motion", slow_motion_note(rec)))
    source = rec.meta.get("source")
    if source:
        rows.insert(1, ("video", str(source)))
    span = video_span(rec)
    if span:
        rows.insert(2 if source else 1, ("in the video", span))
    runs = rec.undetected_runs
    if runs:
        rows.append(("frames without a detection",
                     f"{int(rec.undetected.sum())}, inferred, not observed: "
                     + ", ".join(f"{a / rec.fps:.2f}-{(b + 1) / rec.fps:.2f} s"
                                 for a, b in runs)))
    if rec.has_physics:
        frames = rec.restarts
        rows.append(("physics restarts", "none: one continuous simulation" if not frames else
                     f"{len(frames)}, where the motion jumps back to the estimate: "
                     + ", ".join(f"{f / rec.fps:.2f} s" for f in frames)))
        forces = forces_summary(rec)
        if forces is not None:
            rows.append(("physics forces", forces))
    rows += [("warning", line) for line in warning_lines(rec.meta.get("diagnostics", {}), rec.fps,
                                                         rec.slow_motion)]
    return rows
