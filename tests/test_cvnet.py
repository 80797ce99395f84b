"""The torch-free segmenter (``wtcli.segment.cvnet``): the converted file matches the shipped
weights, each torchvision step written in numpy gives torchvision's answer, the whole path gives
torch's instances on held-out renders, and `plan` from a photo runs without importing torch."""

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch
from torchvision.ops import nms as tv_nms
from torchvision.ops import roi_align as tv_roi_align

from wtcli.errors import ModelError
from wtcli.segment import cvnet

ROOT = Path(__file__).resolve().parents[1]


def test_the_converted_file_is_made_from_the_shipped_weights():
    """Retraining `models/*.pt` without running `python -m wtcli.segment.export_cv2` fails here."""
    assert cvnet.available()


def test_a_converted_file_of_other_weights_is_not_used(tmp_path):
    shutil.copy(cvnet.CONVERTED, tmp_path / cvnet.CONVERTED.name)
    for name in cvnet.SOURCES:
        shutil.copy(cvnet.MODELS_DIR / name, tmp_path / name)
    assert cvnet.available(tmp_path / cvnet.CONVERTED.name)
    with open(tmp_path / cvnet.SOURCES[0], "ab") as f:
        f.write(b"\0")  # a retrained network
    assert not cvnet.available(tmp_path / cvnet.CONVERTED.name)
    with open(tmp_path / cvnet.SOURCES[0], "wb") as f:
        f.write((cvnet.MODELS_DIR / cvnet.SOURCES[0]).read_bytes())
    assert cvnet.available(tmp_path / cvnet.CONVERTED.name)
    shutil.copy(cvnet.MODELS_DIR / cvnet.SOURCES[0], tmp_path / cvnet.MIRROR)  # a pair: torch reads it
    assert not cvnet.available(tmp_path / cvnet.CONVERTED.name)
    assert not cvnet.available(tmp_path / "missing.npz")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    assert not cvnet.available(tmp_path / "bad.npz")
    with pytest.raises(ModelError, match="bad.npz"):
        cvnet.CvModel(tmp_path / "bad.npz")


def test_engine_choice(monkeypatch):
    monkeypatch.setenv("WTINSPECT_SEGMENTER", "torch")
    assert cvnet.chosen() is False
    monkeypatch.setenv("WTINSPECT_SEGMENTER", "cv2")
    assert cvnet.chosen() is True
    monkeypatch.setenv("WTINSPECT_SEGMENTER", "tensorflow")
    with pytest.raises(ModelError, match="WTINSPECT_SEGMENTER"):
        cvnet.chosen()
    monkeypatch.setenv("WTINSPECT_SEGMENTER", "auto")
    monkeypatch.setenv("WTINSPECT_MODEL", "other.pt")
    assert cvnet.chosen() is False  # other weights than the converted ones: torch


def test_roi_align_is_torchvisions():
    rng = np.random.default_rng(0)
    feat = rng.normal(size=(1, 8, 13, 17)).astype(np.float32)
    boxes = np.array([[3.2, 4.1, 60.5, 30.7], [0, 0, 4, 4], [-10, -6, 20, 200], [100, 90, 140, 110],
                      [50.3, 20.2, 50.4, 20.3], [130, 100, 200, 120]], np.float32)
    for scale, size in ((0.125, 7), (0.25, 14)):
        ref = tv_roi_align(torch.from_numpy(feat), [torch.from_numpy(boxes)], size, scale, 2,
                           aligned=False).numpy()
        got = np.stack([cvnet.roi_align_one(feat[0], b, scale, size, 2) for b in boxes])
        np.testing.assert_allclose(got, ref, atol=1e-5)


def test_nms_is_torchvisions():
    rng = np.random.default_rng(1)
    xy = rng.uniform(0, 100, (300, 2))
    boxes = np.concatenate([xy, xy + rng.uniform(2, 40, (300, 2))], 1).astype(np.float32)
    scores = rng.uniform(0, 1, 300).astype(np.float32)
    for thr in (0.3, 0.5, 0.7):
        ref = tv_nms(torch.from_numpy(boxes), torch.from_numpy(scores), thr).numpy()
        np.testing.assert_array_equal(cvnet.nms(boxes, scores, thr), ref)


def test_anchors_are_torchvisions():
    from torchvision.models.detection.image_list import ImageList

    from wtcli.segment.infer import load_model

    gen = load_model(None, "cpu", "fp32").rpn.anchor_generator
    x = torch.zeros(1, 3, 576, 768)
    grids = [(72, 96), (36, 48), (18, 24), (9, 12)]
    ref = gen(ImageList(x, [(576, 768)]), [torch.zeros(1, 1, *g) for g in grids])[0].numpy()
    got = np.concatenate(cvnet.load().anchors((576, 768), grids))
    np.testing.assert_array_equal(got, ref)


@pytest.mark.parametrize("fast", [True, False])
def test_instances_are_torchs_on_held_out_renders(fast):
    """The same network in float32 both ways: same instances, masks nearly pixel for pixel."""
    from wtcli.segment.infer import load_model, segment_image
    from wtcli.synth.render import render_sample

    model = load_model(None, "cpu", "fp32")
    for seed in (9_000_000, 9_000_002):
        img = render_sample(seed, width=640, height=480, view="front").image
        ref = segment_image(img, model=model, flip=not fast, zoom=not fast)
        got = cvnet.segment_image(img, flip=not fast, zoom=not fast)
        assert list(got.labels) == list(ref.labels)
        np.testing.assert_allclose(got.scores, ref.scores, atol=2e-3)
        np.testing.assert_allclose(got.boxes, ref.boxes, atol=0.05)
        for a, b in zip(got.masks, ref.masks):
            assert (a & b).sum() / max((a | b).sum(), 1) > 0.98


def test_plan_from_a_photo_imports_no_torch(tmp_path):
    """`wtinspect plan turbines.yaml T1=photo.jpg`, as a user runs it: the converted network, no
    torch (its import alone is 1.1-1.6 s of the 2 s goal), and the same plan as with torch."""
    out = tmp_path / "plan.json"
    code = textwrap.dedent(f"""
        import json, sys
        from wtcli.cli import main
        try:
            main(["plan", {str(ROOT / 'sample_images' / 'turbines.yaml')!r},
                  "T1={ROOT / 'sample_images' / 'images' / '00000.jpg'}", "--out", {str(out)!r}])
        except SystemExit as e:
            code = e.code
        print(json.dumps({{"code": code, "torch": "torch" in sys.modules}}))
    """)
    env = {k: v for k, v in os.environ.items() if k not in ("WTINSPECT_MODEL", "WTINSPECT_SEGMENTER")}
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    got = json.loads(done.stdout.strip().splitlines()[-1])
    assert got == {"code": 0, "torch": False}, done.stderr[-2000:]
    assert "from sample_images/images/00000.jpg" in done.stderr or "00000.jpg" in done.stderr


def test_plan_segments_a_photo_once_by_default_and_four_times_full(cli, tmp_path, monkeypatch):
    """`plan`'s --fast (the default): one pass of the network; --full: the photo and its mirror,
    twice (the sample photo's turbine is small enough for a second look); never the wide look
    (a plan's photo shows a whole rotor)."""
    import yaml

    doc = yaml.safe_load((ROOT / "sample_images" / "turbines.yaml").read_text())
    doc["turbines"] = doc["turbines"][:1]
    site = tmp_path / "t1.yaml"
    site.write_text(yaml.safe_dump(doc))
    monkeypatch.setenv("WTINSPECT_SEGMENTER", "cv2")
    calls = []
    detect = cvnet.CvModel.detect
    monkeypatch.setattr(cvnet.CvModel, "detect",
                        lambda self, img, flip, size=None: calls.append((flip, size))
                        or detect(self, img, flip, size))
    photo = f"T1={ROOT / 'sample_images' / 'images' / '00000.jpg'}"
    azimuths = []
    for flags, want in (([], [(False, None)]), (["--full"], [(True, None), (True, None)])):
        calls.clear()
        res = cli("plan", site, photo, "--out", tmp_path / "plan.json", *flags)
        assert res.exit_code == 0, res.stderr
        assert calls == want
        line = next(x for x in res.stderr.splitlines() if "blade azimuths" in x)
        azimuths.append(sorted(float(a) for a in line.split("azimuths ")[1].split(" deg")[0].split(", ")))
    assert max(abs((a - b + 180) % 360 - 180) for a, b in zip(*azimuths)) < 0.5


def test_a_photo_of_nothing_gives_no_instances_and_bad_photos_are_refused():
    from wtcli.errors import InputError

    sky = np.full((240, 320, 3), (235, 206, 135), np.uint8)
    inst = cvnet.segment_image(sky)
    assert inst.image_size == (240, 320) and len(inst[inst.scores >= 0.5]) == 0
    m = cvnet.load()
    prob, boxes = m.heads([np.zeros((1, 128, 4, 4), np.float32)] * 4, np.zeros((0, 4), np.float32))
    assert prob.shape == (0, 4) and boxes.shape == (0, 4, 4)
    with pytest.raises(InputError, match="too small"):
        cvnet.segment_image(np.zeros((6, 6, 3), np.uint8))
    with pytest.raises(InputError, match="score threshold"):
        cvnet.segment_image(sky, score_threshold=1.5, candidate_floor=None)
