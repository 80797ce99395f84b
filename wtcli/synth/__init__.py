"""Synthetic drone photos of wind turbines with instance masks and ground truth (``wtinspect
synth``; training data for the segmenter). See docs/synth.md."""

from wtcli.synth.render import (ALL_VIEWS, TRUTH_SCHEMA, TRUTH_VERSION, SynthSample,
                                parse_view_mix, render_dataset, render_sample, sample_seed)
from wtcli.synth.scene import VIEWS
from wtcli.synth.views import WIDE_VIEWS

__all__ = ["ALL_VIEWS", "TRUTH_SCHEMA", "TRUTH_VERSION", "VIEWS", "WIDE_VIEWS", "SynthSample",
           "parse_view_mix", "render_dataset", "render_sample", "sample_seed"]
