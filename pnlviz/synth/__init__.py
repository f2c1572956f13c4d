"""Synthetic broadcast frames with exact ground truth (test oracles for calibration).

* :func:`sample_camera` - broadcast-like random cameras (main, closeup, behind_goal, reverse);
* :func:`render_frame` / :func:`render` - per-pixel ray-cast rendering of a stadium;
* :func:`annotate` - SoccerNet line annotations the official evaluator scores 1.0 for the
  ground-truth camera;
* :func:`generate` - the ``pnlviz synth`` output folder (images, annotations, cameras/).
"""

from .annotate import annotate, annotation_to_json, evaluation_camera
from .cameras import KINDS, camera_problem, sample_camera
from .render import RenderResult, render, render_frame
from .writer import OutputFolderError, SynthSummary, check_output_folder, generate, make_frame

__all__ = ["KINDS", "sample_camera", "camera_problem", "render", "render_frame", "RenderResult", "annotate",
           "annotation_to_json", "evaluation_camera", "generate", "make_frame", "check_output_folder",
           "OutputFolderError", "SynthSummary"]
