import numpy as np
import pytest

from wtcli.errors import InputError
from wtcli.masks import (CATEGORIES, Instances, polygons_decode, polygons_encode, read_instances, rle_decode,
                         rle_encode, write_instances, write_instances_streamed)


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


def test_instances_streamed_are_the_same_bytes(tmp_path):
    """segment's instances.json, written from each photo's annotations as they are read back,
    is byte for byte what one document of every photo's masks gives: ids renumbered, a photo
    with nothing found, a batch with nothing at all."""
    rng = np.random.default_rng(3)
    images, per = [], []
    for k, n in enumerate([2, 0, 3, 1]):
        h, w = 20 + k, 30
        m = rng.random((n, h, w)) > 0.6
        per.append(Instances(np.array(["blade", "tower", "nacelle"][:n] + ["blade"] * (n - 3),
                                      object), m, rng.random(n)) if n else Instances.empty(h, w))
        images.append({"id": k + 1, "file_name": f"{k}.jpg", "width": w, "height": h})
    extra = {"settings": {"score_threshold": 0.5, "model": "m.pt"}}
    for sel in (slice(None), slice(1, 2)):
        want = write_instances(tmp_path / "one.json", images[sel], per[sel], extra=extra).read_bytes()
        anns = [p.annotations(1, first_id=1) for p in per[sel]]  # as each photo's own file holds them
        got = write_instances_streamed(tmp_path / "streamed.json", images[sel], anns, extra=extra)
        assert got.read_bytes() == want
    with pytest.raises(ValueError):  # an image without its annotations is a caller's bug
        write_instances_streamed(tmp_path / "short.json", images, anns)
    assert not list(tmp_path.glob(".short.json*")) and not (tmp_path / "short.json").exists()


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


def _as_array(b: bytes) -> np.ndarray:
    return np.frombuffer(b, np.uint8)


@pytest.mark.parametrize("ext", [".png", ".jpg", ".tif", ".bmp", ".webp"])
def test_declared_size_of_files_opencv_writes(ext):
    import cv2

    from wtcli.masks import declared_size

    ok, buf = cv2.imencode(ext, np.zeros((37, 53, 3), np.uint8))
    assert ok and declared_size(buf) == (53, 37)


def test_declared_size_of_crafted_tiff_bmp_webp_headers():
    import struct

    from wtcli.masks import declared_size

    def tiff(e: str, order: bytes, kind: int, w: int, h: int, big: bool = False) -> bytes:
        if big:
            fmt = {3: "HHQH6x", 4: "HHQI4x", 16: "HHQQ"}[kind]
            return (order + struct.pack(e + "HHHQQ", 43, 8, 0, 16, 2)
                    + struct.pack(e + fmt, 256, kind, 1, w) + struct.pack(e + fmt, 257, kind, 1, h))
        fmt = {3: "HHIH2x", 4: "HHII"}[kind]
        return (order + struct.pack(e + "HIH", 42, 8, 2) + struct.pack(e + fmt, 256, kind, 1, w)
                + struct.pack(e + fmt, 257, kind, 1, h))

    assert declared_size(_as_array(tiff("<", b"II", 4, 70000, 50000))) == (70000, 50000)
    assert declared_size(_as_array(tiff(">", b"MM", 4, 70000, 50000))) == (70000, 50000)
    assert declared_size(_as_array(tiff(">", b"MM", 3, 65535, 40000))) == (65535, 40000)
    assert declared_size(_as_array(tiff("<", b"II", 16, 10**6, 10**6, big=True))) == (10**6, 10**6)
    assert declared_size(_as_array(tiff(">", b"MM", 3, 300, 200, big=True))) == (300, 200)
    # an IFD offset past the end, or an IFD without the sizes: not told (the decoder decides)
    assert declared_size(_as_array(b"II*\0" + struct.pack("<I", 10**6) + bytes(16))) is None
    assert declared_size(_as_array(b"II*\0" + struct.pack("<IH", 8, 1)
                                   + struct.pack("<HHII", 259, 3, 1, 1))) is None
    # BMP: Windows header (negative height = top-down) and the OS/2 one with 16-bit sides
    win = b"BM" + bytes(12) + struct.pack("<Iii", 40, 30000, -20000) + bytes(16)
    assert declared_size(_as_array(win)) == (30000, 20000)
    os2 = b"BM" + bytes(12) + struct.pack("<IHH", 12, 640, 480) + bytes(16)
    assert declared_size(_as_array(os2)) == (640, 480)
    # WebP: extended (24-bit canvas) and lossless (14-bit) headers
    vp8x = b"RIFF" + bytes(4) + b"WEBPVP8X" + bytes(8) + (19999).to_bytes(3, "little") \
        + (14999).to_bytes(3, "little") + bytes(4)
    assert declared_size(_as_array(vp8x)) == (20000, 15000)
    bits = (16383) | (16383 << 14)
    vp8l = b"RIFF" + bytes(4) + b"WEBPVP8L" + bytes(4) + b"\x2f" + bits.to_bytes(4, "little") + bytes(8)
    assert declared_size(_as_array(vp8l)) == (16384, 16384)


def test_check_declared_size_refuses_a_huge_tiff(tmp_path):
    import struct

    from wtcli.masks import check_declared_size

    b = b"II*\0" + struct.pack("<IH", 8, 2) + struct.pack("<HHII", 256, 4, 1, 20000) \
        + struct.pack("<HHII", 257, 4, 1, 10001)
    with pytest.raises(InputError, match=r"x\.tif: image too large.*20000x10001"):
        check_declared_size(_as_array(b), tmp_path / "x.tif")
    b = b.replace(struct.pack("<I", 10001), struct.pack("<I", 10000))  # exactly 200 MP: allowed
    check_declared_size(_as_array(b), tmp_path / "x.tif")


def test_class_map_gives_each_pixel_one_class_nacelle_over_tower_over_blade():
    m = np.zeros((4, 6, 8), bool)
    m[0, 1:4, 0:6] = True  # a blade running on under the hub, the tower and the nacelle
    m[1, 2:6, 4:6] = True  # tower
    m[2, 0:3, 5:8] = True  # nacelle, over the blade's root and the tower's top
    m[3, 5, 0] = True  # a second blade, alone
    inst = Instances(np.array(["blade", "tower", "nacelle", "blade"], dtype=object), m)
    cmap = inst.class_map()
    assert cmap.dtype == np.uint8 and cmap.shape == (6, 8)
    assert (cmap[m[2]] == 3).all()  # the nacelle shows wherever it is
    assert (cmap[m[1] & ~m[2]] == 2).all()  # the tower wherever no nacelle is
    assert (cmap[m[0] & ~m[1] & ~m[2]] == 1).all() and cmap[5, 0] == 1
    assert (cmap[~m.any(0)] == 0).all()
    # the category ids of the instances file
    assert [c["id"] for c in CATEGORIES if c["name"] in ("blade", "tower", "nacelle")] == [1, 2, 3]
    assert (Instances.empty(3, 4).class_map() == 0).all()


def test_annotations_of_no_image_are_refused_not_dropped(tmp_path):
    """An export whose ids do not meet (image_id "1" against id 1) would train on nothing."""
    import json as _json

    from wtcli.errors import InputError
    from wtcli.masks import read_instances

    doc = {"images": [{"id": 1, "file_name": "a.png", "width": 4, "height": 4}],
           "annotations": [{"id": 1, "image_id": "1", "category_id": 1, "bbox": [0, 0, 2, 2],
                            "segmentation": [[0, 0, 2, 0, 2, 2, 0, 2]]}],
           "categories": [{"id": 1, "name": "blade"}, {"id": 2, "name": "tower"},
                          {"id": 3, "name": "nacelle"}]}
    p = tmp_path / "x.json"
    p.write_text(_json.dumps(doc))
    with pytest.raises(InputError, match=r"1 annotation\(s\) name an image_id no image has"):
        read_instances(p)
    doc["annotations"][0]["image_id"] = 1
    p.write_text(_json.dumps(doc))
    assert len(read_instances(p)) == 1


def test_a_checked_segmentation_draws_as_decoded_and_holds_no_mask():
    from wtcli.masks import check_segmentation, decode_segmentation

    m = np.zeros((300, 400), bool)
    m[20:80, 30:300] = True
    m[150:290, 10:20] = True
    for seg in (rle_encode(m), polygons_encode(m)):
        shape = check_segmentation(seg, 300, 400)
        held = shape.runs.nbytes if shape.runs is not None else sum(p.nbytes for p in shape.polygons)
        assert held < 0.05 * m.size  # a few kB against the 120 kB mask
        assert np.array_equal(shape.mask(), decode_segmentation(seg, 300, 400))
    with pytest.raises(ValueError, match=r"RLE size \[30, 40\] does not match the image 300x400"):
        check_segmentation(rle_encode(m[:30, :40]), 300, 400)
    with pytest.raises(ValueError, match="polygon 0"):
        check_segmentation([[1, 2, 3]], 300, 400)


def test_file_declared_size_reads_a_tiff_whose_tags_lie_past_the_first_mib(tmp_path):
    import struct

    from wtcli.masks import file_declared_size

    far = 1 << 21  # the first page's tags at the end, as many writers put them
    ifd = struct.pack("<H", 2) + b"".join(struct.pack("<HHII", tag, 4, 1, v)
                                          for tag, v in ((256, 70000), (257, 50000))) + bytes(4)
    p = tmp_path / "far.tif"
    p.write_bytes(b"II*\0" + struct.pack("<I", far) + bytes(far - 8) + ifd)
    with pytest.raises(InputError, match="70000x50000"):
        file_declared_size(p)
    png = tmp_path / "a.png"
    import cv2

    cv2.imwrite(str(png), np.zeros((37, 53), np.uint8))
    assert file_declared_size(png) == (53, 37)
    with pytest.raises(InputError, match="no-such.png"):
        file_declared_size(tmp_path / "no-such.png")
