"""Render ``docs/benchmarks.md`` from ``benchmarks/results/*.json``.

    python benchmarks/report.py            # write docs/benchmarks.md
    python benchmarks/report.py --check    # exit 1 if docs/benchmarks.md differs from what it renders

It also renders the block of figures that ``BLOCKS`` names in other pages (the model card).

Every headline figure of the project is listed in ``SECTIONS`` below: which results file holds it
(written by the benchmark through ``benchmarks/_results.py``, with the command, date and machine
that made it), under which key, and how it is shown. A benchmark whose results file does not
exist yet is shown as "not measured yet" with the command that measures it, never with an old
number. A results file that lacks a key named here is an error naming both, so the page and the
files cannot drift apart unnoticed (``tests/test_benchmarks_report.py`` runs ``--check``).
"""

from __future__ import annotations

import argparse
import difflib
import json
import re
import sys
import textwrap
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
DOC = ROOT / "docs" / "benchmarks.md"
WIDTH = 100
# Other pages that show some sections' figures, between these two lines (rendered as one table).
BLOCKS: dict[str, tuple[str, ...]] = {
    "models/README.md": ("Segmentation: held-out renders", "Segmentation: real photos, cross-validated",
                         "Segmentation: speed"),
}
BEGIN = "<!-- figures: rendered by `python benchmarks/report.py` from benchmarks/results; edit there -->"
END = "<!-- end of rendered figures -->"


class ReportError(Exception):
    """A results file that cannot be read, or lacks a figure this page shows."""


@dataclass(frozen=True)
class Figure:
    label: str
    keys: tuple[str, ...]   # dotted paths into the results file; ``[k=v]`` picks a list item
    fmt: str                # str.format template over the values, in the order of ``keys``
    goal: str = ""


@dataclass(frozen=True)
class Section:
    title: str
    name: str               # benchmarks/NAME.py writes benchmarks/results/NAME.json
    command: str            # the command that measures it (shown while not measured yet)
    about: str
    figures: tuple[Figure, ...] = field(default_factory=tuple)
    # For a benchmark that does not write its results file yet: the ``save`` call at the end of
    # its main() that gives the keys below (what it computes today). A benchmark may save other
    # keys; then its figures here change with it.
    adopt: str = ""


F = Figure
SECTIONS: tuple[Section, ...] = (
    Section(
        "Segmentation: held-out renders", "segment_accuracy",
        "python benchmarks/segment_accuracy.py --threads 2",
        "The shipped segmenter and edge refiner as `segment` runs them (wide look, second look, mirror pass, "
        "refined edges, bfloat16 trunk where the CPU has it) on 300 renders at 640 × 480 that no "
        "training run saw (seeds 9 000 000 +, 200 of them front views). Mask IoU and AP50 against "
        "the renderer's outline labels; blade count and angle through segment → contours → pitch.",
        (F("mask IoU blade / tower / nacelle",
           ("synthetic.refined.blade_mask_iou", "synthetic.refined.tower_mask_iou",
            "synthetic.refined.nacelle_mask_iou"), "{:.3f} / {:.3f} / {:.3f}", "≥ 0.85 / 0.80 / 0.80"),
         F("class map IoU blade / tower / nacelle (`classes/NAME.png`: one class a pixel)",
           ("synthetic.refined.blade_class_map_iou", "synthetic.refined.tower_class_map_iou",
            "synthetic.refined.nacelle_class_map_iou"), "{:.3f} / {:.3f} / {:.3f}"),
         F("AP50 blade / tower / nacelle",
           ("synthetic.refined.blade_ap50", "synthetic.refined.tower_ap50",
            "synthetic.refined.nacelle_ap50"), "{:.3f} / {:.3f} / {:.3f}"),
         F("front views read with the right blade count",
           ("synthetic.front_right_blade_count", "synthetic.front_views"), "{:.1%} of {}", "≥ 95 %"),
         F("blade angle θ error, mean / median / p95",
           ("synthetic.theta_error_mean_deg", "synthetic.theta_error_median_deg",
            "synthetic.theta_error_p95_deg", "synthetic.theta_blades_measured"),
           "{:.2f}° / {:.2f}° / {:.2f}° ({} blades)", "mean ≤ 2°"),
         F("mask IoU without the edge refiner, blade / tower / nacelle",
           ("synthetic.zoom.blade_mask_iou", "synthetic.zoom.tower_mask_iou",
            "synthetic.zoom.nacelle_mask_iou"), "{:.3f} / {:.3f} / {:.3f}"))),
    Section(
        "Segmentation: real photos, the renders-only model", "segment_real",
        "python benchmarks/segment_real.py --model renders-only.pt --out benchmarks/results/segment_real.json",
        "For comparison: the model shipped until 2026-12-06, trained on renders only (`git show "
        "5d1df58:models/wtseg-r18s.pt > renders-only.pt`), so that every photo of the WTA dataset "
        "folder is held out for it (G. Zampokas et al., \"WTA/TLA: A UAV-captured Dataset for "
        "Semantic Segmentation of Energy Infrastructure\", ICUAS 2022, "
        "doi:10.1109/ICUAS54217.2022.9836096), segmented as `segment` does by default and its "
        "class map (one class a pixel) scored against the photos' semantic masks; tower is "
        "scored as tower ∪ nacelle against the photos' tower class.",
        (F("blade / tower IoU, pooled", ("pooled.blade_iou", "pooled.tower_iou", "pooled.photos"),
           "{:.3f} / {:.3f} ({} photos)"),
         F("the same, the classes' instance unions (a pixel in two classes' masks counts for both)",
           ("pooled.blade_iou_union", "pooled.tower_iou_union"), "{:.3f} / {:.3f}"),
         F("front views with three true blades read as three",
           ("pooled.front_exactly_3", "pooled.front_views_3_true_blades"), "{:.0%} of {}"),
         F("blade angle θ error on them, mean", ("pooled.theta_error_deg_mean", "pooled.blades_matched"),
           "{:.2f}° ({} blades)")),
        adopt='save("segment_real", res, argv=argv, out=args.out)'),
    Section(
        "Segmentation: real photos, cross-validated", "segment_real_finetune",
        "python benchmarks/segment_real.py --runs runs/cv --train ARGS",
        "The shipped model's recipe (docs/train.md, \"Fine-tuning on the real photos\"): the "
        "renders-only model fine-tuned for 400 steps of 2 images on renders and 25 % real photos, "
        "once per flight sequence with that sequence held out; each photo measured with its own "
        "fold's model, segmented as `segment` does by default, its class map (one class a pixel) "
        "scored against the photos' semantic masks. The shipped model is the same recipe "
        "on all 104 photos, so these are its figures on photos it has not seen. \"Every part a "
        "pixel wider\" is a diagnostic, not what `segment` writes: the photos' hand-drawn outline "
        "runs about a pixel outside the edge the renders' labels, and so the masks, follow "
        "(docs/train.md, \"The photos' outline\").",
        (F("blade / tower IoU, pooled", ("pooled.blade_iou", "pooled.tower_iou", "pooled.photos"),
           "{:.3f} / {:.3f} ({} photos)", "≥ 0.80 / 0.80"),
         F("the same, the classes' instance unions (a pixel in two classes' masks counts for both)",
           ("pooled.blade_iou_union", "pooled.tower_iou_union"), "{:.3f} / {:.3f}"),
         F("the same, every part a pixel wider (diagnostic)",
           ("pooled.blade_iou_grown", "pooled.tower_iou_grown"), "{:.3f} / {:.3f}"),
         F("blade pixels the photos' masks hold beyond ours (within 2 px): median share of the "
           "blade's contrast they carry",
           ("outline_tint.missed.p50", "outline_tint.beyond.p50", "outline_tint.edge.p50"),
           "{:.2f} (the background just outside the photos' masks {:.2f}, our masks' edge {:.2f})"),
         F("blade / tower IoU on close-ups", ("per_view.close-up.blade_iou", "per_view.close-up.tower_iou",
                                              "per_view.close-up.photos"),
           "{:.3f} / {:.3f} ({} photos)", "≥ 0.80"),
         F("blade IoU on the distant photos", ("per_view.distant.blade_iou", "per_view.distant.photos"),
           "{:.3f} ({} photos)"),
         F("front views with three true blades read as three",
           ("pooled.front_exactly_3", "pooled.front_views_3_true_blades"), "{:.0%} of {}", "≥ 95 %"),
         F("blade angle θ error on them, mean", ("pooled.theta_error_deg_mean", "pooled.blades_matched"),
           "{:.2f}° ({} blades)", "≤ 1°"))),
    Section(
        "Segmentation: real photos, cross-validated, a refiner tuned on the photos (not shipped)",
        "segment_real_refiner",
        "python benchmarks/segment_real.py --runs runs/cv --train-refiner ARGS --out "
        "benchmarks/results/segment_real_refiner.json",
        "The same folds' networks as above, each fold's edges refined by the shipped refiner "
        "fine-tuned on renders and the other folds' photos (`train-refiner --real`, "
        "docs/train-refiner.md, \"Fine-tuning on labelled photos\"). Not shipped: it moves the "
        "renders' edges as it "
        "moves the photos', and the held-out renders lose what the photos gain (that page).",
        (F("blade / tower IoU, pooled", ("pooled.blade_iou", "pooled.tower_iou", "pooled.photos"),
           "{:.3f} / {:.3f} ({} photos)"),
         F("blade / tower IoU on close-ups", ("per_view.close-up.blade_iou", "per_view.close-up.tower_iou",
                                              "per_view.close-up.photos"),
           "{:.3f} / {:.3f} ({} photos)"),
         F("blade IoU on the distant photos", ("per_view.distant.blade_iou", "per_view.distant.photos"),
           "{:.3f} ({} photos)"),
         F("blade angle θ error on front views, mean",
           ("pooled.theta_error_deg_mean", "pooled.blades_matched"), "{:.2f}° ({} blades)"))),
    Section(
        "Segmentation: the wider views, on renders", "segment_views",
        "python benchmarks/segment_views.py --threads 2",
        "The shipped segmenter, as `segment` runs it, on the renderer's wider views (docs/synth.md): "
        "20 renders of each at 768 × 576 that no run saw (seeds 9 600 000 +). IoU of each class's "
        "union mask against the renderer's labels, averaged over the renders that have the class; "
        "\"tower read as blade\": the share of the true tower's pixels under a blade instance, and "
        "the renders where that is 10 % or more. Then whole turbines (the held-out set's mix) at "
        "1920 × 1080, the real photos' size, and at 768 × 576, the size the network trained at "
        "(40 each, seeds 9 700 000 +): \"a false blade\" is a render where blade instances cover "
        "3 % of the frame or more outside the true blades (sky, haze or a hill read as a blade).",
        (F("blade close-ups filling the frame: blade IoU", ("per_view.closeup.blade_iou",), "{:.3f}"),
         F("nadir and steep-down views: blade / tower / nacelle IoU",
           ("per_view.nadir.blade_iou", "per_view.nadir.tower_iou", "per_view.nadir.nacelle_iou"),
           "{:.3f} / {:.3f} / {:.3f}"),
         F("nadir: the tower read as blade (share of its pixels; renders with 10 % or more)",
           ("per_view.nadir.tower_as_blade", "per_view.nadir.tower_as_blade_renders",
            "per_view.nadir.renders_with_tower"), "{:.1%}; {:.0%} of {}", "none"),
         F("close hub views from above: blade / tower / nacelle IoU",
           ("per_view.hub.blade_iou", "per_view.hub.tower_iou", "per_view.hub.nacelle_iou"),
           "{:.3f} / {:.3f} / {:.3f}"),
         F("frames cutting the nacelle, hub and blade ends: blade / tower / nacelle IoU",
           ("per_view.cut.blade_iou", "per_view.cut.tower_iou", "per_view.cut.nacelle_iou"),
           "{:.3f} / {:.3f} / {:.3f}"),
         F("side-on broad blades: blade / tower IoU",
           ("per_view.broadside.blade_iou", "per_view.broadside.tower_iou"), "{:.3f} / {:.3f}"),
         F("a blade in front of the tower: blade / tower IoU; the blade read as tower",
           ("per_view.overtower.blade_iou", "per_view.overtower.tower_iou",
            "per_view.overtower.blade_as_tower"), "{:.3f} / {:.3f}; {:.1%}"),
         F("distant turbines among distractors: blade / tower IoU",
           ("per_view.distant.blade_iou", "per_view.distant.tower_iou"), "{:.3f} / {:.3f}"),
         F("all of them: blade / tower / nacelle IoU",
           ("pooled.blade_iou", "pooled.tower_iou", "pooled.nacelle_iou", "pooled.renders"),
           "{:.3f} / {:.3f} / {:.3f} ({} renders)"),
         F("whole turbines at 1920 × 1080 / at 768 × 576: blade IoU",
           ("per_size.1920x1080.blade_iou", "per_size.768x576.blade_iou"), "{:.3f} / {:.3f}"),
         F("whole turbines at 1920 × 1080 / at 768 × 576: renders with a false blade",
           ("per_size.1920x1080.false_blade_renders", "per_size.768x576.false_blade_renders",
            "per_size.1920x1080.renders"), "{} / {} of {} each", "none"))),
    Section(
        "Segmentation: speed", "segment_accuracy",
        "python benchmarks/segment_accuracy.py --threads 2",
        "One 1024 × 683 render, images per second in one process with the same thread count, "
        "against torchvision's stock `maskrcnn_resnet50_fpn` on the same input. Timings move by "
        "10–20 % between runs on a shared machine; the ratio is the comparison.",
        (F("stock `maskrcnn_resnet50_fpn`", ("speed.stock_r50_fpn_images_per_s",), "{:.3f} images/s"),
         F("the network with its mirror pass", ("speed.speedup_vs_stock", "speed.ours_images_per_s"),
           "{:.1f}× ({:.2f} images/s)", "≥ 5×"),
         F("the same, edges refined", ("speed.speedup_vs_stock_refined", "speed.ours_refined_images_per_s"),
           "{:.1f}× ({:.2f} images/s)", "≥ 5×"),
         F("the network with its mirror pass in float32 (a CPU without native bfloat16)",
           ("speed.speedup_vs_stock_fp32", "speed.ours_fp32_images_per_s"), "{:.1f}× ({:.2f} images/s)"),
         F("without the mirror pass (`--no-flip`)",
           ("speed.speedup_vs_stock_no_flip", "speed.ours_no_flip_images_per_s"), "{:.1f}× ({:.2f} images/s)"),
         F("all that `segment` runs by default (wide look, second look, refiner), this render / a distant one",
           ("speed.speedup_vs_stock_segment.this render", "speed.speedup_vs_stock_segment.a distant render"),
           "{:.1f}× / {:.1f}×"))),
    Section(
        "Blade angle from masks", "pitch_accuracy",
        "python benchmarks/pitch_accuracy.py",
        "`contours` + `pitch` on exact masks of random turbines seen from the front (rotor 40–90 % "
        "of the frame height) and mildly oblique, and on front renders with distant turbines: the "
        "error of the method alone, without segmentation.",
        (F("front views: θ error mean / p95 / max",
           ("front.theta_err_deg.mean", "front.theta_err_deg.p95", "front.theta_err_deg.max",
            "front.blades"), "{:.3f}° / {:.3f}° / {:.3f}° ({} blades)", "mean ≤ 0.5°"),
         F("front views: class accuracy, φ flipped", ("front.class_acc", "front.flipped"),
           "{:.2%}, {} flipped", "≥ 99 %, none"),
         F("oblique views: θ error mean / p95", ("oblique.theta_err_deg.mean", "oblique.theta_err_deg.p95"),
           "{:.3f}° / {:.3f}°"),
         F("renders with distant turbines: θ error mean / p95, blades taken from another turbine",
           ("synthetic.theta_err_deg.mean", "synthetic.theta_err_deg.p95", "synthetic.wrong_rotor"),
           "{:.3f}° / {:.3f}°, {}"),
         F("partial rotors, 100 renders per view: blades flipped / measured (direction unknown) "
           "— cut by the frame, close-up, hub",
           tuple(f"partial.{v}.{k}" for v in ("cut", "closeup", "hub")
                 for k in ("flipped", "blades", "unknown")),
           "{} / {} ({}), {} / {} ({}), {} / {} ({})", "none flipped"),
         F("time per image (contours + pitch)", ("front.ms_per_image",), "{:.1f} ms"))),
    Section(
        "Planning time", "plan_benchmark",
        "python benchmarks/plan_benchmark.py",
        "`plan_mission` on random sites of 1, 10 and 100 turbines, wall and CPU seconds.",
        (F("1 turbine", ("timing[turbines=1].seconds", "timing[turbines=1].cpu_seconds"),
           "{:.2f} s wall, {:.2f} s CPU"),
         F("10 turbines", ("timing[turbines=10].seconds", "timing[turbines=10].cpu_seconds"),
           "{:.2f} s wall, {:.2f} s CPU"),
         F("100 turbines", ("timing[turbines=100].seconds", "timing[turbines=100].cpu_seconds"),
           "{:.2f} s wall, {:.2f} s CPU"),
         F("adaptive plan against the fixed \"Y\" pattern: mean coverage",
           ("adaptive_vs_fixed_y.adaptive.coverage_mean", "adaptive_vs_fixed_y.fixed-y.coverage_mean"),
           "{:.1%} against {:.1%}")),
        adopt='save("plan_benchmark", res)'),
    Section(
        "Planning time: where it goes", "plan_benchmark_coverage_share",
        "python benchmarks/plan_benchmark.py --coverage-share 10",
        "One process plans a random 10-turbine site (as the planning-time benchmark draws them) under "
        "cProfile; the "
        "CPU seconds inside the coverage measure (`turbine_coverage`) and inside the gap search "
        "(`gap_plan`, which calls the measure too, so the two overlap) against the whole plan.",
        (F("whole plan, CPU", ("cpu_seconds", "turbines"), "{:.2f} s ({} turbines)"),
         F("coverage measure, CPU", ("coverage_cpu_seconds", "coverage_calls"), "{:.2f} s ({} calls)"),
         F("gap search, CPU", ("gap_search_cpu_seconds",), "{:.2f} s"))),
    Section(
        "Photo to plan latency", "plan_latency",
        "python benchmarks/plan_latency.py --accuracy 40",
        "`wtinspect plan turbines.yaml T1=PHOTO` on one turbine (the sample site's T1) in a fresh "
        "process (imports, model load, segmentation, pitch, planning, writing), after one warm-up "
        "run: as shipped (the converted network run by OpenCV, no torch; one pass), with `--full` "
        "(four passes) and with torch's segmenter, in turn; then once more with its steps timed (CPU "
        "seconds, one run: on a shared CPU the wall times are longer, the CPU seconds much the "
        "same). One pass and four are compared on 40 held-out front renders at 640 × 480.",
        (F("wall time, median of the runs", ("median_s",), "{:.2f} s", "< 2 s"),
         F("wall time with `--full` / with torch's segmenter, median of the runs",
           ("full_median_s", "torch_median_s"), "{:.2f} s / {:.2f} s"),
         F("1-minute load average while measured, before / after",
           ("load_avg_1min.0", "load_avg_1min.1"), "{:.1f} / {:.1f}", "0 (idle)"),
         F("CPU reference (a fixed single-threaded workload), before / after",
           ("cpu_reference_s.0", "cpu_reference_s.1"), "{:.3f} s / {:.3f} s"),
         F("CPU s: imports of the CLI / the segmenter / numba and the planner",
           tuple(f"phases.shipped.steps[step={k}].cpu_s" for k in
                 ("cli", "segmenter_imports", "planner_imports")), "{:.2f} / {:.2f} / {:.2f}"),
         F("CPU s: reading the network / its pass / the edge refiner",
           tuple(f"phases.shipped.steps[step={k}].cpu_s" for k in ("model", "network", "refiner")),
           "{:.2f} / {:.2f} / {:.2f}"),
         F("CPU s: planning / writing the plan / the rest (YAML, contours, pitch, output)",
           tuple(f"phases.shipped.steps[step={k}].cpu_s" for k in ("plan", "write", "rest")),
           "{:.2f} / {:.2f} / {:.2f}"),
         F("CPU s of the whole command, shipped / `--full`",
           ("phases.shipped.total_cpu_s", "phases.full.total_cpu_s"), "{:.2f} / {:.2f}"),
         F("right blade count: one pass / four / torch's four",
           ("accuracy.fast.right_blade_count", "accuracy.full.right_blade_count",
            "accuracy.torch_full.right_blade_count"), "{:.1%} / {:.1%} / {:.1%}"),
         F("blade θ error mean: one pass / four / torch's four",
           ("accuracy.fast.theta_error_mean_deg", "accuracy.full.theta_error_mean_deg",
            "accuracy.torch_full.theta_error_mean_deg"), "{:.2f}° / {:.2f}° / {:.2f}°"),
         F("the sample photo's blade φ against torch's four passes, largest difference: one pass / four",
           ("accuracy.sample_photo.max_difference_to_torch_full_deg.fast",
            "accuracy.sample_photo.max_difference_to_torch_full_deg.full"), "{:.2f}° / {:.2f}°", "≤ 0.2°")),
        adopt='save("plan_latency", figures)'),
    Section(
        "Flight time per turbine", "flight_time",
        "python benchmarks/flight_time.py",
        "Planned minutes of flight per turbine (photos while moving at the camera's interval and "
        "blur limits, legs timed as an autopilot flies them) on 100 random single turbines (hub "
        "40-120 m, rotor 80-170 m) with the default camera (Zenmuse P1, 35 mm), where the "
        "minutes go, the predicted coverage beside them, and the manual pilot's time for the "
        "same photos. The mean is a sample's: its standard error is beside it.",
        (F("mean ± standard error (its upper 95 % bound) / worst minutes per turbine",
           ("random.minutes_mean", "random.minutes_se", "random.minutes_mean_upper95",
            "random.minutes_max"),
           "{:.2f} ± {:.2f} ({:.2f}) / {:.1f} min", "mean ≤ 10 min"),
         F("done (upper bound ≤ 10 min, sides ≥ 98 %, tower and nacelle ≥ 95 %, 0 violations)",
           ("random.done",), "{}", "True"),
         F("mean minutes: capture / turns / transit / battery swaps / climbs",
           tuple(f"random.budget_min_mean.{k}" for k in
                 ("capture", "turns", "transit", "battery_swaps", "climbs")),
           "{:.1f} / {:.1f} / {:.1f} / {:.1f} / {:.1f}"),
         F("pass speed (limits: photo interval / motion blur / fleet cap)",
           ("random.capture.speed_m_s", "random.capture.limits.photo_interval_m_s",
            "random.capture.limits.motion_blur_m_s", "random.capture.limits.fleet_m_s"),
           "{:.2f} m/s ({:.2f} / {:.2f} / {:.2f})"),
         F("lowest blade side / tower / nacelle coverage",
           ("random.min_blade_side_min", "random.tower_min", "random.nacelle_min"),
           "{:.1%} / {:.1%} / {:.1%}", "≥ 98 % / 95 % / 95 %"),
         F("clearance violations", ("random.violations",), "{}", "0"),
         F("time against the manual pilot (the paper: −78 %)",
           ("random.reduction_vs_manual_mean",), "{:+.0%}"),
         F("paper S2: minutes per turbine", ("scenarios.paper-s2.minutes_per_turbine",),
           "{:.1f} min"),
         F("the same turbines with a 16 mm lens (1.5 mm/px at 5.6 m): mean minutes, lowest "
           "blade side / tower", ("random_compare.minutes_mean", "random_compare.min_blade_side_min",
                                  "random_compare.tower_min"), "{:.1f} min, {:.1%} / {:.1%}"))),
    Section(
        "Coverage", "plan_coverage",
        "python benchmarks/plan_coverage.py",
        "The planner's predicted coverage of every blade side over random single turbines, with "
        "the settings `wtinspect plan` uses and a 16 mm lens on a 23.2 mm sensor (the sample "
        "site's camera; the default camera's coverage is under Flight time per turbine).",
        (F("blade coverage, mean over cases", ("summary.blade_average_mean",), "{:.1%}"),
         F("worst blade side, mean / min over cases", ("summary.min_side_mean", "summary.min_side_min"),
           "{:.1%} / {:.1%}"),
         F("clearance violations", ("summary.violations",), "{}", "0")),
        adopt='save("plan_coverage", res)'),
    Section(
        "Plan safety over random sites", "plan_property",
        "python benchmarks/plan_property.py",
        "Random sites (turbines, fleets, gimbal limits and safe distances drawn as the benchmark's "
        "docstring says), every plan's waypoints and legs checked against every turbine.",
        (F("cases planned / refused", ("summary.planned", "summary.plan_errors"), "{} / {}"),
         F("clearance or gimbal violations", ("summary.violations",), "{}", "0"),
         F("smallest margin over the safe distance", ("summary.min_margin_over_safe_distance_m",),
           "{:.2f} m", "≥ 0"),
         F("crashes (exit 1) / battery-reserve overruns",
           ("summary.crashes_exit_1", "summary.battery_overruns"), "{} / {}", "0 / 0"),
         F("plans with a side below min_side_coverage at half the sampling (lowest side)",
           ("summary.plans_with_a_side_short_at_half_spacing", "summary.min_side_coverage_at_half_spacing"),
           "{} ({:.1%})", "0")),
        adopt='save("plan_property", {"summary": summary, "cases": res})'),
    Section(
        "Flight: the paper's scenarios", "fly_paper_table",
        "python benchmarks/fly_paper_table.py",
        "The four shipped scenarios (paper-s1 … paper-s4) planned and flown with the PID "
        "controller (eq. 10) and a manual pilot, beside the paper's Table 1.",
        (F("strong wind (paper-s2), automated: mean deviation",
           ("runs.0.rows[scenario=paper-s2].ours.automated.deviation_m",), "{:.2f} m", "≤ 0.5 m"),
         F("strong wind (paper-s2), automated: clearance violations",
           ("runs.0.rows[scenario=paper-s2].automated_safety.violations",), "{}", "0"),
         F("coverage, automated, paper-s1 / s2 / s3 / s4",
           ("runs.0.rows[scenario=paper-s1].ours.automated.coverage_pct",
            "runs.0.rows[scenario=paper-s2].ours.automated.coverage_pct",
            "runs.0.rows[scenario=paper-s3].ours.automated.coverage_pct",
            "runs.0.rows[scenario=paper-s4].ours.automated.coverage_pct"),
           "{:.1f} / {:.1f} / {:.1f} / {:.1f} %", "≥ 97 %"),
         F("done criteria met", ("done",), "{}", "True")),
        adopt='save("fly_paper_table", {"runs": runs, "done": ok})'),
    Section(
        "Flight: deviation and margins by positioning", "fly_margins",
        "python benchmarks/fly_margins.py --seeds 20 --winds 8 10 12",
        "The paper's S2 scenario (IEC 61400-1 category A turbulence with complex terrain's "
        "structure) at 8 m/s hub wind, the wind the margins are documented for, flown over 20 "
        "seeds with each positioning mode, the plan made with that mode's documented tracking "
        "margin; deviation measured on the truth. At 10 m/s the same margins give no violation; "
        "at 12 m/s the worst flights leave the path by 21-23 m (docs/fly.md).",
        tuple(F(f"{label}: mean deviation / worst 99.9th pct / least clearance (margin {m} m)",
                (f"modes.{mode}.summary.mean_deviation_m", f"modes.{mode}.summary.p99_9_worst_seed_m",
                 f"modes.{mode}.summary.min_clearance_m"),
                "{:.2f} / {:.2f} / {:.2f} m", "clearance ≥ 3 m")
              for mode, label, m in (("rtk_fixed", "RTK fixed", 2), ("rtk_float", "RTK float", 3),
                                     ("gnss", "plain GNSS", 4.5)))
        + (F("clearance violations, all modes",
             ("modes.rtk_fixed.summary.clearance_violations", "modes.rtk_float.summary.clearance_violations",
              "modes.gnss.summary.clearance_violations"), "{} / {} / {}", "0"),),
        adopt='save("fly_margins", {"scenario": ..., "seeds": ..., "modes": ..., "done": ...})'),
    Section(
        "Flight simulation speed", "fly_speed",
        "python benchmarks/fly_speed.py",
        "A 20-minute inspection flown in strong turbulent wind (100 Hz physics, 50 Hz control), "
        "then measured.",
        (F("fly + measure, CPU seconds", ("total_cpu_s",), "{:.2f} s", "< 2 s"),
         F("deviation from the planned path, mean / max", ("deviation_mean_m", "deviation_max_m"),
           "{:.3f} / {:.2f} m")),
        adopt='save("fly_speed", {"total_cpu_s": total, "deviation_mean_m": '
              'float(res.deviation.mean()), "deviation_max_m": float(res.deviation.max())})'),
)


def lookup(doc: Any, path: str, where: str) -> Any:
    """The value at a dotted ``path`` (keys may hold spaces; a number indexes a list;
    ``name[k=v]`` takes the list item whose ``k`` reads ``v``)."""
    cur = doc
    for part in path.split("."):
        sel = None
        if part.endswith("]") and "[" in part:
            part, sel = part[:-1].split("[", 1)
        if isinstance(cur, list) and part.isdigit() and int(part) < len(cur):
            cur = cur[int(part)]
        elif isinstance(cur, dict) and part in cur:
            cur = cur[part]
        else:
            raise ReportError(f"{where}: no `{path}` (benchmarks/report.py shows it)")
        if sel is not None:
            k, v = sel.split("=", 1)
            hits = [x for x in (cur or []) if isinstance(x, dict) and str(x.get(k)) == v]
            if not hits:
                raise ReportError(f"{where}: no item with {k} = {v} in `{path}`")
            cur = hits[0]
    if cur is None:
        raise ReportError(f"{where}: `{path}` is null (that part of the benchmark did not run)")
    return cur


def load(name: str, results: Path) -> dict | None:
    path = results / f"{name}.json"
    if not path.exists():
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ReportError(f"{path}: cannot read ({e})") from None
    for key in ("command", "date", "machine"):
        if key not in doc.get("measured", {}):
            raise ReportError(f"{path}: no `measured.{key}` (write it with benchmarks/_results.py)")
    return doc


def _rows(s: Section, doc: dict, where: str) -> list[tuple[str, str, str]]:
    rows = []
    for f in s.figures:
        values = [lookup(doc, k, where) for k in f.keys]
        try:
            shown = f.fmt.format(*values)
        except (ValueError, TypeError, IndexError) as e:
            raise ReportError(f"{where}: {f.keys} cannot be shown as {f.fmt!r} ({e})") from None
        shown = re.sub(r"(\d)%", r"\1 %", shown)  # 96.0 %, as the rest of the docs write it
        rows.append((f.label, shown, f.goal or "—"))
    return rows


def _provenance(doc: dict, where: str) -> str:
    m = doc["measured"]
    machine = m["machine"]["summary"] if isinstance(m["machine"], dict) else str(m["machine"])
    return (f"Measured {m['date']} by `{m['command']}` on a {machine}"
            f" (`{where}`, tool {doc.get('tool_version', '?')}).")


def render_block(titles: tuple[str, ...], results: Path = RESULTS) -> str:
    """The figures of some sections as one table, for a page that shows them beside its text."""
    rel = results.relative_to(ROOT) if results.is_relative_to(ROOT) else results
    by_title = {s.title: s for s in SECTIONS}
    lines, table, seen = [], ["| | figure | value | goal |", "| --- | --- | --- | --- |"], set()
    for title in titles:
        s = by_title[title]
        doc = load(s.name, results)
        where = f"{rel}/{s.name}.json"
        short = title.split(": ", 1)[-1]
        if doc is None:
            lines += textwrap.wrap(f"{short}: not measured yet, run `{s.command}`.", WIDTH)
            continue
        if s.name not in seen:
            seen.add(s.name)
            lines += textwrap.wrap(_provenance(doc, where), WIDTH, break_on_hyphens=False)
        table += [f"| {short} | {a} | {b} | {c} |" for a, b, c in _rows(s, doc, where)]
    return "\n".join([BEGIN, *lines, "", *table, END])


def with_blocks(text: str, titles: tuple[str, ...], page: str, results: Path = RESULTS) -> str:
    """``text`` with its rendered block replaced by a fresh one."""
    if BEGIN not in text or END not in text:
        raise ReportError(f"{page}: no rendered-figures block (the lines {BEGIN!r} ... {END!r})")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    return head + render_block(titles, results) + tail


def render(results: Path = RESULTS) -> str:
    rel = results.relative_to(ROOT) if results.is_relative_to(ROOT) else results
    out = ["# Benchmarks", "",
           "Every headline figure of `wtinspect`, with the command, date and machine that measured it.",
           f"This page is generated from `{rel}/*.json` by `python benchmarks/report.py`; do not edit",
           "it by hand (`tests/test_benchmarks_report.py` fails when it differs from the results files).",
           "Each benchmark writes its results file through `benchmarks/_results.py`; run the command",
           "shown, then `python benchmarks/report.py`, and commit both.", ""]
    for s in SECTIONS:
        out += [f"## {s.title}", "", *textwrap.wrap(s.about, WIDTH), ""]
        doc = load(s.name, results)
        if doc is None:
            out += [*textwrap.wrap(f"Not measured yet: run `{s.command}` (it writes "
                                   f"`{rel}/{s.name}.json`).", WIDTH), ""]
            out += ["| figure | value | goal |", "| --- | --- | --- |"]
            out += [f"| {f.label} | not measured yet | {f.goal or '—'} |" for f in s.figures]
            out.append("")
            continue
        where = f"{rel}/{s.name}.json"
        out += [*textwrap.wrap(_provenance(doc, where), WIDTH, break_on_hyphens=False), "",
                "| figure | value | goal |", "| --- | --- | --- |"]
        out += [f"| {a} | {b} | {c} |" for a, b, c in _rows(s, doc, where)]
        out.append("")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true",
                    help="do not write: exit 1 if the page differs from what the results files give")
    ap.add_argument("--results", type=Path, default=RESULTS, help="folder of the results files")
    ap.add_argument("--out", type=Path, default=DOC, help="the page to write or check")
    ap.add_argument("--no-blocks", dest="blocks", action="store_false",
                    help="leave the figure blocks of other pages (" + ", ".join(BLOCKS) + ") alone")
    a = ap.parse_args(argv)
    try:
        pages = {a.out: render(a.results)}
        if a.blocks:
            for page, titles in BLOCKS.items():
                have = (ROOT / page).read_text(encoding="utf-8")
                pages[ROOT / page] = with_blocks(have, titles, page, a.results)
    except (ReportError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 3
    if a.check:
        stale = []
        for path, text in pages.items():
            have = path.read_text(encoding="utf-8") if path.exists() else ""
            if have != text:
                diff = difflib.unified_diff(have.splitlines(), text.splitlines(), str(path),
                                            "rendered", lineterm="", n=1)
                print("\n".join(list(diff)[:40]), file=sys.stderr)
                stale.append(str(path))
        if stale:
            print(f"{', '.join(stale)}: differ from {a.results}: run `python benchmarks/report.py`",
                  file=sys.stderr)
            return 1
        return 0
    for path, text in pages.items():
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
            print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
