"""`wtinspect fly`: plan + scenario -> simulated flight report (and baselines). docs/fly.md"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from wtcli.console import err_console, stage_bars
from wtcli.errors import SimulationError

FLIGHT_SCHEMA = "wtinspect.flight"
FLIGHT_VERSION = 1
PAPER_TABLE_SCHEMA = "wtinspect.paper_table"
MAX_WARNINGS = 20  # printed; the report holds every one
LABELS = {"time_min": "time (min)", "length_m": "length (m)", "coverage_pct": "coverage (%)",
          "deviation_m": "deviation (m)"}


def _console() -> Console:
    """stdout for people: at least 150 columns wide, so the tables stay tables in files/pipes."""
    c = Console(highlight=False)
    return c if c.width >= 150 else Console(highlight=False, width=150)


def _flight_table(report) -> Table:
    tab = Table(title=f"flight: {report.scenario.name} (seed {report.scenario.seed})")
    for col in ("flight", "time min", "length m", "coverage %", "deviation m mean/rms/max",
                "clearance m", "violations", "photos", "GSD mm", "battery %"):
        tab.add_column(col, justify="left" if col == "flight" else "right")
    for kind, f in report.flights.items():
        d = f.to_dict()
        dev = d["deviation_m"]
        cov = f"{100 * f.coverage_average:.1f}"
        if f.planned_coverage_average is not None:
            cov += f" (plan {100 * f.planned_coverage_average:.1f})"
        g = d["photos"]["gsd_nearest_surface_mm"]["median"]
        tab.add_row(kind, f"{f.time_s / 60:.1f}", f"{f.path_length_m:.0f}", cov,
                    f"{dev['mean']:.2f} / {dev['rms']:.2f} / {dev['max']:.2f}",
                    f"{f.min_clearance_m:.2f}", str(len(f.violations)), str(f.photos),
                    "-" if g is None else f"{g:.2f}", f"{d['battery']['max_used_pct']:.0f}")
    return tab


def _paper_table(rows, means) -> Table:
    tab = Table(title="Table 1 of the paper beside our simulation (manual -> automated)")
    for col in ("scenario", "metric", "paper manual", "paper auto", "paper change",
                "ours manual", "ours auto", "ours change"):
        tab.add_column(col, justify="left" if col in ("scenario", "metric") else "right")
    for r in rows:
        for i, m in enumerate(LABELS):
            unit = " pts" if m == "coverage_pct" else " %"
            tab.add_row(r.name if i == 0 else "", LABELS[m],
                        f"{r.paper['manual'][m]:g}", f"{r.paper['automated'][m]:g}",
                        f"{r.change('paper', m):+.0f}{unit}",
                        _fmt(m, r.ours['manual'][m]), _fmt(m, r.ours['automated'][m]),
                        f"{r.change('ours', m):+.0f}{unit}", end_section=i == len(LABELS) - 1)
    from wtcli.fly.run import PAPER_STATED
    for i, m in enumerate(LABELS):
        unit = " pts" if m == "coverage_pct" else " %"
        tab.add_row("mean of rows" if i == 0 else "", LABELS[m], "", "",
                    f"{means['paper'][m]:+.0f}{unit} (stated {PAPER_STATED[m]:+.0f})", "", "",
                    f"{means['ours'][m]:+.0f}{unit}")
    return tab


def _fmt(metric: str, v: float) -> str:
    return {"time_min": f"{v:.1f}", "length_m": f"{v:.0f}", "coverage_pct": f"{v:.1f}",
            "deviation_m": f"{v:.2f}"}[metric]


def _fly_stage_text() -> dict[str, str]:
    """What the progress bars of ``run_scenario`` are called: the planner's stages (for the
    plan and the fixed-pattern baseline's plan), then one bar per flight kind."""
    from wtcli.commands.plan import PLAN_STAGE_TEXT

    text = {**{k: f"plan: {v}" for k, v in PLAN_STAGE_TEXT.items()},
            **{f"fixed-y {k}": f"fixed-pattern plan: {v}" for k, v in PLAN_STAGE_TEXT.items()}}
    return {**text, "automated": "automated flight (PID)", "no_compensation": "no wind compensation",
            "fixed_pattern": "fixed-pattern flight", "manual": "manual pilot"}


def register(app: typer.Typer) -> None:
    @app.command("fly")
    def fly(
        plan: Optional[Path] = typer.Argument(
            None, metavar="[PLAN_JSON]",
            help="A plan from `wtinspect plan`. Without it, the scenario's mission is planned."),
        scenario: Optional[str] = typer.Option(
            None, "--scenario", "-s", metavar="YAML",
            help="Scenario file, or the name of a shipped one (tiny, paper-s1 ... paper-s4)."),
        out: Optional[Path] = typer.Option(None, "--out", "-o", help="Write the report JSON here."),
        pictures: Optional[Path] = typer.Option(
            None, "--pictures", metavar="DIR",
            help="Write path.png, deviation.png and coverage.png here (with --paper-table: "
                 "sensitivity.png)."),
        baselines: bool = typer.Option(
            False, "--baselines", help="Also fly the baselines the scenario enables "
                                       "(no compensation, fixed pattern, manual pilot)."),
        seed: Optional[int] = typer.Option(None, "--seed", min=0, help="Override the scenario's seed."),
        json_out: bool = typer.Option(False, "--json", help="Print the JSON on stdout, nothing else."),
        fail_on_violation: bool = typer.Option(
            False, "--fail-on-violation",
            help="Exit 8 if the automated flight breaks the safe distance or the height limits."),
        paper: bool = typer.Option(
            False, "--paper-table",
            help="Fly the paper's four scenarios and print our figures beside its Table 1."),
    ) -> None:
        """Fly a plan in a simulation with wind; report time, length, coverage, deviation, safety."""
        from wtcli.fly.flight import describe
        from wtcli.fly.scenario import load_scenario, resolve_scenario
        from wtcli.jsonio import document, dumps, write_json
        from wtcli.outputs import check_not_inputs, check_outputs

        given = [("the input plan", plan)]
        if scenario is not None and not paper:  # --paper-table flies its own scenarios
            given.append(("the scenario file", resolve_scenario(scenario)))
        check_not_inputs([("--out", out)], given)
        check_outputs(files=[out], folders=[pictures])  # before flying, not after
        if paper:
            from wtcli.fly.run import mean_changes, paper_table

            with stage_bars({"scenarios": "the paper's scenarios, planned and flown"}, "fly") as progress:
                rows = paper_table(seed=seed, progress=progress)
            means = mean_changes(rows)
            body = {"rows": [r.to_dict() for r in rows], "mean_change": means}
            if pictures is not None:
                from wtcli.fly.pictures import write_sensitivity
                from wtcli.fly.run import sensitivity

                s2 = next((r for r in rows if r.name == "paper-s2"), rows[0])
                with stage_bars({"sensitivity": f"sensitivity of the deviation ({s2.name})"}, "fly") as pr:
                    body["sensitivity"] = sensitivity(s2.plan, s2.scenario, progress=pr)
                path = write_sensitivity(body["sensitivity"], pictures,
                                         f"{s2.name}: automated flight's deviation, one thing "
                                         "changed at a time")
                err_console.print(f"pictures -> {path}", soft_wrap=True)
            doc = document(PAPER_TABLE_SCHEMA, 1, body)
            if out is not None:
                write_json(out, doc)
            if json_out:
                typer.echo(dumps(doc))
            else:
                _console().print(_paper_table(rows, means))
            return
        if scenario is None:
            raise typer.BadParameter("give --scenario YAML (or --paper-table)",
                                     param_hint="--scenario")
        from wtcli.fly.run import run_scenario

        scn = load_scenario(resolve_scenario(scenario))
        if seed is not None:
            scn = scn.with_seed(seed)
        with stage_bars(_fly_stage_text(), "fly") as progress:
            report = run_scenario(scn, plan, baselines=baselines, progress=progress)
        doc = document(FLIGHT_SCHEMA, FLIGHT_VERSION, report.to_dict())
        if out is not None:
            write_json(out, doc)
            err_console.print(f"flight report -> {out}", soft_wrap=True)
        if pictures is not None:
            from wtcli.fly.pictures import write_pictures

            paths = write_pictures(report, pictures)
            err_console.print(f"pictures -> {', '.join(str(p) for p in paths)}", soft_wrap=True)
        if json_out:
            typer.echo(dumps(doc))
        else:
            _console().print(_flight_table(report))
        for note in report.notes:
            err_console.print(f"note: {note}", soft_wrap=True)
        warnings = report.warnings()
        for w in warnings[:MAX_WARNINGS]:
            err_console.print(f"[yellow]warning:[/yellow] {escape(w)}", markup=True, soft_wrap=True)
        if len(warnings) > MAX_WARNINGS:
            err_console.print(f"[yellow]warning:[/yellow] and {len(warnings) - MAX_WARNINGS} more "
                              "(all in the report: preflight, flights.*.clearance.violations)",
                              markup=True, soft_wrap=True)
        viol = report.preflight + report.automated.violations
        if viol and fail_on_violation:
            kinds = sorted({v.kind for v in viol})
            raise SimulationError(f"the plan and its automated flight broke the limits {len(viol)} "
                                  f"time(s) ({', '.join(kinds)}); first: {describe(viol[0])}")
