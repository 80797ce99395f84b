"""An output that names one of the command's own inputs is refused before any work, exit 2,
with one line naming both; the input is left as it was (docs/exit-codes.md, "Outputs")."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_images"


def _refused(r, message: str) -> None:
    assert r.exit_code == 2, r.output
    assert r.stdout == ""
    assert r.stderr.strip().splitlines() == [f"error: {message}"]


@pytest.fixture
def inputs(tmp_path):
    """Copies of the sample inputs, so a regression replaces a copy, never the repository's."""
    for name in ("turbines.yaml", "uswtdb_sample.csv", "instances.json"):
        (tmp_path / name).write_bytes((SAMPLE / name).read_bytes())
    (tmp_path / "c.json").write_text('{"schema": "wtinspect.contours"}\n')
    (tmp_path / "plan.json").write_text('{"schema": "wtinspect.plan"}\n')
    return tmp_path


@pytest.mark.parametrize("command, name, what", [
    ("plan", "turbines.yaml", "the input turbines file"),
    ("site", "uswtdb_sample.csv", "the input turbine list"),
    ("contours", "instances.json", "an input file"),
    ("pitch", "c.json", "an input file"),
    ("fly", "plan.json", "the input plan"),
])
def test_out_naming_the_input_is_refused(cli, inputs, command, name, what):
    f = inputs / name
    before = f.read_bytes()
    extra = ["--scenario", "tiny"] if command == "fly" else []
    _refused(cli(command, f, "--out", f, *extra), f"--out {f}: is {what}; choose another output")
    assert f.read_bytes() == before


@pytest.mark.parametrize("link", ["symlink", "hardlink"])
def test_a_link_to_the_input_is_the_input(cli, inputs, link):
    src, out = inputs / "uswtdb_sample.csv", inputs / "out.csv"
    (out.symlink_to if link == "symlink" else out.hardlink_to)(src)
    before = src.read_bytes()
    _refused(cli("site", src, "--out", out),
             f"--out {out}: is the input turbine list ({src}); choose another output")
    assert src.read_bytes() == before
    # the same file by another spelling of its path
    other = inputs / "sub" / ".." / "uswtdb_sample.csv"
    (inputs / "sub").mkdir()
    r = cli("site", src, "--out", other)
    assert r.exit_code == 2 and src.read_bytes() == before


def test_plan_picture_and_pitch_inputs_and_yaml_photos_are_inputs_too(cli, inputs):
    y = inputs / "turbines.yaml"
    pj = inputs / "c.json"
    _refused(cli("plan", y, f"T1={pj}", "--out", pj),
             f"--out {pj}: is an input photo or pitch file; choose another output")
    photo = inputs / "ph.jpg"
    photo.write_bytes(b"\xff\xd8 not really a photo")
    y.write_text(y.read_text().replace("blade_azimuths_deg: [80, 200, 320]\n",
                                       "blade_azimuths_deg: [80, 200, 320]\n    photo: ph.jpg\n"))
    _refused(cli("plan", y, "--picture", photo),
             f"--picture {photo}: is turbine T1's photo in {y}; choose another output")
    assert photo.read_bytes() == b"\xff\xd8 not really a photo"


def test_fly_out_naming_the_scenario_is_refused(cli, inputs):
    scn = inputs / "s.yaml"
    scn.write_text("name: mine\n")
    _refused(cli("fly", "--scenario", scn, "--out", scn),
             f"--out {scn}: is the scenario file; choose another output")
    assert scn.read_text() == "name: mine\n"


def test_pitch_refuses_an_overlay_that_would_replace_an_input(cli, inputs):
    """A rerun over a folder that holds last run's overlays (colour PNGs, so photos):
    ``b.jpg``'s overlay ``b_pitch.png`` is one of the inputs. Refused before segmenting."""
    img = np.zeros((32, 32, 3), np.uint8)
    img[..., 2] = 200
    cv2.imwrite(str(inputs / "b.jpg"), img)
    cv2.imwrite(str(inputs / "b_pitch.png"), img)
    before = (inputs / "b_pitch.png").read_bytes()
    ov = inputs / "b_pitch.png"
    _refused(cli("pitch", inputs / "b.jpg", ov, "--overlay-dir", inputs),
             f"--overlay-dir file {ov}: is an input file; choose another output")
    assert ov.read_bytes() == before
    _refused(cli("pitch", inputs / "b.jpg", "--image", inputs / "b.jpg", "--out",
                 inputs / "b.jpg"),
             f"--out {inputs / 'b.jpg'}: is an input file; choose another output")


def test_same_file_compares_paths_that_do_not_exist_yet(tmp_path):
    from wtcli.outputs import same_file

    assert same_file(tmp_path / "a" / ".." / "x", tmp_path / "x")
    assert not same_file(tmp_path / "x", tmp_path / "y")
    (tmp_path / "y").write_text("")
    os.link(tmp_path / "y", tmp_path / "z")
    assert same_file(tmp_path / "y", tmp_path / "z")


def test_two_outputs_that_are_one_file_are_refused(cli, inputs):
    """`plan --out x.png --picture x.png`: the picture would replace the plan just written."""
    out = inputs / "x.png"
    r = cli("plan", inputs / "turbines.yaml", "--out", out, "--picture", out)
    _refused(r, f"--picture {out}: is also --out's output; choose another output")
    assert not out.exists()
