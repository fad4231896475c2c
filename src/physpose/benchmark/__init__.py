"""The benchmark: run pipeline variants on motion capture, a multi-view reference and real videos.

Public API: `run_benchmark`, `BenchmarkConfig`, `Material`, `MaterialConfig`, `shared_material`,
`write_results`, and the variant registry (`register_variant`, `get_variant`, `VARIANTS`,
`VariantContext`). See docs/benchmark.md.
"""

from physpose.benchmark.material import Material, MaterialConfig, shared_material
from physpose.benchmark.report import write_results
from physpose.benchmark.runner import BenchmarkConfig, run_benchmark
from physpose.benchmark.variants import (VARIANTS, VariantContext, available_variants,
                                         get_variant, register_variant)

__all__ = ["Material", "MaterialConfig", "shared_material", "write_results", "BenchmarkConfig",
           "run_benchmark", "VARIANTS", "VariantContext", "available_variants", "get_variant",
           "register_variant"]
