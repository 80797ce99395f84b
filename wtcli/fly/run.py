"""Whole runs: plan from a scenario's mission (if no plan is given), fly, and the paper's table.

``run_scenario`` is what ``wtinspect fly`` calls; ``paper_table`` flies the four shipped
scenarios of the paper's Table 1 (automated and manual) and sets our figures beside the paper's.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from wtcli.console import StageProgress, stage_ticker
from wtcli.errors import ConfigError
from wtcli.fly.flight import FlightReport, fly_plan
from wtcli.fly.scenario import Scenario, load_scenario, shipped_scenarios
from wtcli.plan_file import Plan, read_plan

PAPER_SCENARIOS = ("paper-s1", "paper-s2", "paper-s3", "paper-s4")
# The relative changes the paper states in its abstract and section IV (manual -> automated).
PAPER_STATED = {"time_min": -78.0, "length_m": -17.0, "coverage_pct": 6.0, "deviation_m": -68.0}
METRICS = ("time_min", "length_m", "coverage_pct", "deviation_m")


def plan_from_mission(scn: Scenario, pattern: str = "adaptive",
                      progress: StageProgress | None = None) -> Plan:
    """Plan the scenario's mission with the planner (``wtcli.plan``)."""
    if scn.mission is None:
        raise ConfigError(f"{scn.source or scn.name}: the scenario names no 'mission' file; give "
                          "a plan JSON or add 'mission: turbines.yaml' to the scenario")
    from wtcli.plan.config import load_mission
    from wtcli.plan.mission import plan_mission

    mission = load_mission(scn.mission)
    return plan_mission(mission, azimuths=scn.azimuths, pattern=pattern, progress=progress)


def run_scenario(scn: Scenario, plan_path: str | Path | None = None, baselines: bool = False,
                 progress: StageProgress | None = None) -> FlightReport:
    """Fly a plan file (or the plan of the scenario's mission) and, optionally, the baselines.
    ``progress``: the planner's stages (``wtcli.plan.mission.STAGES``) where it plans, then
    ``fly_plan``'s."""
    if plan_path is not None:
        plan = read_plan(plan_path)
        source = str(plan_path)
    else:
        plan = plan_from_mission(scn, progress=progress)
        source = f"planned from {scn.mission}"
    fixed = None
    notes = []
    if baselines and scn.baselines.fixed_pattern and scn.mission is not None:
        fixed = plan_from_mission(scn, pattern="fixed-y", progress=progress and (
            lambda stage, done, total: progress(f"fixed-y {stage}", done, total)))
        if not same_site(plan, fixed):
            fixed = None
            notes.append(f"fixed_pattern baseline skipped: the scenario's mission ({scn.mission}) "
                         "is not the site of the plan")
    report = fly_plan(plan, scn, baselines=baselines, fixed_plan=fixed, plan_source=source,
                      progress=progress)
    if notes:
        report = replace(report, notes=[n for n in report.notes
                                        if not n.startswith("fixed_pattern")] + notes)
    return report


def same_site(a: Plan, b: Plan, tol_m: float = 1.0) -> bool:
    """Whether two plans are of the same turbines (ids and bases)."""
    ta = {t.id: np.array(t.base) for t in a.turbines}
    tb = {t.id: np.array(t.base) for t in b.turbines}
    return ta.keys() == tb.keys() and all(np.linalg.norm(ta[k] - tb[k]) <= tol_m for k in ta)


@dataclass(frozen=True)
class PaperRow:
    name: str
    label: str  # the paper's scenario text
    paper: dict  # {"manual": {metric: v}, "automated": {...}}
    ours: dict  # same shape
    report: FlightReport
    plan: Plan | None = None  # the plan flown (automated)
    scenario: Scenario | None = None

    def change(self, who: str, metric: str) -> float:
        m, a = self[who]["manual"][metric], self[who]["automated"][metric]
        if metric == "coverage_pct":
            return a - m  # points
        return 100.0 * (a - m) / m if m else float("nan")

    def __getitem__(self, who: str) -> dict:
        return {"paper": self.paper, "ours": self.ours}[who]

    def to_dict(self) -> dict[str, Any]:
        return {"scenario": self.name, "label": self.label, "paper": self.paper, "ours": self.ours,
                "change": {who: {m: self.change(who, m) for m in METRICS} for who in ("paper", "ours")},
                "automated_safety": {
                    "min_clearance_m": self.report.automated.min_clearance_m,
                    "violations": len(self.report.automated.violations),
                    "deviation_rms_m": float(np.sqrt((self.report.automated.deviation ** 2).mean())),
                    "deviation_max_m": float(self.report.automated.deviation.max())}}


def paper_table(names: tuple[str, ...] = PAPER_SCENARIOS, seed: int | None = None,
                progress: StageProgress | None = None) -> list[PaperRow]:
    """Fly the paper's four scenarios (automated and manual only) and collect Table 1.
    ``progress``: one stage, "scenarios", counting them."""
    shipped = shipped_scenarios()
    rows = []
    tick = stage_ticker(progress, "scenarios", len(names))
    for name in names:
        scn = load_scenario(shipped[name])
        if seed is not None:
            scn = scn.with_seed(seed)
        plan = plan_from_mission(scn)
        scn_m = replace(scn, baselines=replace(scn.baselines, no_compensation=False,
                                               fixed_pattern=False, manual=True))
        report = fly_plan(plan, scn_m, baselines=True, plan_source=f"planned from {scn.mission}")
        ours = {"manual": report.flights["manual"].summary(),
                "automated": report.automated.summary()}
        ours = {k: {m: float(v[m]) for m in METRICS} for k, v in ours.items()}
        paper = scn.paper or {"scenario": scn.description, "manual": {}, "automated": {}}
        rows.append(PaperRow(name=name, label=paper.get("scenario", scn.description),
                             paper={k: paper[k] for k in ("manual", "automated")}, ours=ours,
                             report=report, plan=plan, scenario=scn))
        tick()
    return rows


def mean_changes(rows: list[PaperRow]) -> dict[str, dict[str, float]]:
    return {who: {m: float(np.mean([r.change(who, m) for r in rows])) for m in METRICS}
            for who in ("paper", "ours")}


# ---- sensitivity of the deviation ------------------------------------------------------------

SENSITIVITY_WIND_MS = (0.0, 4.0, 8.0, 12.0)
SENSITIVITY_CLASSES = ("C", "B", "A", "A+")
SENSITIVITY_MODES = ("rtk_fixed", "rtk_float", "gnss")


def sensitivity(plan: Plan, scn: Scenario, progress: StageProgress | None = None) -> dict[str, list]:
    """The automated flight's deviation from ``plan`` as one thing changes at a time, the rest
    as ``scn`` says: the hub-height wind speed (the scenario's turbulence category, RTK fixed),
    the IEC turbulence category (Kaimal, the scenario's wind, RTK fixed) and the positioning
    mode (the scenario's wind). Per point: {"x", "mean_m", "p99_9_m", "max_m"}."""
    base = replace(scn, positioning=replace(scn.positioning, mode="rtk_fixed"))
    cases = [("wind_ms", v, replace(base, wind=replace(base.wind, speed_ms=v)))
             for v in SENSITIVITY_WIND_MS]
    cases += [("turbulence_class", c, replace(base, wind=replace(base.wind, turbulence_model="kaimal",
                                                                 turbulence_sigma_ms=None,
                                                                 turbulence_class=c)))
              for c in SENSITIVITY_CLASSES]
    cases += [("positioning", m, replace(scn, positioning=replace(scn.positioning, mode=m)))
              for m in SENSITIVITY_MODES]
    tick = stage_ticker(progress, "sensitivity", len(cases))
    out: dict[str, list] = {"wind_ms": [], "turbulence_class": [], "positioning": []}
    for what, x, s in cases:
        d = fly_plan(plan, s).automated.to_dict()["deviation_m"]
        out[what].append({"x": x, "mean_m": d["mean"], "p99_9_m": d["p99_9"], "max_m": d["max"]})
        tick()
    return out
