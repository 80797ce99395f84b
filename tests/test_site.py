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


# ---- what the turbines.yaml loader refuses is found here first, by row -------------------------

def site_cli(runner, *args):
    from wtcli.cli import app

    return runner.invoke(app, ["site", *map(str, args)])


def test_towers_too_close_later_row_reported_and_skipped(tmp_path, runner):
    rows = [("1", "C", "90", "116", "-100.0", "37.0"),
            ("2", "C", "90", "116", "-100.0003", "37.0"),   # 26.7 m from 1
            ("3", "C", "90", "116", "-100.0", "37.0"),      # on top of 1
            ("4", "C", "90", "116", "-100.003", "37.0")]    # 267 m away: kept
    s = build_site(uswtdb(tmp_path, rows))
    assert [t.id for t in s.turbines] == ["1", "4"]
    assert s.problems[0].startswith("row 3 (case_id 2): stands 26.7 m from row 2 (case_id 1), "
                                    "closer than their rotor radii allow (58 + 58 m): skipped")
    assert s.problems[1].startswith("row 4 (case_id 3): stands 0.0 m from row 2 (case_id 1)")
    assert [t.id for t in written(s, tmp_path)[1].turbines] == ["1", "4"]
    out = tmp_path / "o.yaml"
    res = site_cli(runner, uswtdb(tmp_path, rows[:2]), "-o", out)
    assert res.exit_code == 0, res.output
    assert "row 3 (case_id 2): stands 26.7 m" in res.stderr
    assert [t.id for t in load_mission(out).turbines] == ["1"]


def test_site_wider_than_the_loader_holds_is_refused_naming_the_source(tmp_path, runner):
    rows = [("1", "W", "90", "116", "-100.0", "37.0"), ("2", "W", "90", "116", "-98.8", "37.0")]
    path = uswtdb(tmp_path, rows)
    with pytest.raises(ConfigError, match=r"uswtdb.csv: the turbines span 106.8 km \(row 2 "
                       r"\(case_id 1\) to row 3 \(case_id 2\).*within 50 km.*--bbox"):
        build_site(path)
    res = site_cli(runner, path, "-o", tmp_path / "o.yaml")
    assert res.exit_code == 4 and "uswtdb.csv: the turbines span" in res.stderr
    assert "o.yaml" not in res.stderr and not (tmp_path / "o.yaml").exists()
    # 62 km across, 31 km each side of the centroid: written, with the mission-export line
    rows[1] = ("2", "W", "90", "116", "-99.3", "37.0")
    s = build_site(uswtdb(tmp_path, rows))
    assert any("31.2 km from the origin" in p for p in s.problems)
    written(s, tmp_path)
    with pytest.raises(ConfigError, match="62.3 km from the first turbine"):
        build_site(uswtdb(tmp_path, rows), origin="first")


def test_repeated_ids_get_unused_suffixes(tmp_path):
    def ids(case_ids):
        rows = [(c, "D", "90", "116", f"{-100 - 0.01 * k:.2f}", "37.0")
                for k, c in enumerate(case_ids)]
        s = build_site(uswtdb(tmp_path, rows))
        assert [t.id for t in written(s, tmp_path)[1].turbines] == [t.id for t in s.turbines]
        return [t.id for t in s.turbines], [p for p in s.problems if "repeats" in p]

    got, said = ids(["1", "1", "1-1"])
    assert got == ["1", "1-2", "1-1"]
    assert said == ["row 3 (case_id 1): id '1' repeats an earlier row: written as '1-2'"]
    assert ids(["1", "1", "1-2", "1"])[0] == ["1", "1-3", "1-2", "1-4"]
    assert ids(["7", "7", "7"])[0] == ["7", "7-2", "7-3"]
    feats = [node(k + 1, 8.0 + 0.01 * k, 50.0, ref=r, height="100", **{"rotor:diameter": "100"})
             for k, r in enumerate(["A", "A", "A-2", "A"])]
    s = build_site(osm(tmp_path, feats))
    assert [t.id for t in s.turbines] == ["A", "A-3", "A-2", "A-4"]
    written(s, tmp_path)


def test_osm_lengths_in_other_forms_and_unreadable_values(tmp_path):
    feats = [node(1, 8.00, 50.0, height="90,5", **{"rotor:diameter": "116"}),
             node(2, 8.01, 50.0, height="0.1 km", **{"rotor:diameter": "116 M"}),
             node(3, 8.02, 50.0, height="295'", **{"rotor:diameter": "380'7\""}),
             node(4, 8.03, 50.0, height=95, **{"rotor:diameter": 116.5}),
             node(5, 8.04, 50.0, height="1.2 km", **{"rotor:diameter": "116"}),
             node(6, 8.05, 50.0, height="ninety", **{"rotor:diameter": "116"}),
             node(7, 8.06, 50.0, height="90", **{"rotor:diameter": "100-120"}),
             node(8, 8.07, 50.0, height="-90", **{"rotor:diameter": "116"})]
    s = build_site(osm(tmp_path, feats), hub_default=100, diam_default=110)
    got = {t.id: (t.hub_height_m, t.rotor_diameter_m) for t in s.turbines}
    assert got == {"osm1": (90.5, 116), "osm2": (100, 116), "osm3": (89.92, 116.0),
                   "osm4": (95, 116.5)}
    assert s.problems == [
        "feature 4 (node/5): hub height 1200 m outside [10, 250]: skipped",
        "feature 5 (node/6): hub height 'ninety' unreadable: skipped",
        "feature 6 (node/7): rotor diameter '100-120' unreadable: skipped",
        "feature 7 (node/8): hub height is -90: skipped"]
    assert not any("from --hub-height" in p for p in s.problems), "a present value is never filled"
    written(s, tmp_path)
    rows = [("1", "U", "abc", "116", "-100.0", "37.0")]  # the CSV alike
    s = build_site(uswtdb(tmp_path, rows + [ROWS[0]]), hub_default=90)
    assert s.problems == ["row 2 (case_id 1): hub height 'abc' unreadable: skipped"]


@pytest.mark.parametrize("args, say", [
    (["--hub-height", "-5"], "--hub-height: expected a number in [10, 250] m"),
    (["--hub-height", "5000"], "--hub-height: expected a number in [10, 250] m"),
    (["--hub-height", "nan"], "--hub-height: expected a number in [10, 250] m"),
    (["--rotor-diameter", "inf"], "--rotor-diameter: expected a number in [5, 300] m"),
    (["--rotor-diameter", "2"], "--rotor-diameter: expected a number in [5, 300] m"),
    (["--hub-height", "40", "--rotor-diameter", "100"], "--hub-height 40 leaves no room for "
                                                        "--rotor-diameter 100"),
    (["--yaw-deg", "400"], "--yaw-deg: expected a number in [0, 360]")])
def test_fill_options_checked_up_front(tmp_path, runner, args, say):
    res = site_cli(runner, uswtdb(tmp_path), *args, "-o", tmp_path / "o.yaml")
    assert res.exit_code == 4, res.output
    assert say in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o.yaml").exists()


def test_geojson_with_a_byte_order_mark(tmp_path):
    path = tmp_path / "bom.geojson"
    doc = {"type": "FeatureCollection", "features": [node(1, 8.0, 50.0, height="100",
                                                          **{"rotor:diameter": "110"})]}
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(doc).encode())
    assert [t.id for t in build_site(path).turbines] == ["osm1"]
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(doc).replace("50.0", "NaN").encode())
    with pytest.raises(InputError, match="NaN is not a finite number"):
        build_site(path)
    path.write_bytes(b"\xef\xbb\xbf{")
    with pytest.raises(InputError, match="not valid JSON"):
        build_site(path)


def test_bbox_across_the_antimeridian(tmp_path, runner):
    rows = [("1", "A", "90", "116", "179.999", "-17.0"), ("2", "A", "90", "116", "-179.999", "-17.0"),
            ("3", "A", "90", "116", "179.995", "-17.002"), ("4", "A", "90", "116", "170.0", "-17.0"),
            ("5", "A", "90", "116", "-170.0", "-17.0")]
    path = uswtdb(tmp_path, rows)
    s = build_site(path, bbox=(179.9, -17.1, -179.9, -16.9))
    assert [t.id for t in s.turbines] == ["1", "2", "3"] and not s.problems
    assert abs(s.origin["lon"]) > 179.99  # the centroid on the sphere, not the mean of +-180
    _, m = written(s, tmp_path)
    assert np.hypot(*np.subtract(m.turbines[0].base_xyz, m.turbines[1].base_xyz)[:2]) \
        == pytest.approx(212.9, abs=0.5)
    assert [t.id for t in build_site(path, bbox=(169, -18, 171, -16)).turbines] == ["4"]
    res = site_cli(runner, path, "--bbox=179.9,-17.1,-179.9,-16.9", "-o", tmp_path / "o.yaml")
    assert res.exit_code == 0, res.output
    res = site_cli(runner, path, "--bbox=10,-17.1,10,-16.9", "-o", tmp_path / "o.yaml")
    assert res.exit_code == 4 and "across the antimeridian has min_lon > max_lon" in res.stderr
