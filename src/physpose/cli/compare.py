"""`physpose compare`: benchmark variants paired clip by clip, across one or more runs."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict
from pathlib import Path

from physpose.benchmark.material import MaterialConfig
from physpose.benchmark.paired import (load_results, merge_results, paired_differences,
                                       pooled_clip, run_labels)
from physpose.benchmark.report import render_paired
from physpose.benchmark.scoring import TRUTH_ROW
from physpose.errors import PhysposeError
from physpose.paths import check_output_file
from physpose.json_text import strict_json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compare", help="paired differences between benchmark variants, across runs",
        description="Read results.json files written by `physpose benchmark` (e.g. a new "
                    "variant's run and an earlier run of the default on the same clips) and "
                    "print, per kind of material, each variant's per-clip differences from the "
                    "base variant: their mean and standard error. Where two files have the "
                    "same variant on the same clip, the later file's record is used, unless "
                    "--by-run names each run's variants apart or --pool each run's clips.")
    p.add_argument("results", nargs="+", type=Path, metavar="RESULTS",
                   help="results.json of a benchmark run, or its --out folder")
    p.add_argument("--base", required=True, metavar="NAME",
                   help="the variant the others are compared with, e.g. dynamics")
    p.add_argument("--variant", action="append", default=[], metavar="NAME",
                   help="compare only these variants (repeatable; default: all but the base)")
    apart = p.add_mutually_exclusive_group()
    apart.add_argument("--by-run", action="store_true",
                       help="name every variant NAME@RUN (RUN: the results folder's name) so "
                            "the same variant in two runs is compared, e.g. --base dynamics@old")
    apart.add_argument("--pool", action="store_true",
                       help="name every clip CLIP@RUN so each run's clips count apart: the "
                            "variants are paired within each run and their differences pooled "
                            "over the runs (the same clips under several seeds); the standard "
                            "error treats each clip's runs as one group (cluster-robust), as "
                            "they are not independent")
    p.add_argument("--out", type=Path, metavar="FILE",
                   help="also write the comparison: FILE.md (markdown) or FILE.json")
    p.set_defaults(func=run)


def _material(doc: dict) -> dict | None:
    """A run's material settings, those it predates taken at their defaults (a setting added
    later did not change how the older run prepared its material)."""
    material = doc.get("config", {}).get("material")
    return None if material is None else {**asdict(MaterialConfig()), **material}


def run(args: argparse.Namespace) -> int:
    docs = [load_results(path) for path in args.results]
    labels = run_labels(args.results)
    results = merge_results(docs, labels if args.by_run else None,
                            labels if args.pool else None)
    present = list(dict.fromkeys(r["variant"] for r in results if r["variant"] != TRUTH_ROW))
    missing = [v for v in [args.base, *args.variant] if v not in present]
    if missing:
        raise PhysposeError(f"variant(s) {', '.join(missing)} not in the results given",
                            path=", ".join(str(p) for p in args.results),
                            remedy=f"choose from: {', '.join(present)}")
    variants = [v for v in (args.variant or present) if v != args.base]
    if not variants:
        raise PhysposeError(f"nothing to compare with {args.base!r}: no other variant chosen "
                            "or in the results",
                            remedy="name another variant with --variant, or add the results.json "
                                   "of a run with one")
    if args.out is not None:
        check_output_file(args.out)
    configs = {json.dumps(_material(doc), sort_keys=True) for doc in docs}
    if len(configs) > 1 and not args.pool:  # pooled runs differ in their seeds by design
        print("physpose compare: note: the runs prepared their material differently (seed, "
              "length, camera...); their clips are compared as they are", file=sys.stderr)
    for path, doc in zip(args.results, docs):
        if doc.get("pending"):  # written while its run went on (stopped, or still running)
            print(f"physpose compare: note: {path} is incomplete, {len(doc['pending'])} piece(s) "
                  "of material still to come; only the clips it finished are compared",
                  file=sys.stderr)
    # Pooled, a clip's runs are not independent draws: the standard error is over the clips.
    paired = paired_differences(results, args.base, variants,
                                group=pooled_clip if args.pool else None)
    if not paired:
        raise PhysposeError(f"no clip has both {args.base!r} and another variant",
                            remedy="compare runs made on the same clips")
    text = "\n".join(render_paired(paired, args.base))
    print(text)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        if args.out.suffix == ".json":
            args.out.write_text(strict_json({"base": args.base, "paired": paired}, indent=1)
                                + "\n")
        else:
            args.out.write_text(text + "\n")
        print(f"wrote {args.out}")
    return 0
