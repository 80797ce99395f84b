"""`wtinspect site`: a USWTDB CSV or OSM GeoJSON turbine list -> turbines.yaml. docs/site.md"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.markup import escape

from wtcli.console import err_console
from wtcli.errors import ConfigError


def _bbox(text: str | None):
    if text is None:
        return None
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 4:
        raise ConfigError(f"--bbox: expected MIN_LON,MIN_LAT,MAX_LON,MAX_LAT, got {text!r}")
    return v


def register(app: typer.Typer) -> None:
    @app.command("site")
    def site(
        source: Path = typer.Argument(..., metavar="SOURCE",
                                      help="A U.S. Wind Turbine Database .csv or an OpenStreetMap "
                                           ".geojson of power=generator, generator:source=wind."),
        out: Path = typer.Option(..., "--out", "-o", help="Write the turbines.yaml here."),
        project: Optional[str] = typer.Option(None, "--project",
                                              help="USWTDB: keep the rows whose p_name is this "
                                                   "(case-insensitive)."),
        bbox: Optional[str] = typer.Option(None, "--bbox", metavar="MIN_LON,MIN_LAT,MAX_LON,MAX_LAT",
                                           help="Keep the turbines inside this box (degrees; "
                                                "MIN_LON > MAX_LON: across the antimeridian)."),
        origin: str = typer.Option("centroid", "--origin",
                                   help="site.origin at the turbines' centroid or the first one."),
        origin_alt: float = typer.Option(0.0, "--origin-alt", metavar="M",
                                         help="Ground altitude at the origin, m above mean sea "
                                              "level (the databases do not give it)."),
        yaw_deg: float = typer.Option(180.0, "--yaw-deg",
                                      help="Rotor heading written for every turbine (not in the "
                                           "databases: set it per turbine on the day)."),
        hub_height: Optional[float] = typer.Option(None, "--hub-height", metavar="M",
                                                   help="Fill a missing hub height, 10-250 m "
                                                        "(reported per row); without it such rows "
                                                        "are skipped."),
        rotor_diameter: Optional[float] = typer.Option(None, "--rotor-diameter", metavar="M",
                                                       help="Fill a missing rotor diameter, 5-300 m "
                                                            "(reported per row)."),
    ) -> None:
        """Build a turbines.yaml from a turbine list you already have (USWTDB, OpenStreetMap)."""
        from wtcli.jsonio import atomic_write_text
        from wtcli.outputs import check_not_inputs
        from wtcli.plan.config import mission_from_dict
        from wtcli.site import build_site

        check_not_inputs([("--out", out)], [("the input turbine list", source)])
        s = build_site(source, project=project, bbox=_bbox(bbox), origin=origin,
                       origin_alt_m=origin_alt, yaw_deg=yaw_deg, hub_default=hub_height,
                       diam_default=rotor_diameter)
        # what we write must load: build_site checked it row by row; this is the backstop
        mission_from_dict(s.to_yaml_dict(), where=str(out))
        atomic_write_text(out, s.to_yaml_text())
        for p in s.problems:
            err_console.print(f"[yellow]{escape(p)}[/yellow]", markup=True, soft_wrap=True)
        o = s.origin
        typer.echo(f"{len(s.turbines)} turbine(s) from {s.source}; origin "
                   f"{o['lat']:.6f}, {o['lon']:.6f} ({origin}), alt {o['alt']:g} m AMSL; "
                   f"{len(s.problems)} row(s) reported; yaw_deg {s.yaw_deg:g} for every turbine "
                   "(set it on the day)")
        err_console.print(f"turbines.yaml -> {out}", soft_wrap=True)
