"""Paired comparison of benchmark variants: per-clip differences against a base variant.

A variant's mean over a dozen clips moves by several millimetres between two runs that differ
only in a seed (the simulation is chaotic), so comparing two means says little. Each clip is
instead its own control: the figure of the variant minus the base's on the same clip, then the
mean of those differences and its standard error (sample standard deviation / sqrt(clips)).
A difference within about two standard errors of zero is within the noise.

`paired_differences` works on the per-clip records of `results.json` (one run, or several
merged by `merge_results`, e.g. a new variant's run against an earlier run of the default).
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

from physpose.benchmark.report import KIND_COLUMNS, record_figures
from physpose.benchmark.scoring import TRUTH_ROW
from physpose.errors import PhysposeError

# The figures compared, in the paper's Table 2 order (a subset of report.COLUMNS).
PAIRED_KEYS: tuple[str, ...] = ("mpjpe_g_mm", "mpjpe_pa_mm", "mpjpe_2d_px",
                                "velocity_error_mps", "foot_skate_pct", "float_pct",
                                "fallen_pct", "restarts")


def _value(record: dict, key: str) -> float | None:
    """The record's figure ``key`` when it is a finite number, else None."""
    value = record_figures(record).get(key)
    if isinstance(value, (int, float)) and math.isfinite(value):
        return float(value)
    return None


def _summary(pairs: list[tuple[float, float]], groups: list[str] | None = None
             ) -> dict[str, float | int | None]:
    """Means of the pairs (base, variant) and of their differences, with the difference's
    standard error. groups (one name per pair): pairs of one group are not independent (the
    same clip under several seeds), so the standard error is the cluster-robust one over the
    groups; with every pair its own group it is the ordinary sd / sqrt(n)."""
    n = len(pairs)
    diffs = [v - b for b, v in pairs]
    mean = sum(diffs) / n
    groups = groups if groups is not None else [str(i) for i in range(n)]
    sums: dict[str, float] = defaultdict(float)  # per group, the deviations from the mean
    for name, d in zip(groups, diffs):
        sums[name] += d - mean
    count = len(sums)
    se = (math.sqrt(count / (count - 1) * sum(s * s for s in sums.values())) / n
          if count > 1 else None)
    return {"clips": n, "groups": count, "base": sum(b for b, _ in pairs) / n,
            "variant": sum(v for _, v in pairs) / n, "difference": mean, "standard_error": se}


def paired_differences(results: list[dict], base: str, variants: list[str] | None = None,
                       group: Callable[[str], str] | None = None
                       ) -> dict[str, dict[str, dict[str, dict]]]:
    """kind -> variant -> figure -> {clips, groups, base, variant, difference, standard_error}.

    Only clips on which both the variant and ``base`` have a finite figure count for it;
    ``standard_error`` is None with a single clip (or group). ``variants``: those to compare
    (default: every variant of the records but the base and the truth's own row, in order of
    appearance). ``group``: clip name -> the name of its group of clips that are not
    independent (e.g. `pooled_clip`, the same clip in several runs); the standard error is
    then over the groups (see `_summary`).
    """
    records = {(r["kind"], r["clip"], r["variant"]): r for r in results}
    names = variants if variants is not None else list(dict.fromkeys(
        r["variant"] for r in results if r["variant"] not in (base, TRUTH_ROW)))
    out: dict[str, dict[str, dict[str, dict]]] = defaultdict(dict)
    for kind in dict.fromkeys(r["kind"] for r in results):
        keys = [k for k in PAIRED_KEYS if k in KIND_COLUMNS.get(kind, PAIRED_KEYS)]
        for name in names:
            clips = [c for (k, c, v) in records if k == kind and v == name
                     and (kind, c, base) in records]
            figures = {}
            for key in keys:
                found = [(c, _value(records[(kind, c, base)], key),
                          _value(records[(kind, c, name)], key)) for c in clips]
                found = [(c, b, v) for c, b, v in found if b is not None and v is not None]
                if found:
                    figures[key] = _summary([(b, v) for _, b, v in found],
                                            None if group is None else
                                            [group(c) for c, _, _ in found])
            if figures:
                out[kind][name] = figures
    return dict(out)


def load_results(path: str | Path) -> dict:
    """A results document written by `physpose benchmark` (its results.json, or its folder)."""
    path = Path(path)
    if path.is_dir():
        path = path / "results.json"
    if not path.is_file():
        raise PhysposeError("benchmark results not found", path=path,
                            remedy="pass a results.json written by `physpose benchmark --out "
                                   "DIR`, or that folder")
    try:
        doc = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise PhysposeError(f"not a benchmark results file ({err})", path=path,
                            remedy="pass the results.json that `physpose benchmark` wrote") from err
    records = doc.get("results") if isinstance(doc, dict) else None
    if not isinstance(records, list) or not all(map(_is_record, records)):
        raise PhysposeError("not a benchmark results file (no per-clip results, or one whose "
                            "kind, clip, variant or metrics are not what the benchmark writes)",
                            path=path,
                            remedy="pass the results.json that `physpose benchmark` wrote")
    if not records:
        raise PhysposeError("this benchmark run holds no results (every clip failed or was "
                            "skipped)", path=path, remedy="pass the results of a run that scored "
                                                          "clips")
    if not isinstance(doc.get("config", {}), dict):
        raise PhysposeError("not a benchmark results file (its config is not an object)",
                            path=path, remedy="pass the results.json that `physpose benchmark` "
                                              "wrote")
    return doc


def _is_record(record) -> bool:
    """A per-clip result as the benchmark writes it: kind, clip and variant names and a
    metrics object."""
    return isinstance(record, dict) and all(
        isinstance(record.get(k), str) for k in ("kind", "clip", "variant")) \
        and isinstance(record.get("metrics", {}), dict)


def merge_results(docs: list[dict], labels: list[str] | None = None,
                  clip_labels: list[str] | None = None) -> list[dict]:
    """The per-clip records of several results documents; where two have the same variant on
    the same clip, the later document's record is kept. labels (one per document): name every
    variant of a document ``variant@label`` instead (the truth's own row keeps its name), so
    the same variant in two runs (two seeds, two versions) can be compared. clip_labels (one
    per document): name every clip ``clip@label`` instead, so each run's clips count apart
    and the variants' differences pool over the runs (the same clips under several seeds)."""
    merged: dict[tuple[str, str, str], dict] = {}
    for k, doc in enumerate(docs):
        for r in doc["results"]:
            if labels is not None and r["variant"] != TRUTH_ROW:
                r = dict(r, variant=f"{r['variant']}@{labels[k]}")
            if clip_labels is not None:
                r = dict(r, clip=f"{r['clip']}@{clip_labels[k]}")
            merged[(r["kind"], r["clip"], r["variant"])] = r
    return list(merged.values())


def pooled_clip(name: str) -> str:
    """The clip a pooled record stands for: its name without the ``@RUN`` that
    `merge_results` appended (a segment's own ``@4s`` kept)."""
    return name.rsplit("@", 1)[0]


def run_labels(paths: list[Path]) -> list[str]:
    """A short name per results file: its folder's name for a results.json (else its stem),
    numbered where two would be the same."""
    names = [p.name if p.is_dir() else (p.parent.name if p.name == "results.json" else p.stem)
             for p in map(Path, paths)]
    return [f"{n}#{names[:k].count(n) + 1}" if names.count(n) > 1 else n
            for k, n in enumerate(names)]
