"""``aniso3d bench``: the speed/accuracy trade of every renderer and setting, in numbers.

For one scene (the built-in tree, or any mesh) the bench renders each
configuration, times it, and compares its image with a ground truth: the
polygon model supersampled, drawn with the same camera, lights and image size.
The paper claims that the anisotropic texture reduces data and aliases less
than polygons; this turns both claims into numbers, and gives users the tool
for their own scenes.

The modules follow one run from settings to report:

- :mod:`~aniso3d.bench.settings`: what a run sweeps, the presets;
- :mod:`~aniso3d.bench.cameras`: the camera distances and scoring boxes;
- :mod:`~aniso3d.bench.plan`: the cases to measure and their blocks;
- :mod:`~aniso3d.bench.run`: builds, renders, timings and image errors, one row per case;
- :mod:`~aniso3d.bench.analyse`: Pareto front, recommendations, summaries;
- :mod:`~aniso3d.bench.plots`: the figures (matplotlib, optional);
- :mod:`~aniso3d.bench.report`: the Markdown report, one function per section;
- :mod:`~aniso3d.bench.outputs`: CSV, JSON and writing everything.

Beside the sweep, the corpus bench (``aniso3d bench --corpus``) runs every
built-in scene at the default texture and checks the method's targets per scene:

- :mod:`~aniso3d.bench.corpus`: settings, cameras, flicker, targets, the run;
- :mod:`~aniso3d.bench.corpus_report`: corpus_bench.md, .csv and .json.

The command line (``aniso3d/app/bench_cmd.py``) loads the input and calls
:func:`run_bench` and :func:`write_outputs`.
"""

from __future__ import annotations

from aniso3d.bench.analyse import in_block, label, mark_pareto, pareto_front, recommend
from aniso3d.bench.cameras import CameraSpec, crop_box, make_cameras, near_far, pixels_per_unit
from aniso3d.bench.corpus import CorpusResult, CorpusSettings, corpus_settings, run_corpus
from aniso3d.bench.corpus_report import write_corpus
from aniso3d.bench.outputs import columns_of, to_csv, to_json, write_outputs
from aniso3d.bench.plan import Case, plan_cases, splat_case, volume_case
from aniso3d.bench.plots import PLOTS, matplotlib_available
from aniso3d.bench.report import make_report
from aniso3d.bench.run import COLOUR_SPACE, COLUMNS, BenchResult, blank_row, classify_failure, run_bench
from aniso3d.bench.settings import AXES, PRESETS, RENDERERS, SPLAT_AXES, Settings, preset_settings

__all__ = [
    "AXES", "COLOUR_SPACE", "COLUMNS", "PLOTS", "PRESETS", "RENDERERS", "SPLAT_AXES",
    "BenchResult", "CameraSpec", "Case", "CorpusResult", "CorpusSettings", "Settings",
    "blank_row", "classify_failure", "columns_of", "corpus_settings", "crop_box", "in_block", "label",
    "make_cameras", "make_report", "mark_pareto", "matplotlib_available", "near_far", "pareto_front",
    "pixels_per_unit", "plan_cases", "preset_settings", "recommend", "run_bench", "run_corpus", "splat_case",
    "to_csv", "to_json", "volume_case", "write_corpus", "write_outputs",
]  # fmt: skip
