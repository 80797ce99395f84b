"""`wtinspect plan`: turbines.yaml + photo / pitch JSON -> flight plan + exports. docs/plan.md"""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from wtcli.console import busy, err_console, stage_bars
from wtcli.errors import ConfigError, UsageError
from wtcli.jsonio import dumps
from wtcli.plan_file import PLAN_SCHEMA, PLAN_VERSION, write_plan


def _pose(text: str | None):
    if text is None:
        return None
    from wtcli.plan.config import CameraPose

    try:
        v = [float(x) for x in text.replace(";", ",").split(",")]
    except ValueError:
        v = []
    if len(v) not in (6, 7) or not all(abs(x) <= 1e6 for x in v):  # also refuses nan, inf
        raise ConfigError(f"--camera-pose: expected X,Y,Z,TX,TY,TZ[,ROLL] (finite ENU m of the camera and "
                          f"of the point it looked at), got {text!r}")
    return CameraPose(tuple(v[:3]), tuple(v[3:6]), v[6] if len(v) == 7 else 0.0)


def _replaced_text(done, stem: str) -> str:
    """The end of the exports line: what became of an earlier export of the same stem, so a
    pilot knows the folder holds this plan alone."""
    earlier = len(done.replaced) + len(done.removed)
    if not earlier:
        return ""
    text = f" (replaced the earlier export of {stem}: {earlier} file(s)"
    if done.removed:
        names = [p.name for p in done.removed]
        more = f" and {len(names) - 3} more" if len(names) > 3 else ""
        text += f"; removed {len(names)} this plan has not: {', '.join(names[:3])}{more}"
    return text + ")"


# What each of plan_mission's stages (wtcli.plan.mission.STAGES) does, for the progress bar.
PICTURE_SUFFIXES = (".png", ".jpg", ".jpeg")
PLAN_STAGE_TEXT = {"turbines": "trajectories", "legs": "legs between turbines", "routes": "UAV routes",
               "coverage": "coverage check"}


def register(app: typer.Typer) -> None:
    @app.command("plan")
    def plan(
        turbines_yaml: Path = typer.Argument(..., metavar="TURBINES_YAML",
                                             help="Site, turbines, fleet, camera and mission settings "
                                                  "(docs/turbines-yaml.md)."),
        inputs: Optional[List[str]] = typer.Argument(
            None, metavar="[PHOTO_OR_PITCH_JSON...]",
            help="Blade angles: a photo (segment -> contours -> pitch) or a pitch JSON, per turbine; "
                 "prefix with ID= to name the turbine (T2=photo.png). Default: each turbine's "
                 "'photo' key, else its YAML azimuths."),
        out: Optional[Path] = typer.Option(None, "--out", "-o", help="Write the plan JSON here."),
        export_dir: Optional[Path] = typer.Option(
            None, "--export-dir", help="Write QGroundControl .plan and QGC WPL 110 .waypoints per "
                                       "UAV sortie, and a .geojson (needs site.origin)."),
        dji_kmz: Optional[str] = typer.Option(
            None, "--dji-kmz", metavar="AIRCRAFT",
            help="With --export-dir, also write a DJI WPML .kmz per sortie for DJI Pilot 2: "
                 "m300-p1, m300-h20, m350-p1, m350-h20, m30 or m30t."),
        picture: Optional[Path] = typer.Option(None, "--picture",
                                               help="Write front/side/top views of the path "
                                                    "(.png, or .jpg)."),
        pattern: str = typer.Option("adaptive", "--pattern",
                                    help="adaptive (real blade angles) or fixed-y (baseline that "
                                         "assumes a Y stop; reported, never refused)."),
        camera_pose: Optional[str] = typer.Option(
            None, "--camera-pose", metavar="X,Y,Z,TX,TY,TZ[,ROLL]",
            help="Where the photo was taken from and the point it looked at (ENU m); default: "
                 "the photo's own GPS and gimbal tags where it has them (docs/photo-pose.md), "
                 "else at S_p looking at the rotor centre."),
        fast: bool = typer.Option(
            True, "--fast/--full",
            help="Photos: one pass of the segmenter (--fast, the default), or --full: also the "
                 "mirror pass and a second look at a distant turbine (segment's defaults but the "
                 "wide look), four "
                 "passes, about a second later on 2 cores; on 40 held-out renders both read the "
                 "blade angles as well (docs/plan.md)."),
        json_out: bool = typer.Option(False, "--json", help="Print the plan JSON on stdout."),
        jobs: Optional[int] = typer.Option(
            None, "--jobs", "-j", min=1,
            help="Worker processes (default: one per CPU on sites of 8 turbines or more, none on "
                 "smaller ones); the plan is the same whatever the number."),
    ) -> None:
        """Plan a safe inspection flight around every blade side, the nacelle and the tower."""
        import cv2

        from wtcli.jsonio import atomic_write_bytes, document
        from wtcli.plan.angles import blade_azimuths
        from wtcli.plan.config import load_mission
        from wtcli.plan.exports import export_all
        from wtcli.plan.mission import BUDGET_KEYS, PATTERNS, plan_mission
        from wtcli.plan.path_views import draw_plan
        from wtcli.warmup import imports_frozen

        with imports_frozen():
            if pattern not in PATTERNS:
                raise ConfigError(f"--pattern: expected one of {', '.join(PATTERNS)}, got {pattern!r}")
            if dji_kmz is not None:  # checked before planning, not after
                from wtcli.plan.dji_kmz import aircraft

                aircraft(dji_kmz)
                if export_dir is None:
                    raise ConfigError("--dji-kmz needs --export-dir (where to write the .kmz files)")
            from wtcli.outputs import check_not_inputs, check_outputs
            given = [("the input turbines file", turbines_yaml)] + [
                ("an input photo or pitch file", Path(p)) for a in inputs or []
                for p in {a, a.partition("=")[2] or a}]  # ID=FILE: the file; a name may hold "="
            written = [("--out", out), ("--picture", picture)]
            check_not_inputs(written, given)
            check_outputs(files=[out, picture], folders=[export_dir])  # before planning, not after
            if picture is not None and picture.suffix.lower() not in PICTURE_SUFFIXES:
                raise UsageError(f"--picture {picture}: expected a .png or .jpg file name")
            mission = load_mission(turbines_yaml)
            check_not_inputs(written, [(f"turbine {t.id}'s photo in {turbines_yaml}",
                                        mission.extra(t.id).photo) for t in mission.turbines])
            if export_dir is not None and not mission.site_origin:  # the exports are lat/lon
                raise ConfigError(f"{turbines_yaml}: --export-dir writes lat/lon and needs "
                                  "site.origin (lat, lon, alt) in it")
            stem = out.stem if out else "mission"  # the exports' names
            if export_dir is not None:  # a user's own STEM.geojson: refused before planning
                from wtcli.plan.exports import check_export_names, check_map_is_ours
                check_export_names(export_dir, stem, mission.fleet.uavs)
                check_map_is_ours(export_dir, stem)
            with stage_bars({"photos": "overview photos"}, "plan") as progress:
                azimuths, sources = blade_azimuths(mission, list(inputs or []), _pose(camera_pose),
                                                   fast=fast, progress=progress)
            for tid, src in sources.items():
                err_console.print(f"{tid}: blade azimuths "
                                  f"{', '.join(f'{a:.1f}' for a in azimuths[tid])} deg from {src}",
                                  soft_wrap=True)
            with stage_bars(PLAN_STAGE_TEXT, "plan") as progress:
                result = plan_mission(mission, azimuths=azimuths or None, pattern=pattern, workers=jobs,
                                      progress=progress)
            write_out = (lambda: write_plan(out, result)) if out is not None else None
            if export_dir is not None:
                # The plan JSON is written once the export is staged, before it replaces the
                # earlier set: a failed export leaves the earlier plan and its export together.
                fl = mission.fleet
                with busy(f"writing the exports to {export_dir}"):  # 20 s for 100 turbines
                    done = export_all(result, export_dir, stem=stem, cruise=fl.cruise_speed_m_s,
                                      hover=fl.inspection_speed_m_s, dji=dji_kmz,
                                      before_swap=write_out)
                for p in done.stale:
                    err_console.print(f"exports: removed {p}, a staging folder a killed run left",
                                      soft_wrap=True)
                err_console.print(f"exports: {len(done.written)} file(s) -> {export_dir}"
                                  + _replaced_text(done, stem), soft_wrap=True)
            elif write_out is not None:
                write_out()
            if picture is not None:  # encoded as its name says
                ok, buf = cv2.imencode(picture.suffix.lower(), draw_plan(result))
                atomic_write_bytes(picture, buf.tobytes())
            s = result.summary
            if s.get("notes"):
                err_console.print(f"note: {len(s['notes'])} adaptation(s) near the hub, nacelle or tower "
                                  "(oblique passes, dropped stations): see summary.notes in the plan",
                                  soft_wrap=True)
            if json_out:
                typer.echo(dumps(document(PLAN_SCHEMA, PLAN_VERSION, result.to_dict())))
                return
            cov = s["predicted_coverage"]
            typer.echo(f"pattern {s['pattern']}: {len(result.routes)} UAV route(s), "
                       f"length {s['total_length_m']:.0f} m, time {s['total_time_s'] / 60:.1f} min, "
                       f"{s['photos']} photos, min clearance {s['min_clearance_m']:.2f} m "
                       f"(safe {s['safe_distance_m']:g} m), GSD {s['coverage_gsd_mm']:.2f} mm/px"
                       + ("" if s["gimbal_pitch_range_deg"] == [-90.0, 90.0] else
                          ", gimbal pitch within [{:+g}, {:+g}] deg".format(*s["gimbal_pitch_range_deg"])))
            for tid, c in cov.items():
                typer.echo(f"{tid}: predicted blade coverage {c['blade_average']:.1%} "
                           f"(worst side {c['min_side']:.1%}), tower/nacelle {c['structure']:.1%}")
                b = s["time_budget"][tid]
                typer.echo(f"{tid}: flight {b['total_s'] / 60:.1f} min = " + " + ".join(
                    f"{k[:-2].replace('_', ' ')} {b[k] / 60:.1f}" for k in BUDGET_KEYS))
            v = s["violations"]
            if any(v.values()):
                typer.echo(f"UNSAFE against the real turbines: {v} - {s['first_violation']}")
            if out is not None:
                err_console.print(f"plan -> {out}", soft_wrap=True)
