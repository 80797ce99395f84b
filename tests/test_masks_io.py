import numpy as np
import pytest

from wtcli.errors import InputError
from wtcli.masks import (Instances, polygons_decode, polygons_encode, read_instances, rle_decode,
                         rle_encode, write_instances)


def test_rle_roundtrip_and_convention():
    m = np.zeros((4, 3), bool)
    m[0, 0] = True
    m[1:3, 2] = True
    rle = rle_encode(m)
    assert rle["size"] == [4, 3]
    assert rle["counts"][0] == 0  # first pixel set -> leading empty background run
    assert sum(rle["counts"]) == 12
    assert (rle_decode(rle) == m).all()
    rng = np.random.default_rng(0)
    for _ in range(20):
        r = rng.random((rng.integers(1, 30), rng.integers(1, 30))) > 0.5
        assert (rle_decode(rle_encode(r)) == r).all()


def test_polygon_roundtrip_is_close():
    m = np.zeros((50, 60), bool)
    m[10:30, 5:40] = True
    back = polygons_decode(polygons_encode(m), 50, 60)
    assert (back ^ m).sum() < 0.1 * m.sum()


def test_instances_file_roundtrip(tmp_path):
    m = np.zeros((2, 20, 30), bool)
    m[0, 2:5, 3:9] = True
    m[1, 10:18, 10:12] = True
    inst = Instances(np.array(["blade", "tower"], object), m, np.array([0.9, 0.5]))
    p = write_instances(tmp_path / "i.json", [{"id": 7, "file_name": "x.png", "width": 30,
                                               "height": 20}], [inst])
    (img, back), = read_instances(p)
    assert img["file_name"] == "x.png"
    assert list(back.labels) == ["blade", "tower"]
    assert (back.masks == m).all()
    assert np.allclose(back.boxes[0], [3, 2, 9, 5])
    assert len(inst[inst.scores > 0.6]) == 1


def test_bad_instances_files_are_clear(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text("{not json")
    with pytest.raises(InputError, match="not valid JSON"):
        read_instances(p)
    p.write_text('{"images": 3}')
    with pytest.raises(InputError, match="COCO instances"):
        read_instances(p)
    p.write_text('{"images": [{"id": 1, "width": 4, "height": 4}], "annotations": '
                 '[{"image_id": 1, "category_id": 9, "segmentation": []}]}')
    with pytest.raises(InputError, match=r"category_id: expected an integer in \[1, 3\], got 9"):
        read_instances(p)
    with pytest.raises(ValueError, match="labels"):
        Instances(np.array(["rotor"], object), np.zeros((1, 2, 2), bool))
