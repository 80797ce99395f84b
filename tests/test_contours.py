"""contours: eq. 4-6 on masks built in code, mask PNG inputs, the contours file and CLI."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from wtcli.contours import (CONTOURS_SCHEMA, ContourSet, InstanceContours, binarise,
                            find_contours, instances_from_mask_files, load_instances,
                            read_contours, region_area, require_contours)
from wtcli.errors import InputError, PerceptionError
from wtcli.masks import Instances, write_instances


def rect_mask(h, w, x0, y0, x1, y1):
    m = np.zeros((h, w), bool)
    m[y0:y1, x0:x1] = True
    return m


def three_parts(h=60, w=80):
    blade = rect_mask(h, w, 5, 5, 60, 12)
    blade[40:42, 70:72] = True  # a 4 px speck of noise in the blade mask
    tower = rect_mask(h, w, 30, 20, 36, 60)
    nacelle = rect_mask(h, w, 28, 14, 38, 20)
    return Instances(np.array(["blade", "tower", "nacelle"], object),
                     np.stack([blade, tower, nacelle]), np.array([0.9, 0.8, 0.7]))


def test_binarise_eq4():
    m = np.array([[0, 1, 255], [0, 0, 7]])
    assert binarise(m).tolist() == [[0, 1, 1], [0, 0, 1]]
    assert binarise(m).dtype == np.uint8
    with pytest.raises(ValueError, match="expected a mask"):
        binarise(np.zeros((2, 2, 2)))


def test_area_is_enclosed_pixels_even_for_one_pixel_wide_blades():
    m = np.zeros((20, 200), np.uint8)
    cv2.line(m, (5, 10), (190, 10), 1, 1)
    (c,), _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    assert cv2.contourArea(c) == 0  # the polygon area eq. 6 must not use
    assert region_area(c.reshape(-1, 2)) == int(m.sum()) == 186
    cs = find_contours(Instances(np.array(["blade"], object), m[None] > 0), 100)
    assert len(cs) == 1 and cs.instances[0].area == 186


def test_area_filter_eq6_is_strict_and_keeps_indices():
    inst = three_parts()
    cs = find_contours(inst, area_threshold=4)  # the 4 px speck is not > 4
    assert list(cs.labels) == ["blade", "tower", "nacelle"]
    assert len(cs.instances[0].contours) == 1 and cs.dropped == 1
    assert cs.largest_dropped_area == 4
    assert cs.instances[0].area == 55 * 7
    assert len(find_contours(inst, area_threshold=3).instances[0].contours) == 2
    # A threshold above the nacelle (60 px) drops it but keeps the others' source indices.
    cs = find_contours(inst, area_threshold=60)
    assert list(cs.labels) == ["blade", "tower"]
    assert [i.source_index for i in cs] == [0, 1]
    assert cs.of("tower").instances[0].score == pytest.approx(0.8)
    assert len(cs[cs.areas > 300]) == 1


def test_fill_gives_the_region_back():
    inst = three_parts()
    cs = find_contours(inst, 4)
    for i, ic in enumerate(cs):
        full = ic.fill(inst.image_size)
        m = inst.masks[ic.source_index].copy()
        if i == 0:
            m[40:42, 70:72] = False
        assert (full == m).all()


def test_nothing_left_is_a_clear_perception_error():
    inst = three_parts()
    cs = find_contours(inst, area_threshold=10_000)
    assert len(cs) == 0
    with pytest.raises(PerceptionError, match=r"no contour above the area threshold \(10000 px\)"):
        require_contours(cs)
    empty = find_contours(Instances.empty(10, 10), 1)
    with pytest.raises(PerceptionError, match="empty"):
        require_contours(empty)


def test_contour_set_checks_itself():
    c = np.array([[0, 0], [5, 0], [5, 5]])
    with pytest.raises(ValueError, match="inside the 4x4 image"):
        ContourSet((InstanceContours("blade", 1.0, 0, (c,), (20,)),), (4, 4), 1.0)
    with pytest.raises(ValueError, match="label"):
        InstanceContours("rotor", 1.0, 0, (c,), (20,))
    with pytest.raises(ValueError, match="positive areas"):
        InstanceContours("blade", 1.0, 0, (c,), (0,))
    with pytest.raises(ValueError, match="area_threshold"):
        find_contours(three_parts(), -1)


def test_roundtrip_through_file(tmp_path):
    inst = three_parts()
    write_instances(tmp_path / "i.json", [{"id": 3, "file_name": "a.png", "width": 80,
                                           "height": 60}], [inst])
    from wtcli.contours import contours_batch
    from wtcli.jsonio import write_json

    seen = []
    batch = contours_batch([tmp_path / "i.json"], 4, progress=lambda *x: seen.append(x))
    assert seen == [("images", 0, 1), ("images", 1, 1)]
    write_json(tmp_path / "c.json", batch.to_document())
    (cs, err, img), = read_contours(tmp_path / "c.json")
    assert err is None and img["file_name"] == "a.png"
    ref = find_contours(inst, 4)
    assert [i.label for i in cs] == [i.label for i in ref]
    for a, b in zip(cs, ref):
        assert all((x == y).all() for x, y in zip(a.contours, b.contours))
        assert a.areas == b.areas


def test_mask_files_binary_label_and_names(tmp_path):
    h, w = 40, 50
    b1 = rect_mask(h, w, 2, 2, 30, 8).astype(np.uint8) * 255
    cv2.imwrite(str(tmp_path / "blade_1.png"), b1)
    cv2.imwrite(str(tmp_path / "hub.png"), rect_mask(h, w, 20, 20, 26, 26).astype(np.uint8))
    rec, inst = instances_from_mask_files([tmp_path / "blade_1.png", tmp_path / "hub.png"])
    assert list(inst.labels) == ["blade", "nacelle"] and (rec["width"], rec["height"]) == (w, h)
    lab = np.zeros((h, w), np.uint8)
    lab[2:8, 2:30], lab[12:18, 2:30], lab[25:30, 2:40] = 1, 2, 7
    cv2.imwrite(str(tmp_path / "labels.png"), lab)
    _, inst = instances_from_mask_files([tmp_path / "labels.png"])
    assert list(inst.labels) == ["blade"] * 3
    assert inst.masks[2].sum() == 5 * 38
    # 3-channel grey PNGs are masks too
    cv2.imwrite(str(tmp_path / "grey3.png"), cv2.cvtColor(b1, cv2.COLOR_GRAY2BGR))
    _, inst = instances_from_mask_files([tmp_path / "grey3.png"])
    assert len(inst) == 1


def test_bad_mask_files(tmp_path):
    (tmp_path / "garbage.png").write_bytes(b"not a png at all")
    (tmp_path / "empty.png").write_bytes(b"")
    colour = np.zeros((10, 10, 3), np.uint8)
    colour[..., 2] = 200
    colour[:5, :, 1] = 50
    cv2.imwrite(str(tmp_path / "photo.png"), colour)
    cv2.imwrite(str(tmp_path / "small.png"), np.ones((5, 5), np.uint8))
    cv2.imwrite(str(tmp_path / "big.png"), np.ones((6, 5), np.uint8))
    with pytest.raises(InputError, match="cannot read"):
        load_instances([tmp_path / "garbage.png"])
    with pytest.raises(InputError, match="cannot read"):
        load_instances([tmp_path / "empty.png"])
    with pytest.raises(InputError, match="not found"):
        load_instances([tmp_path / "missing.png"])
    with pytest.raises(InputError, match="colour image, not a mask"):
        load_instances([tmp_path / "photo.png"])
    with pytest.raises(InputError, match="differs"):
        load_instances([tmp_path / "small.png", tmp_path / "big.png"])
    with pytest.raises(InputError, match="expected an instances JSON or mask PNG"):
        load_instances([tmp_path / "notes.txt"])


# ---- CLI -------------------------------------------------------------------------------------
@pytest.fixture
def instances_file(tmp_path):
    inst = three_parts()
    speck = Instances(np.array(["blade"], object), rect_mask(60, 80, 0, 0, 2, 2)[None])
    return write_instances(tmp_path / "instances.json",
                           [{"id": 1, "file_name": "a.png", "width": 80, "height": 60},
                            {"id": 2, "file_name": "b.png", "width": 80, "height": 60}],
                           [inst, speck])


def test_cli_writes_file_and_clean_json(cli, instances_file, tmp_path):
    out = tmp_path / "out" / "contours.json"
    r = cli("contours", instances_file, "--area-threshold", "4", "--out", out, "--json")
    assert r.exit_code == 9  # image 2 has nothing above the threshold
    doc = json.loads(r.stdout)  # stdout is exactly one JSON document
    assert doc["schema"] == CONTOURS_SCHEMA and doc["schema_version"] == 1
    assert doc == json.loads(out.read_text())
    assert doc["images"][0]["error"] is None and len(doc["images"][0]["instances"]) == 3
    assert "no contour above the area threshold" in doc["images"][1]["error"]
    assert "1 of 2 images failed" in r.stderr
    assert "Traceback" not in r.stdout + r.stderr


def test_cli_single_image_ok_and_failing(cli, tmp_path):
    p = write_instances(tmp_path / "one.json", [{"id": 1, "file_name": "a.png", "width": 80,
                                                  "height": 60}], [three_parts()])
    r = cli("contours", p)
    assert r.exit_code == 0 and "a.png: 1 blade, 1 tower, 1 nacelle (dropped 1 contour(s) <= 20 px)" in r.stdout
    r = cli("contours", p, "--area-threshold", "1e6")
    assert r.exit_code == 5
    assert r.stderr.count("\n") == 1 and "no contour above the area threshold" in r.stderr


@pytest.mark.parametrize("content, code, msg", [
    ("{broken", 3, "not valid JSON"),
    ('{"schema": "wtinspect.plan", "images": [], "annotations": []}', 3, "got schema 'wtinspect.plan'"),
    ('{"images": [{"id": 1}], "annotations": []}', 3, "needs integer"),
    ('[1, 2]', 3, "JSON object, got list"),
])
def test_cli_wrong_json_is_one_line(cli, tmp_path, content, code, msg):
    p = tmp_path / "x.json"
    p.write_text(content)
    r = cli("contours", p)
    assert r.exit_code == code and msg in r.stderr and "Traceback" not in r.stderr
    assert r.stdout == ""


def test_cli_missing_and_negative_threshold(cli, tmp_path):
    assert cli("contours", tmp_path / "nope.json").exit_code == 3
    assert cli("contours", tmp_path / "nope.json", "--area-threshold", "-1").exit_code == 2


def test_cli_mask_pngs(cli, tmp_path):
    inst = three_parts()
    for name, k in (("blade.png", 0), ("tower.png", 1), ("nacelle.png", 2)):
        cv2.imwrite(str(tmp_path / name), inst.masks[k].astype(np.uint8) * 255)
    r = cli("contours", tmp_path / "blade.png", tmp_path / "tower.png", tmp_path / "nacelle.png",
            "--area-threshold", "4", "--json")
    assert r.exit_code == 0, r.stderr
    img, = json.loads(r.stdout)["images"]
    assert [i["label"] for i in img["instances"]] == ["blade", "tower", "nacelle"]
    assert img["image_size"] == [60, 80] and img["dropped"] == 1


def _many_images(path, n, size=1000):
    """An instances file of ``n`` images, six full-height bars each (6 MB of masks an image)."""
    per, images = [], []
    for i in range(n):
        m = np.zeros((6, size, size), bool)
        for k in range(6):
            m[k, 10:size - 10, 100 * k + 20:100 * k + 60] = True
        per.append(Instances(np.array(["blade"] * 6, object), m, np.full(6, 0.9)))
        images.append({"id": i + 1, "file_name": f"{i}.jpg", "width": size, "height": size})
    write_instances(path, images, per)
    return path


@pytest.mark.parametrize("stage", ["contours", "pitch"])
def test_a_large_instances_file_is_read_one_image_at_a_time(tmp_path, stage):
    """segment's instances.json of a whole folder: contours and pitch draw one image's masks at
    a time (all of them at once took 3 GB for forty 12 MP photos)."""
    import tracemalloc

    from wtcli.contours import contours_batch
    from wtcli.pitch.inputs import load_pitch_input

    peaks = {}
    for n in (2, 8):
        path = _many_images(tmp_path / f"i{n}.json", n)
        tracemalloc.start()
        if stage == "contours":
            got = contours_batch([path])
            assert len(got.sets) == n and got.n_failed == 0
        else:
            got = load_pitch_input([path])
            assert len(got) == n
        peaks[n] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert peaks[8] - peaks[2] < 9e6, peaks  # six more images' masks would be 36 MB


def test_a_contours_file_is_written_one_image_at_a_time_the_same_bytes(tmp_path):
    """`contours --out` streams the file image by image: the bytes of the whole document."""
    from wtcli.contours import contours_batch
    from wtcli.jsonio import write_json

    path = _many_images(tmp_path / "i.json", 3, size=200)
    batch = contours_batch([path])
    want = write_json(tmp_path / "whole.json", batch.to_document()).read_bytes()
    assert batch.write(tmp_path / "streamed.json").read_bytes() == want
    empty = contours_batch([path])
    empty = type(empty)((), (), (), empty.source, empty.area_threshold)
    assert empty.write(tmp_path / "e.json").read_bytes() == \
        write_json(tmp_path / "e2.json", empty.to_document()).read_bytes()
