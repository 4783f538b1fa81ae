"""Benchmarks: speed per mode, backend, sampling rate and SIMD path of the CPU backend; zoom fidelity (PSNR/SSIM)
against box-downsampled references; flicker along a zoom (gbviewer.outputs.flicker); sorted against order-independent
modes. Everything measured in one run (`run_bench`), reported as tables, JSON and plots (`report`)."""

from .fidelity import FidelityRow, fidelity_cost, measure_fidelity
from .oit import OitRow, measure_oit, oit_cost, oit_settings
from .report import (
    machine_description,
    plot_path,
    print_flicker,
    print_oit,
    print_tables,
    simd_table,
    write_json,
    write_plots,
)
from .run import BenchResult, bench_views, run_bench, select_backends
from .simd import SIMD_NAMES, current_simd, exp_rates, parse_simd, set_simd, simd_info, simd_paths, simd_summary
from .speed import STAGES, SpeedRow, measure_speed, ratios, render_cost, speed_cost
from .stability import FlickerRow, measure_stability, stability_cost

__all__ = [
    "SIMD_NAMES",
    "STAGES",
    "BenchResult",
    "FidelityRow",
    "FlickerRow",
    "OitRow",
    "SpeedRow",
    "bench_views",
    "current_simd",
    "exp_rates",
    "fidelity_cost",
    "machine_description",
    "measure_fidelity",
    "measure_oit",
    "measure_speed",
    "measure_stability",
    "oit_cost",
    "oit_settings",
    "parse_simd",
    "plot_path",
    "print_flicker",
    "print_oit",
    "print_tables",
    "ratios",
    "render_cost",
    "run_bench",
    "select_backends",
    "set_simd",
    "simd_info",
    "simd_paths",
    "simd_summary",
    "simd_table",
    "speed_cost",
    "stability_cost",
    "write_json",
    "write_plots",
]
