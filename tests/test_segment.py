"""segment: the model contract (no trained weights needed), weights errors, the batch command
(folder, bad files, resume, large photos) and the metrics."""

from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from wtcli.errors import ExitCode, InputError, ModelError
from wtcli.masks import LABELS, Instances, read_instances
from wtcli.segment import batch, infer, post
from wtcli.segment.evaluate import Evaluator, average_precision, mask_iou
from wtcli.segment.model import ARCH, build_model, load_weights, save_weights


@pytest.fixture(scope="module")
def random_weights(tmp_path_factory) -> Path:
    """A weights file of the real format holding random (untrained) weights; the box-score
    threshold is lowered so the untrained network returns detections to check shapes on."""
    torch.manual_seed(0)
    path = tmp_path_factory.mktemp("w") / "random.pt"
    save_weights(build_model(), path, meta={"note": "random"})
    return path


@pytest.fixture(scope="module")
def random_model(random_weights):
    m = infer.load_model(random_weights, "cpu")
    m.roi_heads.score_thresh = 0.0
    return m


def _image(h: int = 120, w: int = 160, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = np.full((h, w, 3), 200, np.uint8)
    cv2.line(img, (w // 2, h // 2), (w // 2, 5), (250, 250, 250), 6)
    cv2.rectangle(img, (w // 2 - 3, h // 2), (w // 2 + 3, h - 1), (230, 230, 230), -1)
    return np.clip(img + rng.normal(0, 5, img.shape), 0, 255).astype(np.uint8)


# ---- model ---------------------------------------------------------------------------------
def test_build_model_is_offline_and_small():
    m = build_model()
    n = sum(p.numel() for p in m.parameters())
    assert 3e6 < n < 12.5e6  # fp16 file stays well under 25 MB
    assert m.roi_heads.box_predictor.cls_score.out_features == len(LABELS) + 1


def test_predict_output_contract(random_model):
    img = _image()
    inst = infer.predict(random_model, img, score_threshold=0.0)
    assert isinstance(inst, Instances)
    assert inst.image_size == img.shape[:2]
    assert inst.masks.dtype == bool and inst.masks.shape[1:] == img.shape[:2]
    assert set(inst.labels) <= set(LABELS)
    assert ((inst.scores >= 0) & (inst.scores <= 1)).all()
    assert (inst.boxes[:, 2] >= inst.boxes[:, 0]).all() and (inst.boxes[:, 2] <= img.shape[1]).all()
    strict = infer.predict(random_model, img, score_threshold=1.0)
    assert len(strict) <= len(inst)


def test_weights_round_trip_fp16(random_weights, tmp_path):
    a, b = build_model(), build_model()
    meta = load_weights(a, random_weights)
    assert meta == {"note": "random"}
    save_weights(a, tmp_path / "again.pt")
    load_weights(b, tmp_path / "again.pt")
    for (k, va), vb in zip(a.state_dict().items(), b.state_dict().values()):
        assert torch.equal(va, vb), k
    assert (tmp_path / "again.pt").stat().st_size < 25e6


def test_fine_level_pools_what_the_stride_8_level_pools():
    """The stride-4 level starts as the stride-8 one upsampled: RoIAlign on it at twice the
    scale samples exactly the same values (so weights from before it load unchanged)."""
    from torchvision.ops import roi_align
    from wtcli.segment.model import _upsample2

    torch.manual_seed(0)
    x = torch.rand(1, 3, 12, 16)
    # (boxes at least a coarse cell wide: RoIAlign widens narrower ones to one cell of its level)
    boxes = torch.tensor([[8.0, 8.0, 100.0, 60.0], [30.5, 17.25, 39.0, 80.0], [0.0, 0.0, 120.0, 88.0]])
    coarse = roi_align(x, [boxes], 14, 1 / 8, 2, aligned=False)
    fine = roi_align(_upsample2(x), [boxes], 14, 1 / 4, 2, aligned=False)
    assert torch.allclose(coarse, fine, atol=1e-5)
    # torchvision's own bilinear upsampling would put it a quarter of a coarse cell off
    shifted = torch.nn.functional.interpolate(x, scale_factor=2, mode="bilinear", align_corners=False)
    assert not torch.allclose(coarse, roi_align(shifted, [boxes], 14, 1 / 4, 2, aligned=False), atol=1e-3)


def test_weights_from_before_the_fine_level_load_as_trained(random_weights, tmp_path):
    from wtcli.segment.model import ARCH_BEFORE_P2, _upsample2

    blob = torch.load(random_weights, weights_only=True)
    old = {k: v for k, v in blob["state_dict"].items() if not k.startswith("backbone.fine.")}
    torch.save({"arch": ARCH_BEFORE_P2, "state_dict": old, "meta": {}}, tmp_path / "old.pt")
    m = build_model().eval()
    torch.nn.init.normal_(m.backbone.fine[2].weight)  # whatever it held, the load zeroes it
    load_weights(m, tmp_path / "old.pt")
    assert not m.backbone.fine[2].weight.any()
    with torch.inference_mode():
        f = m.backbone(torch.rand(1, 3, 64, 96))
    assert torch.equal(f["p2"], _upsample2(f["0"]))
    del old["roi_heads.mask_predictor.mask_fcn_logits.bias"]  # anything else missing: refused
    torch.save({"arch": ARCH_BEFORE_P2, "state_dict": old, "meta": {}}, tmp_path / "old.pt")
    with pytest.raises(ModelError, match="do not fit"):
        load_weights(build_model(), tmp_path / "old.pt")


def test_rpn_does_not_see_the_fine_level():
    from torchvision.models.detection.image_list import ImageList

    m = build_model().eval()
    x = torch.rand(1, 3, 64, 96)
    with torch.inference_mode():
        f = m.backbone(x)
        images = ImageList(x, [(64, 96)])
        a = m.rpn(images, f)[0][0]
        f["p2"] = torch.rand_like(f["p2"]) * 100
        b = m.rpn(images, f)[0][0]
    assert torch.equal(a, b)


def test_missing_weights_is_model_error(tmp_path):
    p = tmp_path / "nope.pt"
    with pytest.raises(ModelError, match="nope.pt"):
        load_weights(build_model(), p)


@pytest.mark.parametrize("content", [b"", b"not a torch file at all", b"PK\x03\x04garbage"])
def test_corrupt_weights_is_model_error(tmp_path, content):
    p = tmp_path / "bad.pt"
    p.write_bytes(content)
    with pytest.raises(ModelError, match="bad.pt"):
        load_weights(build_model(), p)


def test_wrong_weights_is_model_error(tmp_path):
    p = tmp_path / "other.pt"
    torch.save({"arch": "something-else", "state_dict": {}}, p)
    with pytest.raises(ModelError, match="architecture"):
        load_weights(build_model(), p)
    torch.save({"arch": ARCH, "state_dict": {"x": torch.zeros(1)}}, p)
    with pytest.raises(ModelError, match="do not fit"):
        load_weights(build_model(), p)


def test_cli_missing_model_exits_7(cli, tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), _image())
    res = cli("segment", tmp_path / "a.png", "--model", tmp_path / "missing.pt", "--out", tmp_path / "o")
    assert res.exit_code == ExitCode.MODEL
    assert "missing.pt" in res.stderr


# ---- inference helpers -----------------------------------------------------------------------
def test_large_image_is_downscaled_and_masks_come_back_full_size(random_model, monkeypatch):
    seen = []
    real = random_model.transform.forward

    def spy(images, targets=None):
        seen.append(tuple(images[0].shape[-2:]))
        return real(images, targets)

    monkeypatch.setattr(random_model.transform, "forward", spy)
    big = cv2.resize(_image(), (2400, 1800), interpolation=cv2.INTER_LINEAR)
    inst = infer.predict(random_model, big, score_threshold=0.0, max_size=320)
    assert max(seen[0]) <= 320
    assert inst.image_size == (1800, 2400)
    assert (inst.boxes[:, [0, 2]] <= 2400).all()


def test_predict_rejects_bad_arrays(random_model):
    with pytest.raises(InputError):
        infer.predict(random_model, np.zeros((10, 10, 3), np.float32))
    with pytest.raises(InputError):
        infer.predict(random_model, np.zeros((4, 4, 3), np.uint8))


def test_remove_background_keeps_only_the_union():
    img = _image()
    m = np.zeros((2,) + img.shape[:2], bool)
    m[0, 10:20, 10:30] = True
    m[1, 50:60, 40:45] = True
    out = infer.remove_background(img, Instances(np.array(["blade", "tower"], dtype=object), m))
    assert (out[~m.any(0)] == 0).all()
    assert (out[m.any(0)] == img[m.any(0)]).all()


def test_overlay_shape():
    img = _image()
    m = np.zeros((1,) + img.shape[:2], bool)
    m[0, 10:20, 10:30] = True
    ov = infer.overlay(img, Instances(np.array(["nacelle"], dtype=object), m, np.array([0.9])))
    assert ov.shape == img.shape and ov.dtype == np.uint8 and not np.array_equal(ov, img)


# ---- the batch command -------------------------------------------------------------------------
@pytest.fixture
def photo_folder(tmp_path) -> Path:
    d = tmp_path / "photos"
    (d / "sub").mkdir(parents=True)
    cv2.imwrite(str(d / "a.png"), _image(seed=1))
    cv2.imwrite(str(d / "b.jpg"), _image(seed=2))
    cv2.imwrite(str(d / "sub" / "c.tif"), _image(seed=3))
    (d / "notes.txt").write_text("not an image")
    return d


def test_segment_folder_writes_everything(cli, photo_folder, random_weights, tmp_path):
    out = tmp_path / "seg"
    res = cli("segment", photo_folder, "--out", out, "--model", random_weights, "--json",
              "--score-threshold", "0.0")
    assert res.exit_code == 0, res.stderr
    report = json.loads(res.stdout)
    assert report["schema"] == "wtinspect.segment_report"
    assert [r["file"] for r in report["images"]] == ["a.png", "b.jpg"]
    assert report["n_failed"] == 0
    for stem in ("a", "b"):
        for sub in ("background_removed", "overlay"):
            img = cv2.imread(str(out / sub / f"{stem}.png"))
            assert img is not None and img.shape == (120, 160, 3)
        assert (out / "instances" / f"{stem}.json").is_file()
    items = read_instances(out / "instances.json")
    assert [img["file_name"] for img, _ in items] == ["a.png", "b.jpg"]
    for (img, inst), stem in zip(items, ("a", "b")):
        # the class map: one channel, each pixel the class of the instances file's masks
        cmap = cv2.imread(str(out / "classes" / f"{stem}.png"), cv2.IMREAD_UNCHANGED)
        assert cmap.shape == (120, 160) and cmap.dtype == np.uint8
        assert np.array_equal(cmap, inst.class_map())
        assert ((cmap > 0) == inst.union()).all()
    doc = json.loads((out / "instances.json").read_text())
    for a in doc["annotations"]:
        assert isinstance(a["segmentation"]["counts"], list) and "score" in a and len(a["bbox"]) == 4
    assert not list(out.rglob(".*"))  # no temporary files left behind


def test_segment_no_flip_is_recorded(cli, photo_folder, random_weights, tmp_path):
    runs = {}
    for flag in ("--flip", "--no-flip"):
        out = tmp_path / flag.strip("-")
        res = cli("segment", photo_folder, "--out", out, "--model", random_weights, "--json",
                  "--score-threshold", "0.0", flag)
        assert res.exit_code == 0, res.stderr
        settings = json.loads(res.stdout)["settings"]
        assert settings["flip"] is (flag == "--flip") and settings["wide"] is True
        runs[flag] = json.loads((out / "instances.json").read_text())["annotations"]
    a, b = runs["--flip"], runs["--no-flip"]
    assert a and b and [(x["bbox"], x["score"]) for x in a] != [(x["bbox"], x["score"]) for x in b]


def test_segment_recursive(cli, photo_folder, random_weights, tmp_path):
    res = cli("segment", photo_folder, "-r", "--out", tmp_path / "seg", "--model", random_weights)
    assert res.exit_code == 0, res.stderr
    assert (tmp_path / "seg" / "overlay" / "sub" / "c.png").is_file()


def test_segment_bad_file_in_folder_exits_9_and_goes_on(cli, photo_folder, random_weights, tmp_path):
    (photo_folder / "broken.jpg").write_bytes(b"\xff\xd8\xff garbage")
    out = tmp_path / "seg"
    res = cli("segment", photo_folder, "--out", out, "--model", random_weights, "--json")
    assert res.exit_code == ExitCode.PARTIAL
    report = json.loads(res.stdout)
    status = {r["file"]: r["status"] for r in report["images"]}
    assert status == {"a.png": "ok", "b.jpg": "ok", "broken.jpg": "error"}
    assert "broken.jpg" in next(r["error"] for r in report["images"] if r["status"] == "error")
    assert len(read_instances(out / "instances.json")) == 2
    assert "1 of 3 images failed" in res.stderr
    # Not on a terminal (a log): a progress line per tenth of the batch, here one per file.
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("segment: ")]
    assert [ln.split(" (")[0] for ln in lines] == ["segment: 1/3", "segment: 2/3", "segment: 3/3"]
    assert "broken.jpg error" in lines[2] and "s each" in lines[2]


def test_segment_single_bad_inputs(cli, tmp_path, random_weights):
    (tmp_path / "x.txt").write_text("hello")
    (tmp_path / "bad.png").write_bytes(b"\x89PNG nope")
    (tmp_path / "empty").mkdir()
    for target in ("x.txt", "bad.png", "empty", "does-not-exist"):
        res = cli("segment", tmp_path / target, "--out", tmp_path / "o", "--model", random_weights)
        assert res.exit_code == ExitCode.INPUT, (target, res.stderr)
        assert target in res.stderr


def test_segment_resume_skips_finished(cli, photo_folder, random_weights, tmp_path):
    out = tmp_path / "seg"
    assert cli("segment", photo_folder, "--out", out, "--model", random_weights).exit_code == 0
    done = out / "instances" / "a.json"
    before = done.stat().st_mtime_ns
    (out / "overlay" / "b.png").unlink()  # b is unfinished: redone
    res = cli("segment", photo_folder, "--out", out, "--model", random_weights, "--resume", "--json")
    assert res.exit_code == 0
    status = {r["file"]: r["status"] for r in json.loads(res.stdout)["images"]}
    assert status == {"a.png": "skipped", "b.jpg": "ok"}
    assert done.stat().st_mtime_ns == before
    assert len(read_instances(out / "instances.json")) == 2


def _found(labels, scores=None):
    m = np.zeros((len(labels), 8, 8), bool)
    return batch.found_in(Instances(np.array(labels, dtype=object), m, scores))


@pytest.mark.parametrize("labels, want", [
    (["blade", "blade", "blade", "tower", "nacelle"], "rotor"),
    (["blade", "blade"], "rotor"),                     # a rotor seen without its hub
    (["blade", "nacelle"], "rotor"),                   # one blade on its nacelle
    (["blade"], "single_blade"),                       # a close-up
    (["blade", "tower"], "single_blade"),
    (["tower"], "tower_only"),
    (["nacelle", "tower"], "tower_only"),
    (["nacelle"], "tower_only"),
    ([], "nothing"),
])
def test_found_in_names_what_a_photo_holds(labels, want):
    assert _found(labels) == want


def test_found_in_counts_only_instances_at_the_score_threshold():
    assert _found(["blade", "blade", "nacelle"], [0.9, 0.3, 0.4]) == "single_blade"
    assert _found(["tower"], [0.49]) == "nothing"
    m = np.zeros((2, 8, 8), bool)
    low = Instances(np.array(["blade", "blade"], dtype=object), m, np.array([0.9, 0.3]))
    assert batch.found_in(low, score_threshold=0.2) == "rotor"


def test_one_blade_close_up_is_a_result(cli, tmp_path, random_weights, monkeypatch):
    """A photo with one blade and no hub is ok: instances, I_t and overlay written; the batch
    counts photos by what was found."""
    folder = tmp_path / "photos"
    folder.mkdir()
    for name in ("close.png", "empty.png", "rotor.png"):
        cv2.imwrite(str(folder / name), _image(seed=4))

    def fake(img, net, score_threshold, *args, **kwargs):
        h, w = img.shape[:2]
        m = np.zeros((1, h, w), bool)
        m[0, 10:110, 60:90] = True  # a blade filling the frame top to bottom
        blade = Instances(np.array(["blade"], dtype=object), m, np.array([0.9]))
        name = fake.names.pop(0)
        if name == "empty.png":
            return Instances.empty(h, w)
        if name == "rotor.png":
            m2 = np.zeros((2, h, w), bool)
            m2[0, 5:60, 70:80] = m2[1, 60:70, 80:150] = True
            return Instances(np.array(["blade", "blade"], dtype=object), m2, np.array([0.8, 0.7]))
        return blade
    fake.names = ["close.png", "empty.png", "rotor.png"]
    monkeypatch.setattr(infer, "segment_image", fake)
    out = tmp_path / "seg"
    res = cli("segment", folder, "--out", out, "--model", random_weights, "--no-refine", "--json")
    assert res.exit_code == 0, res.stderr
    report = json.loads(res.stdout)
    close = next(r for r in report["images"] if r["file"] == "close.png")
    assert close["status"] == "ok" and close["error"] is None and close["found"] == "single_blade"
    assert close["counts"] == {"blade": 1, "tower": 0, "nacelle": 0}
    assert report["n_found"] == {"rotor": 1, "single_blade": 1, "tower_only": 0, "nothing": 1}
    assert json.loads((out / "report.json").read_text())["n_found"] == report["n_found"]
    (_, inst), = read_instances(out / "instances" / "close.json")
    assert list(inst.labels) == ["blade"]
    it = cv2.imread(str(out / "background_removed" / "close.png"))
    assert it[:, :60].max() == 0 and it[10:110, 60:90].max() > 0  # I_t: the blade alone
    assert cv2.imread(str(out / "overlay" / "close.png")).shape == (120, 160, 3)
    assert "found: 1 rotor, 1 single blade, 0 tower only, 1 nothing" in res.stderr


def test_segment_image_api_uses_given_model(random_model):
    inst = infer.segment_image(_image(), model=random_model, score_threshold=0.0)
    assert inst.image_size == (120, 160)


# ---- metrics -------------------------------------------------------------------------------------
def test_evaluator_perfect_and_empty():
    m = np.zeros((2, 20, 20), bool)
    m[0, 2:8, 2:18] = True
    m[1, 10:19, 8:12] = True
    truth = Instances(np.array(["blade", "tower"], dtype=object), m)
    ev = Evaluator()
    ev.add(truth, truth)
    s = ev.summary()
    assert s["blade_mask_iou"] == 1.0 and s["tower_ap50"] == 1.0 and s["nacelle_ap50"] is None
    ev2 = Evaluator()
    ev2.add(Instances.empty(20, 20), truth)
    assert ev2.summary()["blade_mask_iou"] == 0.0 and ev2.summary()["blade_ap50"] == 0.0
    assert mask_iou(m[0], m[0]) == 1.0
    assert average_precision([0.9, 0.8], [True, False], 1) == 1.0
    assert average_precision([0.9, 0.8], [False, True], 1) == 0.5


def test_pitch_on_a_photo_segments_it_first(cli, tmp_path, random_weights, monkeypatch):
    """`wtinspect pitch PHOTO.jpg` runs segment -> contours -> pitch (shipped model, or
    WTINSPECT_MODEL); with random weights the rotor may not be found, but it must not crash."""
    from wtcli.pitch.inputs import PHOTO_SUFFIXES

    if ".jpg" not in PHOTO_SUFFIXES:
        pytest.skip("pitch does not take photos")
    monkeypatch.setenv("WTINSPECT_MODEL", str(random_weights))
    cv2.imwrite(str(tmp_path / "photo.jpg"), _image())
    res = cli("pitch", tmp_path / "photo.jpg")
    assert res.exit_code in (0, ExitCode.PERCEPTION), res.stderr
    assert "unexpected" not in res.stderr and "segment` on it first" not in res.stderr


def test_pitch_on_photos_records_an_unreadable_one_and_goes_on(cli, tmp_path, random_weights,
                                                               monkeypatch):
    monkeypatch.setenv("WTINSPECT_MODEL", str(random_weights))
    cv2.imwrite(str(tmp_path / "photo.jpg"), _image())
    (tmp_path / "bad.jpg").write_text("not a photo")
    res = cli("pitch", tmp_path / "photo.jpg", tmp_path / "bad.jpg", "--out", tmp_path / "p.json")
    assert res.exit_code == ExitCode.PARTIAL, res.stderr
    images = json.loads((tmp_path / "p.json").read_text())["images"]
    assert [im["image"]["file_name"] for im in images] == ["photo.jpg", "bad.jpg"]
    assert "bad.jpg: not a readable image" in images[1]["error"]


def _bar(h: int, w: int, angle: float, width: float, length: float) -> np.ndarray:
    m = np.zeros((h, w), np.uint8)
    pts = cv2.boxPoints(((w / 2 + 13.3, h / 2 - 7.7), (length, width), angle))
    cv2.fillPoly(m, [np.round(pts * 16).astype(np.int32)], 1, shift=4)
    return m.astype(bool)


def _training_target(mask: np.ndarray, m: int = 28) -> tuple[np.ndarray, np.ndarray]:
    """What the mask head learns for a perfect box: torchvision's own target projection."""
    from torchvision.models.detection.roi_heads import project_masks_on_boxes

    box = torch.tensor(infer_box(mask)[None], dtype=torch.float32)
    soft = project_masks_on_boxes(torch.from_numpy(mask[None].astype(np.uint8)), box, torch.tensor([0]), m)
    return soft[0].numpy(), box[0].numpy()


def infer_box(mask: np.ndarray) -> np.ndarray:
    from wtcli.masks import mask_box

    return mask_box(mask)


@pytest.mark.parametrize("angle", [0, 90, 20])
def test_paste_mask_puts_a_thin_blade_back_where_it_was(angle):
    from torchvision.models.detection.roi_heads import paste_masks_in_image

    truth = _bar(480, 640, angle, 6, 160)
    soft, box = _training_target(truth)
    ours = np.zeros_like(truth)
    infer.paste_mask(ours, soft, box, 1.0, 1.0, offset=0.5)
    theirs = paste_masks_in_image(torch.from_numpy(soft)[None, None], torch.from_numpy(box)[None],
                                  (480, 640))[0, 0].numpy() >= 0.5
    assert mask_iou(ours, truth) >= 0.8
    assert mask_iou(ours, truth) >= mask_iou(theirs, truth) + 0.05  # why we paste ourselves
    # An offset on the wrong side moves the blade off itself.
    shifted = np.zeros_like(truth)
    infer.paste_mask(shifted, soft, box, 1.0, 1.0, offset=-1.5)
    assert mask_iou(shifted, truth) < mask_iou(ours, truth) - 0.1


def test_each_class_mask_is_cut_at_its_own_threshold(monkeypatch):
    """A blade's soft mask is cut at MASK_THRESHOLD["blade"] (0.45), the tower's at 0.5: a
    uniform 0.47 in both boxes gives a full blade and no tower."""
    assert infer.MASK_THRESHOLD["blade"] < 0.47 < infer.MASK_THRESHOLD["tower"]
    det = {"scores": torch.tensor([0.9, 0.8]), "labels": torch.tensor([1, 2]),
           "boxes": torch.tensor([[10.0, 10.0, 40.0, 20.0], [50.0, 10.0, 60.0, 50.0]]),
           "masks": torch.full((2, 1, 28, 28), 0.47)}
    monkeypatch.setattr(infer, "_detect", lambda model, x, flip=False, size=None: (det, (64, 96)))
    inst = infer.predict(build_model(), np.zeros((64, 96, 3), np.uint8))
    assert list(inst.labels) == ["blade", "tower"]
    assert inst.masks[0].sum() >= 0.9 * 30 * 10 and inst.masks[1].sum() == 0
    out = np.zeros((64, 96), bool)
    infer.paste_mask(out, np.full((28, 28), 0.47, np.float32), [10, 10, 40, 20], 1.0, 1.0)
    assert not out.any()  # the paste's own default stays 0.5


def test_paste_mask_scales_back_to_the_full_photo():
    full = _bar(960, 1280, 90, 12, 600)
    work = cv2.resize(full.astype(np.float32), (640, 480), interpolation=cv2.INTER_AREA) >= 0.5
    soft, box = _training_target(work)
    out = np.zeros_like(full)
    infer.paste_mask(out, soft, box, 2.0, 2.0, offset=0.5)
    assert mask_iou(out, full) >= 0.9
    ys, xs = np.nonzero(out)
    ty, tx = np.nonzero(full)
    assert abs(xs.mean() - tx.mean()) < 0.6 and abs(ys.mean() - ty.mean()) < 0.6


def test_training_resize_keeps_masks_on_their_pixels():
    """Masks are resized by area with the image, not nearest (which shifts them by up to
    half a pixel, always the same way): over many bar positions the centre stays unbiased."""
    model = build_model()
    model.train()
    model.transform.min_size, model.transform.max_size = (384,), 555
    errs, nearest_errs = [], []
    for x0 in range(100, 140):
        mask = torch.zeros(1, 480, 640, dtype=torch.uint8)
        mask[0, 100:300, x0:x0 + 6] = 1
        target = {"boxes": torch.tensor([[float(x0), 100, x0 + 6.0, 300]]), "labels": torch.tensor([1]),
                  "masks": mask.clone()}
        images, targets = model.transform([torch.rand(3, 480, 640)], [target])
        assert images.tensors.shape[-2:] == (384, 512)
        true_centre = (x0 + 3.0) * 0.8
        xs = np.nonzero(targets[0]["masks"][0].numpy())[1]
        errs.append(xs.mean() + 0.5 - true_centre)
        near = torch.nn.functional.interpolate(mask[:, None].float(), size=(384, 512))[0, 0].numpy()
        nearest_errs.append(np.nonzero(near)[1].mean() + 0.5 - true_centre)
        assert targets[0]["boxes"][0, [0, 2]].tolist() == pytest.approx([x0 * 0.8, (x0 + 6) * 0.8])
    assert abs(np.mean(errs)) < 0.05 and np.max(np.abs(errs)) <= 0.5
    assert abs(np.mean(nearest_errs)) > 0.2  # what torchvision's own resize would have done


def _blade_bar(shape, x0, y0, x1, y1):
    m = np.zeros(shape, bool)
    m[y0:y1, x0:x1] = True
    return m


def test_duplicate_blade_inside_a_better_one_is_dropped():
    shape = (120, 200)
    whole = _blade_bar(shape, 10, 50, 190, 60)  # a horizontal blade
    part = _blade_bar(shape, 120, 48, 190, 62)  # its outer half again, a bit wider: 75 % inside
    other = _blade_bar(shape, 95, 0, 105, 55)  # another blade meeting it at the hub: 5/55 inside
    tower = _blade_bar(shape, 120, 50, 190, 60)  # not a blade: never a duplicate of one
    masks = np.stack([part, whole, other, tower])
    boxes = np.array([[120, 48, 190, 62], [10, 50, 190, 60], [95, 0, 105, 55], [120, 50, 190, 60]], float)
    inst = Instances(np.array(["blade", "blade", "blade", "tower"], dtype=object), masks,
                     np.array([0.7, 0.9, 0.8, 0.95]), boxes)
    out = infer.drop_duplicate_blades(inst)
    assert list(out.labels) == ["blade", "blade", "tower"]
    assert out.scores.tolist() == [0.9, 0.8, 0.95]
    # Greedy by score: the lower-scored copy goes, whichever comes first in the list; and the
    # result at a higher threshold is the same set, thresholded.
    assert infer.drop_duplicate_blades(inst[[1, 0, 2, 3]]).scores.tolist() == [0.9, 0.8, 0.95]
    hi = infer.drop_duplicate_blades(inst[inst.scores >= 0.75])
    assert hi.scores.tolist() == [s for s in out.scores.tolist() if s >= 0.75]
    # A blade less than the threshold inside another stays.
    assert len(infer.drop_duplicate_blades(inst, inside=0.8)) == 4


def test_one_region_read_as_two_classes_keeps_the_better_scored_reading():
    shape = (120, 200)
    blade = _blade_bar(shape, 90, 0, 110, 120)  # a blade close-up across the frame
    tower_copy = _blade_bar(shape, 88, 5, 110, 120)  # the same region read as a tower: IoU 0.87
    tower = _blade_bar(shape, 20, 40, 36, 120)  # another turbine's tower beside it
    over = _blade_bar(shape, 22, 40, 34, 70)  # a blade over that tower: IoU 0.28, not the same
    nacelle = _blade_bar(shape, 85, 0, 115, 12)  # a nacelle where the blade starts: IoU 0.1
    masks = np.stack([tower_copy, blade, tower, over, nacelle])
    inst = Instances(np.array(["tower", "blade", "tower", "blade", "nacelle"], dtype=object), masks,
                     np.array([0.77, 0.89, 0.95, 0.6, 0.7]))
    out = post.drop_duplicates(inst)
    assert list(out.labels) == ["blade", "tower", "blade", "nacelle"]
    assert out.scores.tolist() == [0.89, 0.95, 0.6, 0.7]
    # the better-scored reading wins whichever class it is, and whatever the order
    flipped = Instances(inst.labels, masks, np.array([0.95, 0.89, 0.95, 0.6, 0.7]))
    assert list(post.drop_duplicates(flipped[[4, 3, 2, 1, 0]]).labels) == ["nacelle", "blade", "tower", "tower"]
    # greedy by score: the result at a higher threshold is this one, thresholded
    hi = post.drop_duplicates(inst[inst.scores >= 0.75])
    assert hi.scores.tolist() == [s for s in out.scores.tolist() if s >= 0.75]
    # under the IoU asked for, both readings stay
    assert len(post.drop_duplicates(inst, same=0.9)) == 5


def _rect(h, w, x0, x1, y0, y1):
    m = np.zeros((h, w), bool)
    m[y0:y1, x0:x1] = True
    return m


def _parts(*parts):
    """Instances of (label, mask) pairs, every one scoring 0.9."""
    return Instances(np.array([p[0] for p in parts], object), np.array([p[1] for p in parts]),
                     np.array([0.9] * len(parts)))


def test_a_lone_blades_end_read_as_a_nacelle_joins_the_blade():
    """A "nacelle" on a lone blade's axis beyond its end, no wider than it and on no tower, is
    the blade's tip (tip close-ups); one beside the blade, wider than it, on a tower or where
    two blades meet stays a nacelle, and so does one scoring under the threshold."""
    from wtcli.segment.post import absorb_blade_ends

    h, w = 120, 200
    blade = _rect(h, w, 0, 150, 50, 70)  # a blade from the frame's left edge, 20 px wide
    tip = _rect(h, w, 145, 172, 49, 71)

    out = absorb_blade_ends(_parts(("blade", blade), ("nacelle", tip)), 0.5)
    assert list(out.labels) == ["blade"] and out.masks[0].sum() == (blade | tip).sum()
    doubtful = _parts(("blade", blade), ("nacelle", tip))
    doubtful = Instances(doubtful.labels, doubtful.masks, np.array([0.9, 0.4]))
    assert list(absorb_blade_ends(doubtful, 0.5).labels) == ["blade", "nacelle"]
    assert out.boxes[0].tolist() == [0, 49, 172, 71]
    kept = [
        _parts(("blade", blade), ("nacelle", tip), ("tower", _rect(h, w, 150, 170, 71, 120))),
        _parts(("blade", blade), ("nacelle", _rect(h, w, 145, 190, 35, 85))),  # wider than the blade
        _parts(("blade", blade), ("nacelle", _rect(h, w, 100, 140, 70, 90))),  # beside it
        _parts(("blade", blade), ("nacelle", tip), ("blade", _rect(h, w, 165, 175, 0, 50))),
        _parts(("blade", _rect(h, w, 30, 180, 50, 70)), ("nacelle", _rect(h, w, 0, 35, 49, 71))),  # cut
        # within a mask's few pixels of error (0.5 % of the longer side, here 2 px) of the edge
        _parts(("blade", _rect(h, w, 0, 180, 50, 70)), ("nacelle", _rect(h, w, 175, 199, 49, 71))),
    ]
    for case in kept:
        assert list(absorb_blade_ends(case, 0.5).labels) == list(case.labels)


def test_a_lone_blades_end_read_as_a_short_tower_joins_the_blade():
    """A "tower" across a lone blade's end (a tip's bright rim), no longer along the blade than
    across it, is the blade's end; a tower running on in line with a blade (a blade pointing up
    from the hub, its tower below) and one under a nacelle stay towers."""
    from wtcli.segment.post import absorb_blade_ends

    h, w = 120, 300
    blade = _rect(h, w, 0, 150, 50, 70)

    rim = _rect(h, w, 149, 157, 48, 72)
    out = absorb_blade_ends(_parts(("blade", blade), ("tower", rim)), 0.5)
    assert list(out.labels) == ["blade"] and out.masks[0].sum() == (blade | rim).sum()
    kept = [
        _parts(("blade", blade), ("tower", _rect(h, w, 150, 260, 48, 72))),  # in line, long
        _parts(("blade", blade), ("tower", rim), ("nacelle", _rect(h, w, 157, 190, 45, 75))),
        _parts(("blade", blade), ("tower", _rect(h, w, 149, 157, 48, 72)),
             ("blade", _rect(h, w, 150, 160, 0, 49))),  # where two blades meet
    ]
    for case in kept:
        assert list(absorb_blade_ends(case, 0.5).labels) == list(case.labels)


def test_a_blades_end_read_apart_from_a_blade_that_stops_short_joins_it_with_the_gap():
    """The network's blade can stop short of the tip it read as a nacelle: a piece in line
    beyond the blade's end by at most the blade's width joins it, the gap with it; farther off,
    or beyond a blade's end where another blade also ends, it stays what it was read as."""
    from wtcli.segment.post import absorb_blade_ends

    h, w = 120, 300
    blade = _rect(h, w, 0, 150, 50, 70)  # 20 px wide

    out = absorb_blade_ends(_parts(("blade", blade), ("nacelle", _rect(h, w, 165, 190, 50, 70))), 0.5)
    assert list(out.labels) == ["blade"]
    assert out.masks[0][50:70, 0:190].all() and out.masks[0].sum() == 190 * 20
    assert out.boxes[0].tolist() == [0, 50, 190, 70]
    kept = [
        _parts(("blade", blade), ("nacelle", _rect(h, w, 175, 200, 50, 70))),  # 25 px beyond
        _parts(("blade", blade), ("nacelle", _rect(h, w, 165, 190, 80, 100))),  # not in line
        _parts(("blade", blade), ("nacelle", _rect(h, w, 165, 190, 50, 70)),
             ("blade", _rect(h, w, 165, 190, 75, 119))),  # a second blade, ending by it too
    ]
    for case in kept:
        assert list(absorb_blade_ends(case, 0.5).labels) == list(case.labels)


def test_the_wide_look_adds_a_blade_too_big_for_the_first_look_and_drops_its_pieces():
    """A wide-look blade spanning most of the frame joins, and the first look's pieces of it
    (its tip read as a nacelle, an edge as a tower, a weaker copy of it) go; it does not join
    where the first look has it surer, or split it into surer blades (two meeting at a hub),
    nor when it is small (the first look sees those as well) or doubtful."""
    from wtcli.segment.model import TRAIN_MAX_SIZE, TRAIN_MIN_SIZES
    from wtcli.segment.post import WIDE_SIZE, wide_look

    assert WIDE_SIZE == (TRAIN_MIN_SIZES[0], TRAIN_MAX_SIZE)  # the smallest size it trained at
    h, w = 120, 200
    big = _rect(h, w, 0, 180, 20, 100)

    def inst(*parts):
        return Instances(np.array([p[0] for p in parts], object), np.array([p[1] for p in parts]),
                         np.array([p[2] for p in parts], float))

    def looked(first, wide):
        asked = []

        def look(img, thr, ms, fl):
            asked.append(img.shape)
            return wide

        out = wide_look(look, np.zeros((h, w, 3), np.uint8), first, 0.2, sure=0.5)
        assert asked == [(h, w, 3)]
        return sorted((lab, round(float(sc), 2)) for lab, sc in zip(out.labels, out.scores))

    pieces = inst(("nacelle", _rect(h, w, 150, 180, 30, 90), 0.8),
                  ("tower", _rect(h, w, 0, 10, 20, 100), 0.6),
                  ("blade", _rect(h, w, 0, 120, 20, 100), 0.45),
                  ("tower", _rect(h, w, 185, 195, 0, 120), 0.9))  # beside it: stays
    assert looked(pieces, inst(("blade", big, 0.95))) == [("blade", 0.95), ("tower", 0.9)]
    surer_same = inst(("blade", _rect(h, w, 0, 170, 22, 98), 0.97))
    assert looked(surer_same, inst(("blade", big, 0.95))) == [("blade", 0.97)]
    two = inst(("blade", _rect(h, w, 0, 90, 20, 100), 0.99), ("blade", _rect(h, w, 90, 180, 20, 100), 0.98))
    assert looked(two, inst(("blade", big, 0.9))) == [("blade", 0.98), ("blade", 0.99)]
    two = inst(("blade", _rect(h, w, 0, 90, 20, 100), 0.7), ("blade", _rect(h, w, 90, 180, 20, 100), 0.6))
    assert looked(two, inst(("blade", big, 0.9))) == [("blade", 0.6), ("blade", 0.7)]  # they cover it
    small = inst(("blade", _rect(h, w, 0, 100, 20, 60), 0.99))
    assert looked(pieces, small) == looked(pieces, inst(("blade", big, 0.4))) == sorted(
        (lab, round(float(sc), 2)) for lab, sc in zip(pieces.labels, pieces.scores))


def test_segment_image_keeps_low_score_blades_as_completion_candidates(monkeypatch):
    """segment_image returns what scores >= the threshold plus blades down to the candidate
    floor (for pitch's rotor completion); low-score towers and nacelles are not kept."""
    h, w = 40, 50
    masks = np.zeros((5, h, w), bool)
    for i in range(5):
        masks[i, 5 * i:5 * i + 4, 5:30] = True
    every = Instances(np.array(["blade", "blade", "tower", "blade", "nacelle"], object), masks,
                      np.array([0.9, 0.3, 0.3, 0.1, 0.6]))
    asked = []

    def fake_predict(model, image, score_threshold=0.5, max_size=None, flip=True, size=None):
        asked.append((score_threshold, size))
        return every[every.scores >= score_threshold]

    monkeypatch.setattr(infer, "predict", fake_predict)
    img = np.zeros((h, w, 3), np.uint8)
    inst = infer.segment_image(img, model=object())
    assert asked == [(0.2, None), (0.2, infer.WIDE_SIZE)]  # the first look, then the wide look
    assert list(inst.scores) == [0.9, 0.3, 0.6]
    assert list(inst.labels) == ["blade", "blade", "nacelle"]
    plain = infer.segment_image(img, model=object(), candidate_floor=None, wide=False)
    assert asked[-1] == (0.5, None) and list(plain.scores) == [0.9, 0.6]


def _png_header_only(w: int, h: int) -> bytes:
    """A PNG whose header declares w x h pixels (a decompression bomb's shape), tiny on disk."""
    import struct
    import zlib

    def chunk(t: bytes, d: bytes) -> bytes:
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\x00" * 301)) + chunk(b"IEND", b""))


def test_segment_folder_with_corrupt_non_image_and_huge_files(cli, photo_folder, random_weights, tmp_path):
    """The done-when case: a corrupt JPEG, a text file named like an image, a drone-size photo
    (5472 x 3648, processed downscaled, outputs at full size) and a header declaring 100 000^2
    pixels. The readable ones finish, the three bad ones are reported each on one clear line."""
    (photo_folder / "broken.jpg").write_bytes(b"\xff\xd8\xff garbage")
    (photo_folder / "notes.png").write_text("meeting notes, not a photo")
    (photo_folder / "bomb.png").write_bytes(_png_header_only(100_000, 100_000))
    big = cv2.resize(_image(seed=4), (5472, 3648), interpolation=cv2.INTER_NEAREST)
    cv2.imwrite(str(photo_folder / "drone.jpg"), big)
    out = tmp_path / "seg"
    res = cli("segment", photo_folder, "--out", out, "--model", random_weights, "--json")
    assert res.exit_code == ExitCode.PARTIAL
    report = {r["file"]: r for r in json.loads(res.stdout)["images"]}
    assert {f: r["status"] for f, r in report.items()} == {
        "a.png": "ok", "b.jpg": "ok", "drone.jpg": "ok",
        "broken.jpg": "error", "notes.png": "error", "bomb.png": "error"}
    assert "not a readable image" in report["broken.jpg"]["error"]
    assert "not a readable image" in report["notes.png"]["error"]
    assert "too large to decode" in report["bomb.png"]["error"]
    for r in report.values():
        assert r["error"] is None or "\n" not in r["error"]
    assert (report["drone.jpg"]["width"], report["drone.jpg"]["height"]) == (5472, 3648)
    assert cv2.imread(str(out / "overlay" / "drone.png")).shape == (3648, 5472, 3)
    assert "3 of 6 images failed" in res.stderr


# ---- second look at small turbines -----------------------------------------------------------
def test_turbine_groups_join_touching_boxes_only():
    boxes = np.array([[10, 10, 20, 60], [18, 5, 40, 12], [100, 100, 110, 110],
                      [41, 11, 50, 20], [300, 300, 310, 310]], float)
    groups = sorted(sorted(g.tolist()) for g in infer._turbine_groups(boxes))
    assert groups == [[0, 1, 3], [2], [4]]


def test_second_look_recrops_a_small_turbine_and_pastes_it_back(monkeypatch):
    """A distant turbine (first-pass blade and tower, 40 px in a 300 x 400 photo) is segmented
    again on a crop with the photo's aspect around it, no smaller than ZOOM_MIN_CROP; the
    crop's instances replace it, at the right place; one cut by the crop's edge and one off the
    turbine are dropped; a large turbine is left as it was."""
    H, W = 300, 400
    first = np.zeros((3, H, W), bool)
    first[0, 100:120, 200:203] = True  # a small turbine: a thin blade ...
    first[1, 120:140, 200:204] = True  # ... and its tower
    first[2, 10:290, 20:60] = True  # a large turbine's tower, left alone
    inst = Instances(np.array(["blade", "tower", "tower"], object), first, np.array([0.9, 0.8, 0.95]))
    crops = []

    def fake_predict(model, image, score_threshold=0.5, max_size=None, flip=True):
        h, w = image.shape[:2]
        crops.append((h, w))
        m = np.zeros((3, h, w), bool)
        m[0, h // 2 - 30:h // 2, w // 2 - 4:w // 2 + 4] = True  # a fuller blade
        m[1, h // 2:h - 10, w // 2 - 3:w // 2 + 3] = True  # the tower
        m[2, 0:5, 0:5] = True  # something cut by the crop's top-left edge
        m = np.concatenate([m, np.zeros((1, h, w), bool)])
        m[3, h - 9:h - 4, 3:8] = True  # whole in the crop, but off this turbine: a neighbour's
        return Instances(np.array(["blade", "tower", "blade", "nacelle"], object), m,
                         np.array([0.97, 0.9, 0.99, 0.8]))

    monkeypatch.setattr(infer, "predict", fake_predict)
    out = infer.second_look(object(), np.zeros((H, W, 3), np.uint8), inst, 0.2)
    assert len(crops) == 1
    h, w = crops[0]
    # 40 px + 2 x 0.6 x 40 = 88 px, raised to ZOOM_MIN_CROP of the frame, at the photo's aspect
    assert abs(w / h - W / H) < 0.02 and abs(h - infer.ZOOM_MIN_CROP * H) <= 1
    assert sorted(out.labels.tolist()) == ["blade", "tower", "tower"]
    assert np.array_equal(out.masks[out.scores == 0.95][0], first[2])
    blade = out.masks[out.labels == "blade"][0]
    ys, xs = np.nonzero(blade)
    assert blade.sum() == 30 * 8 and abs(xs.mean() - 201.5) < 3 and 88 <= ys.mean() <= 122
    assert out.boxes[out.labels == "blade"][0][0] == xs.min()


def test_second_look_leaves_large_turbines_alone(monkeypatch):
    def fail(*a, **k):
        raise AssertionError("no crop expected")

    monkeypatch.setattr(infer, "predict", fail)
    m = np.zeros((2, 100, 100), bool)
    m[0, 5:90, 48:52] = True
    m[1, 40:45, 10:90] = True
    inst = Instances(np.array(["tower", "blade"], object), m, np.array([0.9, 0.8]))
    assert infer.second_look(object(), np.zeros((100, 100, 3), np.uint8), inst, 0.5) is inst


def test_second_look_that_finds_nothing_keeps_the_first_pass(monkeypatch):
    monkeypatch.setattr(infer, "predict", lambda model, image, *a, **k: Instances.empty(*image.shape[:2]))
    m = np.zeros((1, 300, 400), bool)
    m[0, 100:130, 200:203] = True
    inst = Instances(np.array(["blade"], object), m, np.array([0.9]))
    assert infer.second_look(object(), np.zeros((300, 400, 3), np.uint8), inst, 0.2) is inst


# ---- precision ---------------------------------------------------------------------------------
def test_precision_choice():
    from wtcli.segment.model import resolve_precision

    cpu = torch.device("cpu")
    assert resolve_precision("fp32", cpu) == "fp32" and resolve_precision("bf16", cpu) == "bf16"
    assert resolve_precision("auto", cpu) in ("fp32", "bf16")
    assert resolve_precision(None, torch.device("cuda")) == "fp32"  # GPUs keep float32
    with pytest.raises(ModelError, match="fp16"):
        resolve_precision("fp16", cpu)


def test_bf16_backbone_segments_like_fp32():
    # The shipped network with its trunk and FPN in bfloat16 finds the same instances, with
    # nearly the same masks, on a render (dev probe, 200 front views: count and IoU unchanged).
    from wtcli.synth.render import render_sample

    s = render_sample(7_000_010, width=640, height=480, view="front")
    a = infer.load_model(None, "cpu", "fp32")
    b = infer.load_model(None, "cpu", "bf16")
    assert (a.precision, b.precision) == ("fp32", "bf16") and a is not b
    pa, pb = infer.predict(a, s.image), infer.predict(b, s.image)
    assert sorted(pa.labels) == sorted(pb.labels) and len(pa) >= 4
    for label in ("blade", "tower", "nacelle"):
        assert mask_iou(pa.of(label).union(), pb.of(label).union()) > 0.97
    assert mask_iou(pa.of("blade").union(), s.instances.of("blade").union()) > 0.6


def test_bf16_covers_the_backbone_only():
    # Convolutions of the trunk compute in bfloat16; the heads get float32 features (bf16 box
    # coordinates made degenerate proposals); switching it off restores plain float32.
    from wtcli.segment.model import backbone_in_bf16

    m = build_model().eval()
    seen = []
    m.backbone.body.conv1.register_forward_hook(lambda mod, i, o: seen.append(o.dtype))
    x = torch.rand(1, 3, 64, 96)
    backbone_in_bf16(m)
    with torch.inference_mode():
        feats = m.backbone(x)
    assert seen == [torch.bfloat16] and all(v.dtype == torch.float32 for v in feats.values())
    backbone_in_bf16(m, False)
    with torch.inference_mode():
        feats = m.backbone(x)
    assert seen[-1] == torch.float32 and all(v.dtype == torch.float32 for v in feats.values())


def test_mirrored_boxes_pool_the_same_place():
    """The mask head pools with RoIAlign (aligned=False): a box and its ``mirror_boxes`` box in
    the mirrored map, the latter pooled and mirrored back, must see a thin line at the same
    cell (without the one-pixel move they are a cell apart)."""
    from torchvision.ops import roi_align

    W = 64
    feat = torch.zeros(1, 1, 40, W)
    feat[..., 27] = 1.0  # a one-pixel line in column 27
    box = torch.tensor([[14.0, 5.0, 42.0, 33.0]])  # 28 px wide: one pixel per cell
    plain = roi_align(feat, [box], 28, 1.0, 2, aligned=False)[0, 0].mean(0)
    moved = infer.mirror_boxes(box, W)
    assert moved.tolist() == [[W - 42.0 - 1, 5.0, W - 14.0 - 1, 33.0]]
    back = roi_align(feat.flip(-1), [moved], 28, 1.0, 2, aligned=False)[0, 0].mean(0).flip(0)
    assert int(plain.argmax()) == int(back.argmax())
    assert torch.allclose(plain, back, atol=1e-6)


def test_unmirrored_boxes_come_back_half_a_pixel_left():
    W = 64
    box = torch.tensor([[[W - 42.0, 5.0, W - 14.0, 33.0]]])  # (N, C, 4) as the box head decodes
    assert infer.unmirror_boxes(box, W).tolist() == [[[13.5, 5.0, 41.5, 33.0]]]


def test_flip_detects_photo_and_mirror_together(random_model):
    """``flip`` averages the class scores (and boxes) of both passes, not only the masks: the
    untrained network scores the photo and its mirror differently, so the scores change."""
    img = _image()
    a = infer.predict(random_model, img, score_threshold=0.0, flip=False)
    b = infer.predict(random_model, img, score_threshold=0.0, flip=True)
    assert len(a) and len(b)
    assert not (len(a) == len(b) and np.allclose(a.scores, b.scores))
    assert (b.boxes[:, [0, 2]] >= 0).all() and (b.boxes[:, [0, 2]] <= img.shape[1]).all()


def test_flip_gives_the_mirror_image_the_mirrored_answer():
    """Both passes together are (nearly) symmetric: the mirror image of a render gets the same
    labels and scores, and mirrored boxes and masks. A box or mask mirrored back wrongly (or a
    pass left out) breaks it; the shifts of ``mirror_boxes`` and ``unmirror_boxes`` keep it
    within a pixel. Not every edge: where an edge is ambiguous (the tower's top under the
    nacelle) the two directions may keep different proposals (the tower's box, up to 7.6 px apart
    with an earlier network), so every box but one must agree to the pixel. Instances are
    paired by mask, not by rank: two scoring within 0.001 (the nacelle and a blade tip, seen
    with an earlier network) may swap places between the two. One network reads both passes
    here: with a mirror partner the photo and its mirror are read by different networks."""
    from wtcli.synth.render import render_sample

    model = infer.load_model(None, "cpu", mirror="none")
    s = render_sample(7_000_002, width=640, height=480, view="front")
    a = infer.predict(model, s.image, 0.3)
    b = infer.predict(model, np.ascontiguousarray(s.image[:, ::-1]), 0.3)
    assert len(a) >= 4 and len(a) == len(b)
    pair = [int(np.argmax([mask_iou(a.masks[i], m[:, ::-1]) if label == a.labels[i] else -1.0
                           for label, m in zip(b.labels, b.masks)])) for i in range(len(a))]
    assert sorted(pair) == list(range(len(b)))  # one to one
    b = b[np.array(pair)]
    assert list(a.labels) == list(b.labels)
    assert np.allclose(a.scores, b.scores, atol=0.02)
    back = b.boxes.copy()
    back[:, [0, 2]] = 640 - b.boxes[:, [2, 0]]
    d = np.abs(back - a.boxes)
    assert np.median(d) < 0.5 and (d.max(axis=1) >= 1.5).sum() <= 1 and d.max() < 10
    for i in range(len(a)):
        assert mask_iou(a.masks[i], b.masks[i][:, ::-1]) > 0.93

def test_evaluator_scores_the_class_map_beside_the_classes_unions():
    from wtcli.segment.evaluate import Evaluator

    truth = np.zeros((2, 20, 30), bool)
    truth[0, 5:8, 0:12] = True  # a blade, its root hidden by the tower
    truth[1, 0:20, 12:16] = True  # the tower in front of it
    pred = truth.copy()
    pred[0, 5:8, 0:16] = True  # the network's blade runs on under the tower
    labels = np.array(["blade", "tower"], dtype=object)
    ev = Evaluator(0.5)
    ev.add(Instances(labels, pred, np.array([0.9, 0.9])), Instances(labels, truth))
    s = ev.summary()
    assert s["blade_mask_iou"] == pytest.approx(36 / 48)  # the union counts the hidden root
    assert s["blade_class_map_iou"] == 1.0 and s["tower_class_map_iou"] == 1.0
    assert s["nacelle_class_map_iou"] is None


def test_a_mirror_partner_reads_the_mirror_pass(random_weights, tmp_path):
    """``NAME.mirror.pt`` beside ``NAME.pt`` reads the mirror image: the detections change with
    it and only with the mirror pass; a partner that is the same network gives exactly the
    one-network answer; a partner whose masks sit elsewhere in their box is refused."""
    import shutil

    from wtcli.segment.model import mirror_weights

    a = tmp_path / "net.pt"
    shutil.copy(random_weights, a)
    assert mirror_weights(a) is None
    torch.manual_seed(1)
    save_weights(build_model(), tmp_path / "net.mirror.pt", meta={"note": "another draw"})
    assert mirror_weights(a) == tmp_path / "net.mirror.pt"
    assert mirror_weights(tmp_path / "net.mirror.pt") is None  # a partner has none of its own
    img = _image()

    def run(mirror, flip=True):
        m = infer.load_model(a, "cpu", mirror=mirror)
        m.roi_heads.score_thresh = 0.0
        return m, infer.predict(m, img, score_threshold=0.0, flip=flip)

    pair, with_partner = run("auto")
    alone, one_net = run("none")
    assert pair.mirror_weights == str(tmp_path / "net.mirror.pt") and alone.mirror_weights is None
    assert pair.mirror_partner is not None and alone.mirror_partner is None
    assert not (len(with_partner) == len(one_net) and np.allclose(with_partner.scores, one_net.scores))
    _, plain_a = run("auto", flip=False)
    _, plain_b = run("none", flip=False)
    assert np.array_equal(plain_a.scores, plain_b.scores)  # one pass: the model alone
    shutil.copy(random_weights, tmp_path / "same.pt")
    _, same = run(tmp_path / "same.pt")
    assert np.array_equal(same.scores, one_net.scores) and np.array_equal(same.masks, one_net.masks)
    torch.manual_seed(2)
    save_weights(build_model(), tmp_path / "off.pt", meta={"mask_offset_px": 0.25})
    with pytest.raises(ModelError, match="off.pt"):
        infer.load_model(a, "cpu", mirror=tmp_path / "off.pt")


def test_segment_records_the_mirror_model_and_refuses_a_missing_one(cli, photo_folder, random_weights,
                                                                     tmp_path):
    import shutil

    a = tmp_path / "w" / "net.pt"
    a.parent.mkdir()
    shutil.copy(random_weights, a)
    shutil.copy(random_weights, a.with_name("net.mirror.pt"))
    for extra, want in (((), str(a.with_name("net.mirror.pt"))), (("--mirror-model", "none"), None),
                        (("--no-flip",), None)):
        res = cli("segment", photo_folder, "--out", tmp_path / "o", "--model", a, "--json", *extra)
        assert res.exit_code == 0, res.stderr
        assert json.loads(res.stdout)["settings"]["mirror_model"] == want
    res = cli("segment", photo_folder, "--out", tmp_path / "o2", "--model", a,
              "--mirror-model", tmp_path / "missing.pt")
    assert res.exit_code == ExitCode.MODEL and "missing.pt" in res.stderr


# ---- a real photo folder's edges ---------------------------------------------------------------
def _fake_segment(monkeypatch):
    """segment_image replaced by one blade down the middle of any photo (no network)."""
    def fake(img, net, score_threshold, *args, **kwargs):
        h, w = img.shape[:2]
        m = np.zeros((1, h, w), bool)
        m[:, :, w // 2 - 2:w // 2 + 2] = True
        return Instances(np.array(["blade"], dtype=object), m, np.array([0.9]))
    monkeypatch.setattr(infer, "segment_image", fake)


def test_photos_segment_does_not_read_are_said_not_silently_left_out(cli, random_weights,
                                                                    tmp_path, monkeypatch):
    """A drone's folder: a .DNG beside each .JPG, a phone's .HEIC. The JPEGs are segmented, the
    rest counted on stderr and in report.json; a folder of raw files alone, or one given by
    name, is refused (exit 3) saying what to do."""
    _fake_segment(monkeypatch)
    folder = tmp_path / "DCIM"
    (folder / "sub").mkdir(parents=True)
    cv2.imwrite(str(folder / "DJI_0001.JPG"), _image())
    for name in ("DJI_0001.DNG", "DJI_0002.DNG", "IMG_7.HEIC", ".hidden.dng", "flight.SRT",
                 "sub/DJI_0003.DNG"):
        (folder / name).write_bytes(b"\0" * 64)
    out = tmp_path / "seg"
    res = cli("segment", folder, "--out", out, "--model", random_weights, "--no-refine")
    assert res.exit_code == 0, res.stderr[-800:]
    assert (f"note: 3 photo(s) in {folder} not read: 2 .DNG (raw), 1 .HEIC (HEIF) — use the "
            "JPEG the camera saved beside each raw file, or convert them to .jpg") in res.stderr
    report = json.loads((out / "report.json").read_text())
    assert report["not_read"] == {".DNG": 2, ".HEIC": 1} and report["n_images"] == 1
    res = cli("segment", folder, "--out", tmp_path / "seg-r", "--recursive", "--model",
              random_weights, "--no-refine")
    assert json.loads((tmp_path / "seg-r" / "report.json").read_text())["not_read"] == {
        ".DNG": 3, ".HEIC": 1}
    (folder / "DJI_0001.JPG").unlink()
    res = cli("segment", folder, "--out", tmp_path / "seg2", "--model", random_weights)
    assert res.exit_code == ExitCode.INPUT
    assert res.stderr.strip().endswith("it holds photos segment does not read: 2 .DNG (raw), "
                                       "1 .HEIC (HEIF) — use the JPEG the camera saved beside "
                                       "each raw file, or convert them to .jpg, .jpeg, .png, "
                                       ".tif, .tiff")
    for name, kind in (("DJI_0001.DNG", "raw"), ("IMG_7.HEIC", "HEIF")):
        res = cli("segment", folder / name, "--out", tmp_path / "seg3", "--model", random_weights)
        assert res.exit_code == ExitCode.INPUT
        assert f"{folder / name}: a {kind} photo, which wtinspect does not read;" in res.stderr


def test_a_batch_holds_one_photos_masks_at_a_time(tmp_path, monkeypatch):
    """instances.json is made from the photos' own files at the end: the masks of the photos
    done are not held (they took ~70 MB a 12 MP photo: a folder of 500 ran out of memory)."""
    import tracemalloc

    def big(img):
        h, w = img.shape[:2]
        m = np.zeros((6, h, w), bool)
        for k in range(6):
            m[k, :, 40 * k:40 * k + 20] = True
        return Instances(np.array(["blade"] * 6, dtype=object), m, np.full(6, 0.9))

    peaks = {}
    for n in (2, 8):
        folder = tmp_path / f"p{n}"
        folder.mkdir()
        for i in range(n):
            cv2.imwrite(str(folder / f"{i}.png"), np.full((1000, 1000, 3), 90, np.uint8))
        tracemalloc.start()
        b = batch.segment_paths(folder, tmp_path / f"out{n}", big)
        batch.write_batch_files(tmp_path / f"out{n}", b.results,
                                batch.batch_report(tmp_path / f"out{n}", b.results, {}))
        peaks[n] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert [img["file_name"] for img, _ in read_instances(tmp_path / f"out{n}" / "instances.json")] \
            == [f"{i}.png" for i in range(n)]
    assert peaks[8] - peaks[2] < 6e6, peaks  # six more photos' masks would be 36 MB


def _png_folder(folder: Path, n: int, name: str = "{}.png") -> Path:
    """``n`` small test photos named ``name.format(i)``."""
    folder.mkdir()
    for i in range(n):
        cv2.imwrite(str(folder / name.format(i)), _image(seed=i))
    return folder


def test_a_photos_instances_file_gone_before_the_end_is_said(tmp_path, monkeypatch):
    _fake_segment(monkeypatch)
    folder = _png_folder(tmp_path / "p", 2)
    out = tmp_path / "out"
    b = batch.segment_paths(folder, out, lambda img: infer.segment_image(img, None, 0.5))
    (out / "instances" / "1.json").unlink()
    with pytest.raises(InputError, match=r"instances\.json: not written: 1\.png's instances file "
                                         r"could not be read back \(.*1\.json: file not found\)"):
        batch.write_batch_files(out, b.results, batch.batch_report(out, b.results, {}))
    assert json.loads((out / "report.json").read_text())["n_images"] == 2  # the report still out
    assert not (out / "instances.json").exists() and not list(out.glob(".instances.json*"))


def test_a_large_batch_says_where_every_photo_is(cli, random_weights, tmp_path, monkeypatch):
    """Over 40 photos the summary lists the failed ones only; with none failed it prints no
    empty table but where every photo's row is."""
    _fake_segment(monkeypatch)
    folder = _png_folder(tmp_path / "p", 41, "{:02d}.png")
    out = tmp_path / "seg"
    res = cli("segment", folder, "--out", out, "--model", random_weights, "--no-refine")
    assert res.exit_code == 0, res.stderr[-800:]
    assert f"41 photos: every photo in {out / 'report.json'}" in res.stderr
    assert "┃ file" not in res.stderr and "| file" not in res.stderr
    (folder / "07.png").write_bytes(b"not a photo")
    res = cli("segment", folder, "--out", out, "--model", random_weights, "--no-refine")
    assert res.exit_code == ExitCode.PARTIAL
    said = " ".join(res.stderr.split())  # the table's caption is folded to the terminal's width
    assert "41 photos: the failed shown, every photo in" in said and "07.png" in said


def test_output_names_keep_apart_photos_that_would_share_one():
    names = batch.output_names(["dup.jpg", "dup.png", "a.jpg", "s/x.jpg", "t/x.jpg",
                                "IMG_1.jpg", "IMG_1.JPG", "b.JPG"])
    assert names == {"dup.jpg": "dup.jpg", "dup.png": "dup.png", "a.jpg": "a",
                     "s/x.jpg": "s/x", "t/x.jpg": "t/x", "IMG_1.JPG": "IMG_1.JPG",
                     "IMG_1.jpg": "IMG_1.jpg~2", "b.JPG": "b"}
    assert len({n.casefold() for n in names.values()}) == len(names)  # apart on any disk


def test_photos_sharing_a_name_keep_their_own_results_and_resume(cli, tmp_path, random_weights,
                                                                  monkeypatch):
    folder = tmp_path / "photos"
    folder.mkdir()
    cv2.imwrite(str(folder / "dup.jpg"), _image(seed=1))
    cv2.imwrite(str(folder / "dup.png"), _image(60, 80, seed=2))
    _fake_segment(monkeypatch)
    out = tmp_path / "seg"
    for resume in ((), ("--resume",)):
        res = cli("segment", folder, "--out", out, "--model", random_weights, "--no-refine",
                  "--json", *resume)
        assert res.exit_code == 0, res.stderr
        rows = {r["file"]: r for r in json.loads(res.stdout)["images"]}
        assert {f: r["status"] for f, r in rows.items()} == \
            {"dup.jpg": "skipped" if resume else "ok", "dup.png": "skipped" if resume else "ok"}
        assert rows["dup.jpg"]["outputs"]["overlay"] != rows["dup.png"]["outputs"]["overlay"]
        sizes = {img["file_name"]: (img["width"], img["height"])
                 for img, _ in read_instances(out / "instances.json")}
        assert sizes == {"dup.jpg": (160, 120), "dup.png": (80, 60)}
    assert cv2.imread(str(out / "overlay" / "dup.png.png")).shape == (60, 80, 3)
    assert cv2.imread(str(out / "overlay" / "dup.jpg.png")).shape == (120, 160, 3)


def test_resume_redoes_a_photo_replaced_under_its_name_and_refuses_other_settings(
        cli, photo_folder, random_weights, tmp_path, monkeypatch):
    _fake_segment(monkeypatch)
    out = tmp_path / "seg"
    args = ("segment", photo_folder, "--out", out, "--model", random_weights, "--no-refine")
    assert cli(*args).exit_code == 0
    cv2.imwrite(str(photo_folder / "a.png"), _image(60, 80, seed=9))  # another flight's a.png
    res = cli(*args, "--resume", "--json")
    assert res.exit_code == 0, res.stderr
    rows = {r["file"]: r for r in json.loads(res.stdout)["images"]}
    assert rows["a.png"]["status"] == "ok" and rows["a.png"]["width"] == 80
    assert rows["b.jpg"]["status"] == "skipped"
    res = cli(*args, "--resume", "--score-threshold", "0.3")
    assert res.exit_code == ExitCode.CONFIG
    assert "score_threshold 0.5" in res.stderr and "0.3" in res.stderr and "a.json" in res.stderr
    assert cli(*args, "--resume", "--no-flip").exit_code == ExitCode.CONFIG


def test_recursive_never_reads_an_output_folder_as_photos(cli, photo_folder, random_weights,
                                                          tmp_path, monkeypatch):
    _fake_segment(monkeypatch)
    for out in (photo_folder / "seg", photo_folder / "seg2"):  # a second --out in the folder too
        for _ in range(2):
            res = cli("segment", photo_folder, "-r", "--out", out, "--model", random_weights,
                      "--no-refine", "--json")
            assert res.exit_code == 0, res.stderr
            assert [r["file"] for r in json.loads(res.stdout)["images"]] == \
                ["a.png", "b.jpg", str(Path("sub") / "c.tif")]


def test_an_output_that_cannot_be_written_stops_the_batch_keeping_what_is_done(
        cli, photo_folder, random_weights, tmp_path, monkeypatch):
    from wtcli.errors import OutputError

    _fake_segment(monkeypatch)
    real = batch.atomic_write_bytes

    def full_disk(path, data):
        if "b" in Path(path).stem:
            raise OutputError(f"{path}: cannot write (no space left on device)")
        return real(path, data)
    monkeypatch.setattr(batch, "atomic_write_bytes", full_disk)
    (photo_folder / "c.png").write_bytes((photo_folder / "a.png").read_bytes())
    out = tmp_path / "seg"
    res = cli("segment", photo_folder, "--out", out, "--model", random_weights, "--no-refine")
    assert res.exit_code == ExitCode.INPUT, res.stderr
    # b.jpg, where it stopped, and c.png after it
    assert "no space left" in res.stderr and "stopped with 2 photo(s) not done" in res.stderr
    report = json.loads((out / "report.json").read_text())
    assert [(r["file"], r["status"]) for r in report["images"]] == [("a.png", "ok"), ("b.jpg", "error")]
    assert (out / "instances" / "a.json").is_file() and not (out / "instances" / "c.json").exists()


def test_a_blocked_output_subfolder_fails_before_the_model(cli, photo_folder, tmp_path):
    out = tmp_path / "seg"
    out.mkdir()
    (out / "overlay").write_text("a file where the overlays go")
    res = cli("segment", photo_folder, "--out", out, "--model", tmp_path / "missing.pt")
    assert res.exit_code == ExitCode.INPUT  # not 7: the weights were never looked at
    assert "overlay" in res.stderr


def test_a_strip_photo_is_refused_by_name_and_the_batch_goes_on(cli, photo_folder, random_weights,
                                                                tmp_path):
    cv2.imwrite(str(photo_folder / "strip.png"), np.full((9, 2000, 3), 120, np.uint8))
    res = cli("segment", photo_folder, "--out", tmp_path / "seg", "--model", random_weights,
              "--no-refine")
    assert res.exit_code == ExitCode.PARTIAL, res.stderr
    line = next(ln for ln in res.stderr.splitlines() if ln.startswith("failed: "))
    assert "strip.png: image is too narrow (2000x9)" in line
    res = cli("segment", photo_folder / "strip.png", "--out", tmp_path / "one", "--model",
              random_weights)
    assert res.exit_code == ExitCode.INPUT and "too narrow" in res.stderr


def test_a_photo_is_read_upright_as_its_exif_orientation_says(tmp_path):
    import struct

    img = _image(seed=5)  # 120 x 160
    ok, buf = cv2.imencode(".jpg", img)
    tiff = b"II*\0" + struct.pack("<IH", 8, 1) + struct.pack("<HHIHH", 0x0112, 3, 1, 6, 0) \
        + struct.pack("<I", 0)
    app1 = b"Exif\0\0" + tiff
    data = buf.tobytes()
    path = tmp_path / "turned.jpg"
    path.write_bytes(data[:2] + b"\xff\xe1" + struct.pack(">H", len(app1) + 2) + app1 + data[2:])
    got = batch.read_image(path)
    assert got.shape == (160, 120, 3)  # Orientation 6: turned a quarter clockwise to be shown
    want = cv2.rotate(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR),
                      cv2.ROTATE_90_CLOCKWISE)
    assert np.abs(got.astype(int) - want.astype(int)).max() <= 1


def test_an_interrupted_batch_sums_up_the_photos_done(cli, photo_folder, random_weights, tmp_path,
                                                      monkeypatch):
    def fake(img, net, score_threshold, *args, **kwargs):
        fake.calls += 1
        if fake.calls == 2:
            raise KeyboardInterrupt  # Ctrl-C while the second photo is under way
        h, w = img.shape[:2]
        return Instances(np.array(["blade"], dtype=object), np.ones((1, h, w), bool), np.array([0.9]))
    fake.calls = 0
    monkeypatch.setattr(infer, "segment_image", fake)
    out = tmp_path / "seg"
    res = cli("segment", photo_folder, "--out", out, "--model", random_weights, "--no-refine")
    assert res.exit_code == ExitCode.INTERRUPTED, res.stderr
    assert "1/2 image(s) done before the interrupt" in res.stderr
    report = json.loads((out / "report.json").read_text())
    assert report["interrupted"] is True and [r["file"] for r in report["images"]] == ["a.png"]
    assert [img["file_name"] for img, _ in read_instances(out / "instances.json")] == ["a.png"]
    res = cli("segment", photo_folder, "--out", out, "--model", random_weights, "--no-refine",
              "--resume", "--json")
    assert res.exit_code == 0 and json.loads(res.stdout)["interrupted"] is False


def test_sigterm_sums_up_the_photos_done_as_ctrl_c(photo_folder, random_weights, tmp_path):
    """SIGTERM (a scheduler's time limit, `timeout`, `kill`) while the second photo is under
    way: report.json and instances.json hold the first, then exit 143 (130 is Ctrl-C's)."""
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent("""
        import os, signal, sys, time
        import numpy as np
        from wtcli.masks import Instances
        from wtcli.segment import infer

        calls = []

        def fake(img, net, score_threshold, *args, **kwargs):
            calls.append(1)
            if len(calls) == 2:
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(30)
            h, w = img.shape[:2]
            return Instances(np.array(["blade"], dtype=object), np.ones((1, h, w), bool),
                             np.array([0.9]))

        infer.segment_image = fake
        from wtcli.cli import main
        main(["segment", sys.argv[1], "--out", sys.argv[2], "--model", sys.argv[3], "--no-refine"])
    """)
    out = tmp_path / "seg"
    done = subprocess.run([sys.executable, "-c", code, str(photo_folder), str(out), str(random_weights)],
                          capture_output=True, text=True, cwd=Path(__file__).resolve().parents[1],
                          timeout=300)
    assert done.returncode == 143, (done.returncode, done.stderr[-800:])
    assert "1/2 image(s) done before the interrupt; rerun with --resume" in done.stderr
    assert done.stderr.endswith("interrupted (SIGTERM)\n")
    report = json.loads((out / "report.json").read_text())
    assert report["interrupted"] is True and [r["file"] for r in report["images"]] == ["a.png"]
    assert [img["file_name"] for img, _ in read_instances(out / "instances.json")] == ["a.png"]


def test_a_name_near_the_limit_gets_outputs_cut_to_fit(cli, random_weights, tmp_path, monkeypatch):
    """A photo named close to the 255-byte limit: at 250 characters `instances/NAME.json` fits;
    at 255 it would be 256 bytes, which no disk takes, so NAME is cut to fit with a hash of the
    photo's path after it, and report.json names the files."""
    _fake_segment(monkeypatch)
    folder = tmp_path / "photos"
    folder.mkdir()
    ok, long = "p" * 246 + ".png", "q" * 251 + ".png"
    for name in (ok, long, "z.png"):
        cv2.imwrite(str(folder / name), _image(seed=len(name)))
    out = tmp_path / "seg"
    res = cli("segment", folder, "--out", out, "--model", random_weights, "--no-refine")
    assert res.exit_code == 0, res.stderr[-800:]
    report = json.loads((out / "report.json").read_text())
    rows = {r["file"]: r for r in report["images"]}
    assert {k: r["status"] for k, r in rows.items()} == {ok: "ok", long: "ok", "z.png": "ok"}
    assert (out / "instances" / ("p" * 246 + ".json")).is_file()
    for kind, path in rows[long]["outputs"].items():
        name = Path(path).name
        assert Path(path).is_file() and len(name.encode()) <= 255, (kind, name)
        assert re.fullmatch(r"q+~[0-9a-f]{8}\.(json|png)", name), name
    assert [p for p in out.rglob(".*")] == []  # no temporary left
    res = cli("segment", folder, "--out", out, "--model", random_weights, "--no-refine", "--resume")
    assert res.exit_code == 0, res.stderr[-800:]
    report = json.loads((out / "report.json").read_text())
    assert {r["file"]: r["status"] for r in report["images"]} == {
        ok: "skipped", long: "skipped", "z.png": "skipped"}


def test_a_name_the_disk_refuses_fails_that_photo_alone(cli, random_weights, tmp_path,
                                                        monkeypatch):
    """A file system with a shorter limit than the 255 bytes names are cut to (eCryptfs: 143)
    refuses a name: that photo fails (exit 9 at the end), the batch goes on."""
    import wtcli.jsonio

    _fake_segment(monkeypatch)
    monkeypatch.setattr(wtcli.jsonio, "NAME_MAX", 1000)  # as if the limit were higher than the disk's
    folder = tmp_path / "photos"
    folder.mkdir()
    too_long = "q" * 251 + ".png"
    for name in (too_long, "z.png"):
        cv2.imwrite(str(folder / name), _image(seed=len(name)))
    out = tmp_path / "seg"
    res = cli("segment", folder, "--out", out, "--model", random_weights, "--no-refine")
    assert res.exit_code == ExitCode.PARTIAL, res.stderr[-800:]
    report = json.loads((out / "report.json").read_text())
    status = {r["file"]: (r["status"], r["error"]) for r in report["images"]}
    assert status["z.png"] == ("ok", None)
    assert status[too_long][0] == "error" and "File name too long" in status[too_long][1]
    res = cli("segment", folder, "--out", out, "--model", random_weights, "--no-refine", "--resume")
    assert res.exit_code == ExitCode.PARTIAL, res.stderr[-800:]  # --resume gets past it too
    report = json.loads((out / "report.json").read_text())
    assert {r["file"]: r["status"] for r in report["images"]} == {too_long: "error", "z.png": "skipped"}
