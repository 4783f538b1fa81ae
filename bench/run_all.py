"""Regenerate bench/RESULTS.md in one command:

    .venv/bin/python bench/run_all.py [--quick]

Measures, in one run on this machine: speed per mode/backend/rate and zoom fidelity on the shared scenes (on the
CPU backend's SIMD path in use: GBVIEWER_SIMD, else the best this CPU runs), every SIMD path of the CPU backend
against the scalar one at 640x480, the synthetic scaling series (splats and pixels), loading speed per format, and
the viewer's frame pacing in the real window under Xvfb (bench/viewer_pacing.py, ~1 min).
Plots go to bench/results/. It prints the time each part took and writes it at the end of RESULTS.md: on 2 cores
about 15-20 min in all (scenes ~10, of which the SIMD comparison ~1.5 with the scalar path as the slow part;
scaling to 10M splats ~4; loading ~1), --quick about 2 min."""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
SHARED = REPO.parent / "shared" / "scenes"
sys.path.insert(0, str(HERE))

import scaling  # noqa: E402
import viewer_pacing  # noqa: E402

import gbviewer as gb  # noqa: E402
from gbviewer import bench  # noqa: E402
from gbviewer.core.files import atomic_write  # noqa: E402
from gbviewer.model.camera import format_rate  # noqa: E402
from gbviewer.render import BACKENDS, RenderSettings  # noqa: E402

MODES = "scalar,mip,analytic,gaussian_blending,supersample:3,gaussian_blending:2"
RATES = [2.0, 1.0, 0.5, 0.25, 0.125]
UP = {"plant.splat": "-y", "v3dg-donut.fused.ply": "-y"}
SIMD_MODES = "scalar,gaussian_blending"  # the SIMD comparison: these modes at x1, SIMD_SIZE, every path
SIMD_SIZE = (640, 480)
BLEND_SPEEDUP_TARGET = {"gaussian_blending": 6.0, "scalar": 4.0}  # vector path's blend over the scalar path's, >=
GB_MS_TARGET = 100.0  # gaussian_blending frame ms at SIMD_SIZE on the vector path, median over the shared scenes, <=


def md_table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def scene_benchmarks(quick: bool) -> tuple[list, list, list, list[str]]:
    """Speed and fidelity on every shared scene (and the bundled one) on the SIMD path in use, and the SIMD
    comparison (SIMD_MODES at x1 and SIMD_SIZE on every path this CPU runs, taking turns render by render)."""
    paths = [gb.DEFAULT_SCENE] + sorted(p for p in SHARED.glob("*") if p.suffix in (".ply", ".splat", ".spz", ".sog"))
    if quick:
        paths = paths[:2]
    gpu = [b for b, cls in BACKENDS.items() if b != "cpu" and cls.available()[0]]
    settings = RenderSettings.parse_list(MODES)
    simd_settings = RenderSettings.parse_list(SIMD_MODES)
    simd_paths = bench.simd_paths()
    exp = bench.exp_rates(simd_paths)
    speed, fidelity, simd, names = [], [], [], []
    for path in paths:
        name = ("bundled: " if path == gb.DEFAULT_SCENE else "") + path.name
        if path != gb.DEFAULT_SCENE and path.name == gb.DEFAULT_SCENE.name:
            continue
        t0 = time.perf_counter()
        scene = gb.load(path)
        up = UP.get(path.name, "-y")
        cams = bench.bench_views(scene, 1 if quick else 2, 320, 240, up=up, multiple=8)
        # GPU backends on the bundled scene only: on a machine without a GPU they run on llvmpipe, slowly
        backends = ["cpu"] + (gpu if path == gb.DEFAULT_SCENE else [])
        speed += bench.measure_speed(scene, name, cams, settings, backends, [1.0, 0.125], 1 if quick else 3, exp=exp)
        fidelity += bench.measure_fidelity(scene, name, cams, settings, RATES, "cpu")
        big = bench.bench_views(scene, 1 if quick else 2, *SIMD_SIZE, up=up)
        simd += bench.measure_speed(
            scene, name, big, simd_settings, ["cpu"], [1.0], 1 if quick else 3, simd=simd_paths, exp=exp
        )
        names.append(name)
        print(f"measured {name} in {time.perf_counter() - t0:.0f} s", flush=True)
    return speed, fidelity, simd, names


def _shared(name: str) -> bool:
    return not name.startswith("bundled: ")


def targets(speed: list, fidelity: list, names: list[str], simd: list, in_use: str | None = None) -> list[list]:
    """The benchmark issues' targets, measured (CPU backend, x1, per scene; on the SIMD path in use, the vector path
    whose blend speedup over the scalar one is checked), with a last row for the median gaussian_blending frame
    time over the shared scenes."""
    rows = []
    t = {(r.scene, r.mode, r.rate): r.median_ms for r in speed if r.backend == "cpu"}
    f = {(r.scene, r.mode, r.rate): r.psnr for r in fidelity if r.kind == "zoom-out"}
    in_use = in_use or bench.current_simd()
    big = {(r.scene, r.simd_requested, r.mode): r for r in simd}
    gb_ms = {}
    for n in names:
        gb_ms_, sc_ms, ss_ms = (t.get((n, m, 1.0)) for m in ("gaussian_blending", "scalar", "scalar:3"))
        gb8, sc8, ss8 = (f.get((n, m, 0.125)) for m in ("gaussian_blending", "scalar", "scalar:3"))
        row = [
            n,
            f"{gb_ms_ / sc_ms:.2f} {'ok' if gb_ms_ <= 1.5 * sc_ms else 'MISSED'}",
            f"{ss_ms / gb_ms_:.2f} {'ok' if ss_ms >= 3 * gb_ms_ else 'MISSED'}",
            f"{gb8:.2f} vs {ss8:.2f} {'ok' if gb8 >= ss8 else 'MISSED'}",
            f"{gb8 - sc8:+.2f} {'ok' if gb8 - sc8 >= 6 else 'MISSED'}",
        ]
        for mode in ("gaussian_blending", "scalar"):
            base, vec = big.get((n, "scalar", mode)), big.get((n, in_use, mode))
            if in_use == "scalar" or base is None or vec is None:
                row.append("n/a (scalar path only) MISSED")
                continue
            x = base.stages_ms["blend_ms"] / max(vec.stages_ms["blend_ms"], 1e-9)
            row.append(f"{x:.1f}x {'ok' if x >= BLEND_SPEEDUP_TARGET[mode] else 'MISSED'}")
        vec = big.get((n, in_use, "gaussian_blending"))
        gb_ms[n] = vec.median_ms if vec is not None else float("nan")
        row.append(f"{gb_ms[n]:.0f}")
        rows.append(row)
    shared = [v for n, v in gb_ms.items() if _shared(n)] or list(gb_ms.values())
    med = statistics.median(shared) if shared else float("nan")
    label = "median over the shared scenes" if any(map(_shared, gb_ms)) else "median over the scenes"
    rows.append([label, "", "", "", "", "", "", f"{med:.0f} {'ok' if med <= GB_MS_TARGET else 'MISSED'}"])
    return rows


def target_header(in_use: str | None = None) -> list[str]:
    w, h = SIMD_SIZE
    in_use = in_use or bench.current_simd()
    return [
        "scene",
        "gaussian_blending / scalar (<= 1.5)",
        "scalar 3x3 / gaussian_blending (>= 3)",
        "x1/8 PSNR: GB vs scalar 3x3 (GB >=)",
        "x1/8 PSNR: GB - scalar (>= +6 dB)",
        f"GB blend speedup {in_use} over scalar at {w}x{h} (>= {BLEND_SPEEDUP_TARGET['gaussian_blending']:g})",
        f"scalar blend speedup {in_use} over scalar at {w}x{h} (>= {BLEND_SPEEDUP_TARGET['scalar']:g})",
        f"GB ms at {w}x{h}, {in_use} (median over the shared scenes <= {GB_MS_TARGET:g})",
    ]


FAST_GB_HEADING = "## Fast Gaussian Blending against scalar on the CPU"


def kept_section(path: Path, heading: str) -> list[str]:
    """The lines of the section `heading` of the markdown file `path` (up to the next "## "), or none."""
    lines = path.read_text().splitlines() if path.exists() else []
    if heading not in lines:
        return []
    start = lines.index(heading)
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
    return lines[start:end]


def ns_per_eval(r: dict, cores: int | None) -> float:
    """A scale row's blend time per splat-pixel evaluation and core, in ns."""
    return r["blend_ms"] * 1e6 * (cores or 1) / max(r["evals_per_pixel"] * r["width"] * r["height"], 1)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="two scenes, one view, small scaling series")
    args = parser.parse_args()
    out_dir = HERE / "results"
    out_dir.mkdir(exist_ok=True)

    started = time.perf_counter()
    times = {}
    speed, fidelity, simd, names = scene_benchmarks(args.quick)
    times["scenes"] = time.perf_counter() - started
    info = bench.simd_info(bench.simd_paths())
    bench.write_json(out_dir / "scenes.json", speed + simd, fidelity, force=True, simd=info)
    plots = bench.write_plots(out_dir, speed, fidelity, force=True)
    t0 = time.perf_counter()
    scale = scaling.run(300_000 if args.quick else 10_000_000, 1 if args.quick else 2, ["scalar", "gaussian_blending"])
    atomic_write(out_dir / "scaling.json", lambda p: p.write_text(json.dumps(scale, indent=2)), force=True)
    times["scaling"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    load = subprocess.run(
        [sys.executable, str(HERE / "load_speed.py"), "--n", "100000" if args.quick else "1000000"],
        capture_output=True,
        text=True,
    )
    times["loading"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    pacing_json = out_dir / "viewer_pacing.json"
    pacing = subprocess.run(
        [sys.executable, str(HERE / "viewer_pacing.py"), "--json", str(pacing_json)]
        + (["--cycles", "1"] if args.quick else []),
        capture_output=True,
        text=True,
    )
    pacing_lines = (
        viewer_pacing.markdown(json.loads(pacing_json.read_text()))
        if pacing.returncode == 0
        else ["```", (pacing.stderr or pacing.stdout).strip()[-2000:], "```"]
    )
    times["viewer pacing"] = time.perf_counter() - t0

    machine = bench.machine_description()
    w, h = SIMD_SIZE
    lines = [
        "# Benchmark results",
        "",
        f"Regenerated by `.venv/bin/python bench/run_all.py`{' --quick' if args.quick else ''}. Machine: "
        f"{machine['cpu']}, {machine['cores']} cores, Python {machine['python']}"
        + "".join(f"; {k}: {v}" for k, v in machine.items() if k.endswith("_backend"))
        + ".",
        f"{bench.simd_summary(info)}.",
        "Times are medians over repeats and views; ratios come from the same run.",
        "",
    ]
    lines += [
        f"## Targets (CPU backend, 320x240 at x1, orbit views; SIMD comparison at {w}x{h})",
        "",
        md_table(target_header(), targets(speed, fidelity, names, simd)),
        "",
    ]
    lines += [
        f"## SIMD paths of the CPU backend ({w}x{h} at x1)",
        "",
        "Every path measured in the same run, taking turns render by render. Speedup: the scalar path's ms / "
        "the path's. Mevals/s/core: splat-pixel evaluations per second per core in the blend stage; exp: "
        "that path's exp evaluations per second on one core (`gbviewer._native.testing.exp_rate`). max abs diff: the "
        "largest rgb difference from the scalar path's image.",
        "",
    ]
    header, rows = bench.simd_table(simd)
    exp_rate = info["exp_per_s_per_core"]
    lines += [
        md_table(header, rows) if rows else "(this CPU runs the scalar path only)",
        "",
        "exp per core: " + ", ".join(f"{p} {v / 1e6:.0f} M/s" for p, v in exp_rate.items()),
        "",
    ]
    lines += [
        "## Speed per mode (x1 and x1/8)",
        "",
        md_table(
            [
                "scene",
                "backend",
                "simd",
                "mode",
                "rate",
                "size",
                "ms",
                "preprocess",
                "sort",
                "blend",
                "evals/px",
                "Mevals/s/core",
                "blend Mevals/s/core",
                "exp M/s/core",
            ],
            [
                [
                    r.scene,
                    r.backend,
                    r.simd or "-",
                    r.mode,
                    format_rate(r.rate),
                    f"{r.width}x{r.height}",
                    f"{r.median_ms:.1f}",
                    f"{r.stages_ms['preprocess_ms']:.1f}",
                    f"{r.stages_ms['sort_ms']:.1f}",
                    f"{r.stages_ms['blend_ms']:.1f}",
                    f"{r.evals_per_pixel:.0f}",
                    f"{r.mevals_per_s_per_core:.0f}",
                    f"{r.blend_mevals_per_s_per_core:.0f}",
                    "-" if r.exp_mevals_per_s_per_core is None else f"{r.exp_mevals_per_s_per_core:.0f}",
                ]
                for r in speed
            ],
        ),
        "",
    ]
    modes = list(dict.fromkeys(r.mode for r in fidelity))
    for kind, rates in (("zoom-out", [r for r in RATES if r < 1]), ("zoom-in", [r for r in RATES if r > 1])):
        ref = "the x1 scalar render box-downsampled" if kind == "zoom-out" else "the x1 render of the same mode"
        lines += [f"## {kind.capitalize()} fidelity: PSNR dB (SSIM) against {ref}", ""]
        rows = []
        for n in names:
            for rate in rates:
                vals = {r.mode: r for r in fidelity if r.scene == n and r.rate == rate and r.kind == kind}
                rows.append(
                    [n, format_rate(rate)]
                    + [f"{vals[m].psnr:.2f} ({vals[m].ssim:.3f})" if m in vals else "" for m in modes]
                )
        lines += [md_table(["scene", "rate"] + modes, rows), ""]
    lines += [
        "## Scaling (synthetic scenes, CPU backend)",
        "",
        "Splat series at 640x480; pixel series at 300k splats. Peak RSS is the whole process. SIMD path: "
        + ", ".join(sorted({str(r.get("simd")) for r in scale["splats"] + scale["pixels"]}))
        + ".",
        "",
        md_table(
            [
                "mode",
                "splats",
                "size",
                "ms",
                "preprocess",
                "sort",
                "blend",
                "sort length",
                "evals/px",
                "ns per evaluation x cores",
                "peak RSS MiB",
            ],
            [
                [
                    r["mode"],
                    f"{r['splats']:,}",
                    f"{r['width']}x{r['height']}",
                    f"{r['total_ms']:.1f}",
                    f"{r['preprocess_ms']:.1f}",
                    f"{r['sort_ms']:.1f}",
                    f"{r['blend_ms']:.1f}",
                    f"{r['sort_length']:,}",
                    f"{r['evals_per_pixel']:.0f}",
                    f"{ns_per_eval(r, machine['cores']):.1f}",
                    f"{r['peak_rss_mib']:.0f}",
                ]
                for r in scale["splats"] + scale["pixels"]
            ],
        ),
        "",
    ]
    lines += ["## Loading speed", "", "```", (load.stdout or load.stderr).strip(), "```", ""]
    lines += ["## Viewer frame pacing", ""] + pacing_lines + [""]
    lines += kept_section(HERE / "RESULTS.md", "## Scale")  # bench/scale.py's, run on its own (minutes per scene)
    lines += kept_section(HERE / "RESULTS.md", FAST_GB_HEADING)  # measured by hand: CPU-time ratios, alternating runs
    lines += ["## Plots", ""] + [f"![{p.stem}](results/{p.name})" for p in plots] + [""]
    times["total"] = time.perf_counter() - started
    lines += ["## Run time", "", ", ".join(f"{k} {v / 60:.1f} min" for k, v in times.items()), ""]
    atomic_write(HERE / "RESULTS.md", lambda p: p.write_text("\n".join(lines)), force=True)

    print(
        f"wrote {HERE / 'RESULTS.md'} in {times['total'] / 60:.1f} min "
        f"({', '.join(f'{k} {v / 60:.1f}' for k, v in times.items() if k != 'total')})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
