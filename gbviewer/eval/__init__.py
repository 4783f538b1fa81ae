"""Evaluation against a scene's training photos (`gbviewer eval`): multi-scale ground truth (alpha-aware box
downsampling, cached), PSNR and SSIM per mode and sampling rate over a split's views, run in this process, a
process pool or on Ray, reported as the paper's tables, JSON and plots.

For the viewer: `ground_truth(view, rate, background, cache)` is a view's photo at a rate, and
`camera_for_rate(view.camera, rate)` the camera whose render matches its pixels."""

from .multiscale import camera_for_rate, default_cache, ground_truth, ground_truths, rate_factor
from .report import plot_paths, print_tables, to_json, write_json, write_plots
from .run import EvalResult, SceneEval, run_eval
from .tasks import ViewResult, ViewTask, evaluate_view

__all__ = [
    "EvalResult",
    "SceneEval",
    "ViewResult",
    "ViewTask",
    "camera_for_rate",
    "default_cache",
    "evaluate_view",
    "ground_truth",
    "ground_truths",
    "plot_paths",
    "print_tables",
    "rate_factor",
    "run_eval",
    "to_json",
    "write_json",
    "write_plots",
]
