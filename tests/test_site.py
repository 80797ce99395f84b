"""`wtinspect site`: USWTDB CSV and OpenStreetMap GeoJSON -> turbines.yaml that the plan loader
accepts; bad rows reported by row, never invented and never a crash. Inputs are built here."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from wtcli.errors import ConfigError, InputError
from wtcli.plan.config import load_mission
from wtcli.plan.geodesy import geodetic_to_enu
from wtcli.site import build_site

HEADER = "case_id,t_state,p_name,p_year,t_manu,t_cap,t_hh,t_rd,t_ttlh,xlong,ylat\n"
ROWS = [  # (case_id, p_name, t_hh, t_rd, xlong, ylat)
    ("101", "Windy Mesa", "80", "100", "-101.5000", "35.2000"),
    ("102", "Windy Mesa", "80", "100", "-101.4950", "35.2010"),
    ("103", "Windy Mesa", "", "100", "-101.4900", "35.2020"),       # hub height missing
    ("104", "Windy Mesa", "80", "0", "-101.4850", "35.2030"),       # zero diameter
    ("105", "Windy Mesa", "80", "100", "", ""),                     # no coordinates
    ("106", "Windy Mesa", "-9999", "-9999", "-101.4800", "35.2040"),  # USWTDB's 'missing'
    ("107", "Windy Mesa", "40", "100", "-101.4750", "35.2050"),     # hub below the rotor
    ("201", "Other Farm", "95", "120", "-101.9000", "35.6000"),
]


def uswtdb(tmp_path, rows=ROWS):
    path = tmp_path / "uswtdb.csv"
    path.write_text(HEADER + "".join(f"{c},TX,{p},2015,GE,2300,{h},{d},0,{x},{y}\n"
                                     for c, p, h, d, x, y in rows))
    return path


def osm(tmp_path, feats):
    path = tmp_path / "wind.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    return path


def node(i, lon, lat, **tags):
    return {"type": "Feature", "id": f"node/{i}", "geometry": {"type": "Point", "coordinates":
            [lon, lat]}, "properties": {"power": "generator", "generator:source": "wind", **tags}}


def written(site, tmp_path):
    path = tmp_path / "turbines.yaml"
    path.write_text(site.to_yaml_text())
    return path, load_mission(path)


def test_uswtdb_project_filter_bad_rows_reported_by_row(tmp_path):
    s = build_site(uswtdb(tmp_path), project="windy mesa")
    assert [t.id for t in s.turbines] == ["101", "102"]
    assert s.problems == [
        "row 4 (case_id 103): hub height missing: skipped (give --hub-height to fill it)",
        "row 5 (case_id 104): rotor diameter is 0: skipped",
        "row 6 (case_id 105): missing or invalid coordinates: skipped",
        "row 7 (case_id 106): hub height missing: skipped (give --hub-height to fill it)",
        "row 8 (case_id 107): hub height 40 m leaves no room for a 100 m rotor: skipped"]
    path, m = written(s, tmp_path)
    text = path.read_text()
    assert all(f"# {p}" in text for p in s.problems), "the YAML carries the report"
    assert [t.id for t in m.turbines] == ["101", "102"]
    assert [t.hub_height for t in m.turbines] == [80, 80]
    assert [t.rotor_diameter for t in m.turbines] == [100, 100]
    # centroid origin; each base where its lat/lon says
    assert m.site_origin["lat"] == pytest.approx(35.2005, abs=1e-6)
    for t, (_, _, _, _, x, y) in zip(m.turbines, ROWS):
        want = geodetic_to_enu(float(y), float(x), 0.0, m.site_origin)
        assert np.allclose(t.base_xyz, want, atol=1e-6)


def test_uswtdb_defaults_fill_missing_values_and_say_so(tmp_path):
    s = build_site(uswtdb(tmp_path), project="Windy Mesa", hub_default=85, diam_default=110,
                   origin="first", origin_alt_m=900, yaw_deg=225)
    ids = [t.id for t in s.turbines]
    assert ids == ["101", "102", "103", "106"]
    assert "row 4 (case_id 103): hub height missing: 85 m from --hub-height" in s.problems
    assert "row 7 (case_id 106): rotor diameter missing: 110 m from --rotor-diameter" in s.problems
    assert "row 5 (case_id 104): rotor diameter is 0: skipped" in s.problems
    _, m = written(s, tmp_path)
    t = {t.id: t for t in m.turbines}
    assert (t["103"].hub_height, t["103"].rotor_diameter) == (85, 100)
    assert (t["106"].hub_height, t["106"].rotor_diameter) == (85, 110)
    assert m.site_origin == {"lat": 35.2, "lon": -101.5, "alt": 900.0}
    assert np.allclose(t["101"].base_xyz, 0, atol=1e-6) and t["101"].yaw_deg == 225


def test_uswtdb_bbox_and_no_match(tmp_path):
    path = uswtdb(tmp_path)
    s = build_site(path, bbox=(-102, 35.5, -101.8, 35.7))
    assert [t.id for t in s.turbines] == ["201"]
    # a row without coordinates may belong to the box: it is reported, not dropped unseen
    assert s.problems == ["row 6 (case_id 105): missing or invalid coordinates: skipped"]
    with pytest.raises(InputError, match="did you mean 'Windy Mesa'"):
        build_site(path, project="Windy Messa")
    with pytest.raises(InputError, match="every matching row was skipped"):
        build_site(uswtdb(tmp_path, [ROWS[3], ROWS[4]]))
    bad = tmp_path / "bad.csv"
    bad.write_text("id,lon,lat\n1,2,3\n")
    with pytest.raises(InputError, match="missing column.*case_id"):
        build_site(bad)
    with pytest.raises(ConfigError, match="--bbox"):
        build_site(path, bbox=(10, 10, 5, 5))


def test_osm_geojson_tags_units_and_bad_features(tmp_path):
    feats = [node(1, 8.0, 50.0, ref="WEA1", height="120 m", **{"rotor:diameter": "131"}),
             node(2, 8.004, 50.001, height="394 ft", **{"rotor:diameter": "131 m"}),
             node(3, 8.008, 50.002),                                         # no tags: defaults
             node(4, 8.012, 50.003, **{"rotor:diameter": "0"}),                # zero diameter
             {"type": "Feature", "id": "node/5", "geometry": None,
              "properties": {"tags": {"power": "generator", "generator:source": "wind"}}},
             {"type": "Feature", "id": "way/6", "geometry": {"type": "Polygon", "coordinates": []},
              "properties": {"power": "generator", "generator:source": "wind"}},
             node(7, 8.1, 50.1, **{"generator:source": "solar"})]             # not wind: ignored
    s = build_site(osm(tmp_path, feats), hub_default=100, diam_default=120)
    assert [t.id for t in s.turbines] == ["WEA1", "osm2", "osm3"]
    assert s.turbines[1].hub_height_m == pytest.approx(120.09, abs=0.01)  # 394 ft
    assert s.problems == [
        "feature 2 (node/3): hub height missing: 100 m from --hub-height",
        "feature 2 (node/3): rotor diameter missing: 120 m from --rotor-diameter",
        "feature 3 (node/4): rotor diameter is 0: skipped",
        "feature 4 (node/5): missing or invalid coordinates: skipped",
        "feature 5 (way/6): geometry 'Polygon' is not a Point: skipped"]
    _, m = written(s, tmp_path)
    assert [t.id for t in m.turbines] == ["WEA1", "osm2", "osm3"]
    assert [t.rotor_diameter for t in m.turbines] == [131, 131, 120]
    with pytest.raises(ConfigError, match="--project filters a USWTDB CSV"):
        build_site(osm(tmp_path, feats), project="x")
    s = build_site(osm(tmp_path, feats))  # without defaults the unknown turbine is skipped
    assert [t.id for t in s.turbines] == ["WEA1", "osm2"]
    assert "feature 2 (node/3): hub height missing: skipped (give --hub-height to fill it)" \
        in s.problems


def test_wide_site_is_reported_and_the_yaml_header_states_what_is_not_known(tmp_path):
    rows = [("1", "Long", "80", "100", "-100.0", "40.0"), ("2", "Long", "80", "100", "-99.85", "40.0")]
    s = build_site(uswtdb(tmp_path, rows), origin="first")
    assert any("12.8 km from the origin" in p and "10 km" in p for p in s.problems)
    text = s.to_yaml_text()
    assert "yaw_deg (180) is not in any turbine database" in text
    assert "site.origin.alt is metres above mean sea level" in text
    assert yaml.safe_load(text)["turbines"][1]["id"] == "2"


def test_site_command(tmp_path, runner):
    from wtcli.cli import app

    path = uswtdb(tmp_path)
    out = tmp_path / "site.yaml"
    res = runner.invoke(app, ["site", str(path), "--project", "Windy Mesa", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert res.stdout.startswith("2 turbine(s) from the USWTDB CSV")
    assert "row 6 (case_id 105): missing or invalid coordinates: skipped" in res.stderr
    assert [t.id for t in load_mission(out).turbines] == ["101", "102"]
    res = runner.invoke(app, ["site", str(tmp_path / "nope.csv"), "-o", str(out)])
    assert res.exit_code == 3 and "no such file" in res.stderr
    res = runner.invoke(app, ["site", str(path), "--bbox", "1,2,3", "-o", str(out)])
    assert res.exit_code == 4 and "--bbox" in res.stderr
