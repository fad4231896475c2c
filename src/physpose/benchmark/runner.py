"""Run variants over benchmark material and collect per-clip figures and timings."""

from __future__ import annotations

import os
import platform
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import threadpoolctl

from physpose.benchmark.material import Clip, Material, MaterialConfig, load_clips
from physpose.benchmark.paired import paired_differences
from physpose.benchmark.report import aggregate
from physpose.benchmark.scoring import score_clip, truth_record
from physpose.benchmark.variants import get_variant
from physpose.errors import PhysposeError


@dataclass(frozen=True)
class BenchmarkConfig:
    """Which variants run, on material prepared how, and which one the others are paired
    against (None: the first variant; see paired.py)."""

    variants: tuple[str, ...] = ("baseline",)
    material: MaterialConfig = MaterialConfig()
    paired_against: str | None = None

    def __post_init__(self) -> None:
        if self.paired_against is not None and self.paired_against not in self.variants:
            raise PhysposeError(f"the paired comparison's base {self.paired_against!r} is not "
                                "among the variants run",
                                remedy=f"pass one of {', '.join(self.variants)}, or add it with "
                                       "--variant")

    @property
    def base(self) -> str | None:
        """The variant the others are paired against; None with a single variant."""
        if len(self.variants) < 2:
            return None
        return self.paired_against or self.variants[0]


def _log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def run_variant(name: str, clip: Clip) -> dict:
    """Run one variant on one clip and score it; returns the clip's result record."""
    fn = get_variant(name)
    start = time.perf_counter()
    recon = fn(clip.observations, clip.context)
    variant_s = time.perf_counter() - start
    if recon.num_frames != clip.observations.num_frames:
        raise PhysposeError(f"variant {name} returned {recon.num_frames} frames for "
                            f"{clip.observations.num_frames} observed", path=clip.source,
                            remedy="a variant must reconstruct every observed frame")
    start = time.perf_counter()
    metrics, ground = score_clip(clip, recon)
    windows = recon.meta.get("dynamics", {}).get("windows")
    if windows is not None:  # windows restarted from the kinematic state: jumps, not physics
        metrics["restarts"] = float(len(recon.restarts))
    stages = {stage: float(s) for stage, s in recon.meta.get("timings_s", {}).items()}
    return {
        "variant": name, "kind": clip.kind, "clip": clip.name, "source": clip.source,
        "frames": clip.observations.num_frames, "fps": clip.observations.fps,
        "metrics": metrics, "ground": ground,
        "time_s": {**clip.timings_s, "variant": variant_s, "score": time.perf_counter() - start},
        "variant_stages_s": stages,  # the variant's own breakdown of its time
    }


def run_clips(clips: Sequence[Clip], variants: Sequence[str],
              log: Callable[[str], None] = _log) -> tuple[list[dict], list[dict]]:
    """(results, failures) of every variant on every clip, plus each truth's own row."""
    results: list[dict] = []
    failures: list[dict] = []
    for clip in clips:
        if clip.truth is not None:
            results.append(truth_record(clip))
        for name in variants:
            try:
                record = run_variant(name, clip)
            except PhysposeError as err:
                failures.append({"variant": name, "clip": clip.name, "error": str(err)})
                log(f"benchmark: {name} on {clip.name} failed: {err}")
                continue
            results.append(record)
            log(f"benchmark: {name} on {clip.kind} {clip.name}: " + ", ".join(
                f"{k}={v:.3g}" for k, v in record["metrics"].items() if v is not None))
    return results, failures


def machine_description() -> str:
    """The machine, with what decides whether another machine's run gives the same digits: the
    processor and the kernels that each loaded OpenBLAS (NumPy's, SciPy's, OpenCV's) picked for
    it at run time (docs/benchmark.md, The same digits on another machine)."""
    kernels = openblas_kernels()
    blas = f"; OpenBLAS kernels {', '.join(kernels)}" if kernels else ""
    return (f"{platform.machine()}{_processor_name()}, {os.cpu_count()} cores (shared with "
            f"other work){blas}")


def openblas_kernels() -> list[str]:
    """Each loaded OpenBLAS's kernel name with the package that ships it, "SkylakeX (scipy)",
    sorted by package. Wheels keep their copy in a ``<package>.libs`` folder."""
    named = []
    for lib in threadpoolctl.threadpool_info():
        if lib.get("internal_api") != "openblas":
            continue
        path = str(lib.get("filepath", ""))
        folder = os.path.basename(os.path.dirname(path))
        owner = folder.removesuffix(".libs") if folder.endswith(".libs") else os.path.basename(path)
        named.append((owner, f"{lib.get('architecture')} ({owner})"))
    return [text for _, text in sorted(named)]


def _processor_name() -> str:
    """The processor's model name as ", NAME" (Linux's /proc/cpuinfo), or an empty string."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as info:
            for line in info:
                if line.startswith("model name"):
                    return f", {line.split(':', 1)[1].strip()}"
    except OSError:
        pass
    return ""


def results_document(results: list[dict], failures: list[dict], cfg: BenchmarkConfig, *,
                     skipped: Sequence[str] = (), command: str = "",
                     pending: Sequence[str] = ()) -> dict:
    """The document written to results.json (and rendered into results.md); with two or more
    variants it pairs them against ``cfg.base`` clip by clip ("paired"). `pending`: the
    material not run yet, where the document is written while the run goes on."""
    base = cfg.base
    return {
        "command": command,
        "machine": machine_description(),
        "config": asdict(cfg),
        "skipped": list(skipped),
        "pending": list(pending),
        "failures": failures,
        "results": results,
        "aggregate": aggregate(results),
        "paired_against": base,
        "paired": ({} if base is None else paired_differences(
            results, base, [v for v in cfg.variants if v != base])),
    }


def run_benchmark(materials: Sequence[Material], cfg: BenchmarkConfig = BenchmarkConfig(), *,
                  skipped: Sequence[str] = (), command: str = "",
                  log: Callable[[str], None] = _log,
                  on_progress: Callable[[dict], None] | None = None) -> dict:
    """Run every variant of `cfg` on every clip of `materials`; returns the results document.

    Problems a user can fix on one clip (PhysposeError: unreadable file, person not found, a
    variant refusing its input) are recorded under "failures" and the run goes on; anything
    else is a bug and propagates. on_progress gets the document so far after each piece of
    material (its "pending" naming the rest), so a run stopped midway (a bug, Ctrl-C, the
    machine) keeps what it finished.
    """
    for name in cfg.variants:
        get_variant(name)  # unknown names fail before any work is done
    results: list[dict] = []
    failures: list[dict] = []
    for i, material in enumerate(materials):
        log(f"benchmark: preparing {material.kind} {material.path}")
        try:
            clips = load_clips(material, cfg.material)
        except PhysposeError as err:
            failures.append({"variant": "-", "clip": str(material.path), "error": str(err)})
            log(f"benchmark: failed: {err}")
            clips = []
        done, failed = run_clips(clips, cfg.variants, log)
        results += done
        failures += failed
        if on_progress is not None and i + 1 < len(materials):
            on_progress(results_document(results, failures, cfg, skipped=skipped,
                                         command=command,
                                         pending=[str(m.path) for m in materials[i + 1:]]))
    return results_document(results, failures, cfg, skipped=skipped, command=command)
