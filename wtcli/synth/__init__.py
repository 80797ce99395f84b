"""Synthetic drone photos of wind turbines with instance masks and ground truth (``wtinspect
synth``; training data for the segmenter). See docs/synth.md."""

from wtcli.synth.render import (TRUTH_SCHEMA, TRUTH_VERSION, SynthSample, render_dataset,
                                render_sample, sample_seed)
from wtcli.synth.scene import VIEWS

__all__ = ["TRUTH_SCHEMA", "TRUTH_VERSION", "VIEWS", "SynthSample", "render_dataset",
           "render_sample", "sample_seed"]
