"""What accuracy costs in time: the benchmark study, its report, the speed suite.

* :mod:`~draaw_mi.bench.study` -- :func:`run_study` (error vs time per version and spp against a
  cached ground truth) and :func:`frame_times` (GO-Draaw's frame-time statistics);
* :mod:`~draaw_mi.bench.bias` -- bias told apart from noise; :mod:`~draaw_mi.bench.metrics` --
  RMSE, relative MSE, CIEDE2000; :mod:`~draaw_mi.bench.report` -- JSON, CSV, Markdown, plots;
* :mod:`~draaw_mi.bench.suite` and :mod:`~draaw_mi.bench.speed` -- the speed suite (eighteen
  scenes of different kinds, time to ``path``'s error); :mod:`~draaw_mi.bench.reference_scenes` -- small
  reference scenes of the integrator tests;
* :mod:`~draaw_mi.bench.sdf_study` -- the sphere tracer's accuracy against its cost;
* :mod:`~draaw_mi.bench.code_digest` -- a hash of the render code, naming cached references.
"""
from __future__ import annotations

from .._lazy import old_names
from .study import DEFAULT_VERSIONS, Setting, frame_times, ground_truth, measure, run_study

__all__ = ["DEFAULT_VERSIONS", "Setting", "frame_times", "ground_truth", "measure", "run_study"]

# names draaw_mi/bench.py had, served from their new modules with a DeprecationWarning
__getattr__ = old_names(__name__, {
    **dict.fromkeys(("WARMUP_AGAIN_S", "ground_truth_depth", "load_note", "measure_group", "reference_version",
                     "scene_versions", "with_load_note"), f"{__name__}.study"),
    "estimate_bias": f"{__name__}.bias"})
