"""train: a tiny run on renders and on a COCO folder, checkpoint + resume, config errors,
augmentation keeps masks and image aligned, LR schedule."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from wtcli.errors import ConfigError, ExitCode, InputError, ModelError
from wtcli.masks import Instances, write_instances
from wtcli.segment import data as D
from wtcli.segment.model import average_weights, build_model, load_weights, save_weights
from wtcli.segment.train import (SYNTH_STRETCH, TrainConfig, _batches, _seed_all, export_checkpoint,
                                 lr_factor, train)


def _tiny(tmp_path, **kw) -> TrainConfig:
    base = dict(out=str(tmp_path / "run"), iterations=2, width=96, height=72, eval_count=1,
                workers=0, checkpoint_every=1, warmup=1)
    base.update(kw)
    return TrainConfig(**base)


def test_tiny_run_then_resume(tmp_path):
    seen = []
    s = train(_tiny(tmp_path), progress=seen.append)
    assert s["iterations"] == 2 and [r["iteration"] for r in seen] == [1, 2]
    assert all(np.isfinite(r["loss"]) for r in seen)
    run = tmp_path / "run"
    assert {"last.ckpt", "model.pt", "metrics.json"} <= {p.name for p in run.iterdir()}
    m = json.loads((run / "metrics.json").read_text())
    assert m["schema"] == "wtinspect.train_metrics" and "blade_mask_iou" in m["evaluation"]
    assert m["train_sizes_used"] == [72]  # the default sizes exceed these tiny renders: their own
    load_weights(build_model(), run / "model.pt")
    s2 = train(_tiny(tmp_path, iterations=3, resume=True, eval_count=0), progress=seen.append)
    assert s2["iterations"] == 3 and seen[-1]["iteration"] == 3
    export_checkpoint(run / "last.ckpt", tmp_path / "exported.pt")
    meta = load_weights(build_model(), tmp_path / "exported.pt")
    assert meta["iterations"] == 3


def test_bf16_run_trains_and_says_so(tmp_path):
    # bfloat16 autocast: the losses stay finite and the weights move; metrics and the weights'
    # meta record the precision (auto picks it only on CPUs that do bf16 natively).
    _seed_all(3)
    init = build_model().state_dict()  # what train() builds from the same seed
    s = train(_tiny(tmp_path, precision="bf16", eval_count=0, seed=3))
    assert s["precision"] == "bf16" and np.isfinite(s["final_loss"])
    run = tmp_path / "run"
    assert load_weights(build_model(), run / "model.pt")["precision"] == "bf16"
    after = torch.load(run / "last.ckpt", weights_only=True)["state_dict"]
    rel = [float((after[k] - v).norm() / v.norm()) for k, v in init.items()
           if v.dtype.is_floating_point and v.dim() > 1 and v.norm() > 0]
    # Two AdamW steps move every weight a little from the same initialisation, not far.
    assert 0 < float(np.median(rel)) < 0.1
    assert json.loads((run / "metrics.json").read_text())["precision"] == "bf16"


def test_resume_without_checkpoint_is_input_error(tmp_path):
    with pytest.raises(InputError, match="last.ckpt"):
        train(_tiny(tmp_path, resume=True))


def test_resume_of_another_architecture_is_model_error(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    torch.save({"arch": "wtseg-r18s-fpn128", "state_dict": {}, "optimizer": {}, "iteration": 5},
               run / "last.ckpt")
    with pytest.raises(ModelError, match="architecture 'wtseg-r18s-fpn128'.*--init"):
        train(_tiny(tmp_path, resume=True))


@pytest.mark.parametrize("kw", [{"iterations": 0}, {"lr": -1.0}, {"width": 8}, {"batch_size": 0},
                                {"train_sizes": ()}, {"train_sizes": (480, 10)},
                                {"precision": "fp16"}])
def test_bad_config(tmp_path, kw):
    with pytest.raises(ConfigError):
        train(_tiny(tmp_path, **kw))


def test_train_on_coco_folder(tmp_path):
    import cv2

    d = tmp_path / "ds"
    (d / "images").mkdir(parents=True)
    images, per = [], []
    for k in range(2):
        s = D.render(D.TRAIN_SEED_BASE + k, 96, 72)
        cv2.imwrite(str(d / "images" / f"{k}.png"), s.image)
        images.append({"id": k + 1, "file_name": f"{k}.png", "width": 96, "height": 72})
        per.append(s.instances)
    write_instances(d / "instances.json", images, per)
    s = train(_tiny(tmp_path, data=str(d), train_sizes=(72,), eval_count=0))
    assert s["iterations"] == 2 and s["config"]["data"] == str(d)


def test_augment_keeps_masks_aligned():
    img = np.zeros((60, 80, 3), np.uint8)
    m = np.zeros((1, 60, 80), bool)
    m[10:30, 20:60] = True
    img[m[0]] = 255
    for seed in range(10):
        out = D.augment(D.Sample(img, Instances(np.array(["tower"], dtype=object), m)),
                        np.random.default_rng(seed))
        assert out.image.shape == img.shape
        if len(out.instances):
            mm = out.instances.masks[0]
            grey = out.image.mean(axis=2)
            assert grey[mm].mean() > grey[~mm].mean() + 60, seed


def test_to_target_types():
    s = D.render(D.TRAIN_SEED_BASE, 96, 72)
    x, t = D.to_target(s)
    assert x.shape == (3, 72, 96) and x.dtype == torch.float32 and 0 <= float(x.min()) <= float(x.max()) <= 1
    assert t["boxes"].shape == (len(t["labels"]), 4) and t["masks"].dtype == torch.uint8
    assert set(t["labels"].tolist()) <= {1, 2, 3}


def test_lr_schedule():
    assert lr_factor(0.0, 0, 100) == pytest.approx(0.01)
    assert lr_factor(0.0, 200, 100) == pytest.approx(1.0)
    assert lr_factor(1.0, 10_000, 100) == pytest.approx(0.02)
    assert lr_factor(0.5, 10_000, 100) == pytest.approx(0.51)


def test_cli_train_bad_data_exit_3(cli, tmp_path):
    res = cli("train", "--data", tmp_path / "nothing", "--out", tmp_path / "r")
    assert res.exit_code == ExitCode.INPUT


class _Seeds(torch.utils.data.Dataset):
    """Stands for the synthetic set: item i is the scene index itself."""

    def __len__(self):
        return 1_000_000

    def __getitem__(self, i):
        return int(i)


def test_seeds_up_to_49_get_scenes_of_their_own(tmp_path, monkeypatch):
    """Seeds 6 and 16 once trained on the same scenes (a set of 1 000 000 wraps at seed 10)."""
    monkeypatch.setattr(D, "collate", lambda b: list(b))

    class Full(_Seeds):
        def __len__(self):
            return TrainConfig().synth_count

    firsts = {}
    for seed in (6, 16, 49):
        cfg = _tiny(tmp_path, seed=seed)
        firsts[seed] = next(_batches(Full(), cfg, start_it=0))[0]
    assert firsts == {s: s * SYNTH_STRETCH for s in firsts}
    assert D.TRAIN_SEED_BASE + TrainConfig().synth_count <= D.DEV_SEED_BASE < D.HELDOUT_SEED_BASE


@pytest.mark.parametrize("seed", [0, 3])
def test_synthetic_scenes_follow_the_seed(tmp_path, seed, monkeypatch):
    monkeypatch.setattr(D, "collate", lambda b: list(b))
    cfg = _tiny(tmp_path, seed=seed)
    it = _batches(_Seeds(), cfg, start_it=0)
    first = [next(it) for _ in range(3)]
    assert first == [[seed * SYNTH_STRETCH + 2 * k, seed * SYNTH_STRETCH + 2 * k + 1] for k in range(3)]
    resumed = next(_batches(_Seeds(), cfg, start_it=2))
    assert resumed == first[2]


def test_cli_train_sizes_not_numbers_exit_4(cli, tmp_path):
    res = cli("train", "--sizes", "384,big", "--out", tmp_path / "r")  # a bad option value
    assert res.exit_code == ExitCode.CONFIG and "--sizes" in res.output


def test_cli_train_sizes_above_the_renders_exit_4(cli, tmp_path):
    """A size the renders cannot give is refused up front, not dropped silently (a run asking
    for 448-576 on 640 x 480 renders would train at 448 and 480 only)."""
    res = cli("train", "--sizes", "448,576", "--out", tmp_path / "r")
    assert res.exit_code == ExitCode.CONFIG
    assert "576" in res.output and "--width 768 --height 576" in res.output
    assert not (tmp_path / "r").exists()  # refused before anything was written


def test_progress_in_a_log_is_a_line_per_checkpoint(capsys):
    """Not on a terminal (a batch server's log) the run still tells its progress: a line at the
    first step, then every --checkpoint-every steps; the share done follows whichever end
    comes first, the iterations or --max-minutes (as the LR schedule)."""
    from wtcli.commands.train import _Report

    for max_minutes, shares in ((10, ["1 %", "52 %", "100 %", "100 %"]),
                                (None, ["0 %", "10 %", "20 %", "30 %"])):
        r = _Report(iterations=1000, max_minutes=max_minutes, every=100)
        for it in range(1, 302):
            r.step({"iteration": it, "loss": 0.8, "lr": 1e-4, "loss_mask": 0.2,
                    "loss_classifier": 0.1, "elapsed_s": 3.1 * it})
        r.close()
        lines = capsys.readouterr().err.splitlines()
        assert [line.split(",")[0] for line in lines] == [f"train: step {k}" for k in (1, 101, 201, 301)]
        assert [line.split(", ")[1].split(" of")[0] for line in lines] == shares
        assert "loss 0.800 (mask 0.200, cls 0.100)" in lines[1] and "3.10 s/step" in lines[1]
        assert "s/step" not in lines[0]


def test_progress_on_a_terminal_is_a_bar(monkeypatch):
    import io

    from rich.console import Console

    import wtcli.console
    from wtcli.commands.train import _Report

    buf = io.StringIO()
    monkeypatch.setattr(wtcli.console, "err_console", Console(file=buf, force_terminal=True, width=160))
    r = _Report(iterations=1000, max_minutes=10, every=100)
    for it in range(1, 51):  # a resumed run: the bar starts where the run stands
        r.step({"iteration": 500 + it, "loss": 0.8, "lr": 1e-4, "elapsed_s": 290.0 + 0.1 * it})
    r.close()
    out = buf.getvalue()
    assert "train" in out and "55%" in out and "step 550 loss 0.800" in out
    assert "train: step" not in out  # no log lines on a terminal


def test_fine_lr_mult_moves_the_fine_branch_that_much_faster(tmp_path):
    # AdamW's first step moves each weight with a gradient by the learning rate itself, so the
    # fine branch's last conv (started at zero) moves by --lr x the multiplier, the rest by --lr.
    _seed_all(5)
    init = build_model().state_dict()
    train(_tiny(tmp_path, iterations=1, eval_count=0, seed=5, lr=1e-3, fine_lr_mult=10.0))
    state = torch.load(tmp_path / "run" / "last.ckpt", weights_only=True)
    after = state["state_dict"]
    fine = float((after["backbone.fine.2.weight"] - init["backbone.fine.2.weight"]).abs().max())
    head = float((after["roi_heads.box_head.fc6.weight"] - init["roi_heads.box_head.fc6.weight"]).abs().max())
    assert fine == pytest.approx(1e-2, rel=0.05) and head == pytest.approx(1e-3, rel=0.05)
    assert [g["lr_mult"] for g in state["optimizer"]["param_groups"]] == [1.0, 10.0]
    # Resuming with another multiplier would silently change the run: refused, naming it.
    with pytest.raises(ConfigError, match="--fine-lr-mult 10"):
        train(_tiny(tmp_path, iterations=2, eval_count=0, seed=5, resume=True))
    with pytest.raises(ConfigError, match="fine-lr-mult"):
        train(_tiny(tmp_path, fine_lr_mult=0.0))


def test_average_weights_is_the_mean_and_says_of_what(tmp_path):
    models = []
    for seed in (1, 2):
        _seed_all(seed)
        models.append(build_model())
        save_weights(models[-1], tmp_path / f"w{seed}.pt", meta={"seed": seed})
    average_weights([tmp_path / "w1.pt", tmp_path / "w2.pt"], tmp_path / "mean.pt")
    m = build_model()
    meta = load_weights(m, tmp_path / "mean.pt")
    assert meta["weight_average"] == [str(tmp_path / "w1.pt"), str(tmp_path / "w2.pt")]
    a, b, got = (x.state_dict() for x in (*models, m))
    k = "roi_heads.box_head.fc6.weight"
    want = ((a[k].half().float() + b[k].half().float()) / 2).half().float()
    assert torch.equal(got[k], want) and not torch.equal(got[k], a[k].half().float())
    with pytest.raises(ModelError, match="nothing.pt"):
        average_weights([tmp_path / "w1.pt", tmp_path / "nothing.pt"], tmp_path / "x.pt")


def test_average_with_a_bad_file_fails_before_training(tmp_path):
    with pytest.raises(ModelError, match="nothing.pt"):
        train(_tiny(tmp_path, average_with=str(tmp_path / "nothing.pt")))
    assert not (tmp_path / "run" / "last.ckpt").exists()


def test_tiny_run_averaged_with_its_init(tmp_path):
    _seed_all(7)
    save_weights(build_model(), tmp_path / "init.pt")
    s = train(_tiny(tmp_path, iterations=1, eval_count=0, init=str(tmp_path / "init.pt"),
                    average_with=str(tmp_path / "init.pt")))
    run = tmp_path / "run"
    assert s["average"] == str(run / "model-average.pt")
    w = [build_model() for _ in range(3)]
    for m, p in zip(w, (tmp_path / "init.pt", run / "model.pt", run / "model-average.pt")):
        load_weights(m, p)
    k = "roi_heads.box_head.fc6.weight"
    i, t, avg = (m.state_dict()[k] for m in w)
    assert torch.allclose(avg, (i + t) / 2, atol=1e-3) and not torch.equal(i, t)


def test_weight_average_is_the_exponential_moving_average():
    from wtcli.segment.train import WeightAverage

    m = torch.nn.Linear(2, 1)
    m.register_buffer("steps", torch.tensor(0))
    with torch.no_grad():
        m.weight.fill_(1.0)
    ema = WeightAverage(m, 0.9)
    for value in (2.0, 4.0):
        with torch.no_grad():
            m.weight.fill_(value)
            m.steps += 1
        ema.update(m)
    want = 0.9 * (0.9 * 1.0 + 0.1 * 2.0) + 0.1 * 4.0
    assert torch.allclose(ema.state["weight"], torch.full((1, 2), want))
    assert int(ema.state["steps"]) == 2  # an integer buffer follows as it is
    ema.copy_to(m)
    assert torch.allclose(m.weight, torch.full((1, 2), want))


def test_ema_run_ships_the_average_and_resumes_it(tmp_path):
    """--ema: model.pt holds the averaged weights (the checkpoint keeps both), a resumed run
    goes on averaging where it stood, and the average is resumed only as it was started."""
    _seed_all(3)
    save_weights(build_model(), tmp_path / "init.pt")
    cfg = dict(eval_count=0, init=str(tmp_path / "init.pt"), seed=3, ema=0.5, lr=1e-3)
    train(_tiny(tmp_path, iterations=2, **cfg))
    run = tmp_path / "run"
    ck = torch.load(run / "last.ckpt", weights_only=True)
    k = "roi_heads.box_head.fc6.weight"
    last, avg = ck["state_dict"][k], ck["ema_state_dict"][k]
    assert not torch.equal(last, avg)
    shipped = build_model()
    meta = load_weights(shipped, run / "model.pt")
    assert meta["ema"] == 0.5
    assert torch.allclose(shipped.state_dict()[k], avg, atol=1e-3)
    export_checkpoint(run / "last.ckpt", tmp_path / "exported.pt")
    load_weights(shipped, tmp_path / "exported.pt")
    assert torch.allclose(shipped.state_dict()[k], avg, atol=1e-3)
    with pytest.raises(ConfigError, match="ema 0.5"):
        train(_tiny(tmp_path, iterations=3, resume=True, **{**cfg, "ema": 0.0}))
    train(_tiny(tmp_path, iterations=3, resume=True, **cfg))
    ck3 = torch.load(run / "last.ckpt", weights_only=True)
    want = 0.5 * avg + 0.5 * ck3["state_dict"][k]
    assert torch.allclose(ck3["ema_state_dict"][k], want, atol=1e-6)
    with pytest.raises(ConfigError, match="--ema"):
        train(_tiny(tmp_path / "bad", ema=1.0))


# ---- labelled real photos: semantic masks -> instances, mixed batches, held-out sequences ----
def _blade(hub, angle_deg, length=120, root=14, tip=4):
    import math

    a = math.radians(angle_deg)
    d, n = np.array([math.cos(a), -math.sin(a)]), np.array([math.sin(a), math.cos(a)])
    h = np.array(hub, float)
    return np.round([h + n * root / 2, h + d * length + n * tip / 2, h + d * length - n * tip / 2,
                     h - n * root / 2]).astype(np.int32)


def _semantic_rotor(angles, hub=(200, 150), hub_disk=True, size=(320, 400), blade_root=14):
    """Class 1 blades from ``hub`` at ``angles`` (degrees, counter-clockwise from +x, y up),
    class 2 tower below the hub, nacelle box and (optionally) hub disk, as WTA masks label them."""
    import cv2

    sem = np.zeros(size, np.uint8)
    cv2.rectangle(sem, (hub[0] - 8, hub[1]), (hub[0] + 8, size[0] - 1), 2, -1)
    cv2.rectangle(sem, (hub[0] - 22, hub[1] - 10), (hub[0] + 22, hub[1] + 10), 2, -1)
    for a in angles:
        cv2.fillPoly(sem, [_blade(hub, a, root=blade_root)], 1)
    if hub_disk:
        cv2.circle(sem, hub, 9, 2, -1)
    return sem


@pytest.mark.parametrize("angles,hub_disk", [((90, 210, 330), True), ((90, 210, 330), False),
                                             ((30, 150, 270), True), ((45, 165, 285), True),
                                             ((10, 130, 250), False)])
def test_semantic_split_gives_three_blades_at_their_angles(angles, hub_disk):
    from wtcli.segment.real import blade_angles, split_semantic

    s = split_semantic(_semantic_rotor(angles, hub_disk=hub_disk))
    labels = list(s.instances.labels)
    assert labels.count("blade") == 3 and labels.count("tower") == 1, labels
    assert len(s.hubs) == 1 and np.hypot(s.hubs[0][0] - 200, s.hubs[0][1] - 150) < 3
    got = sorted(a for _, a in blade_angles(s))
    err = [abs((g - w + 180) % 360 - 180) for g, w in zip(got, sorted(angles))]
    assert max(err) < 2.0, (got, angles)
    # Every labelled pixel is in exactly one instance: nothing lost, nothing twice.
    sem = _semantic_rotor(angles, hub_disk=hub_disk)
    cover = s.instances.masks.sum(axis=0)
    assert cover.max() == 1 and np.array_equal(cover == 1, sem > 0)


def test_semantic_split_joins_a_tower_cut_by_the_lower_blade():
    from wtcli.segment.real import split_semantic

    sem = _semantic_rotor((90, 210, 270), blade_root=24)  # the lower blade wider than the tower
    import cv2

    assert cv2.connectedComponents((sem == 2).astype(np.uint8))[0] - 1 >= 2  # cut apart
    labels = list(split_semantic(sem).instances.labels)
    assert labels.count("tower") == 1 and labels.count("blade") == 3, labels


def test_semantic_split_nacelle_close_up_and_strays():
    from wtcli.segment.real import split_semantic

    sem = np.zeros((300, 300), np.uint8)
    sem[40:290, 140:156] = 2  # a shaft 16 px wide, 250 tall
    sem[20:40, 100:200] = 2  # a nacelle 100 px wide on top of it
    s = split_semantic(sem)
    assert sorted(s.instances.labels) == ["nacelle", "tower"]
    nac = s.instances.of("nacelle").masks[0]
    assert nac[20:40, 100:200].all() and not nac[60:].any()
    close = np.zeros((200, 300), np.uint8)
    close[80:140, 20:280] = 1  # a blade filling the frame, no tower: one blade, no hub
    close[5:7, 5:7] = 1  # 4 stray pixels: dropped
    s = split_semantic(close)
    assert list(s.instances.labels) == ["blade"] and s.hubs == ()
    assert split_semantic(np.zeros((50, 60), np.uint8)).instances.image_size == (50, 60)


def test_view_types_and_sequences():
    from wtcli.segment.real import sequences, view_type

    assert view_type("single blade close-up (tip), ground behind") == "close-up"
    assert view_type("distant, three turbines; main rotor oblique") == "distant"
    assert view_type("rear three-quarter view, whole rotor") == "rear-oblique"
    assert view_type("rear close view, whole rotor") == "rear"
    assert view_type("close front-oblique view of hub") == "front-oblique"
    assert view_type("close front view of the hub from above") == "front"
    assert view_type("side-oblique, whole rotor") == "oblique"
    assert view_type("two turbines, rotors near edge-on") == "side"
    assert view_type("steep downward nadir view") == "nadir"
    assert view_type("close; blades cut by frame") == "other"
    names = (["a_03t", "a_04t", "b_09"] + [f"a_{k:02d}" for k in range(1, 11)]
             + [f"a_{k:02d}" for k in (20, 22, 24, 26, 28, 30, 32, 33)] + ["c_01", "c_02"])
    seqs = sequences(names)
    assert seqs[:3] == ["other"] * 3 and seqs[-2:] == ["other"] * 2
    assert set(seqs[3:13]) == {"a_01-10"} and set(seqs[13:21]) == {"a_20-33"}


def _photo_folder(root, n=4):
    """A folder as ../shared/real-photos is laid out: images/, masks/, manifest.csv."""
    import cv2

    (root / "images").mkdir(parents=True)
    (root / "masks").mkdir()
    rows = ["image,mask,site,view"]
    rng = np.random.default_rng(0)
    for k in range(n):
        sem = _semantic_rotor((90 + 7 * k, 210 + 7 * k, 330 + 7 * k), size=(240, 320), hub=(160, 110))
        img = rng.integers(60, 120, (240, 320, 3)).astype(np.uint8)
        img[sem == 1], img[sem == 2] = 235, 200
        name = f"s_{k + 1:02d}"
        cv2.imwrite(str(root / "images" / f"{name}.jpg"), img)
        cv2.imwrite(str(root / "masks" / f"{name}.png"), sem)
        rows.append(f"images/{name}.jpg,masks/{name}.png,s,front view whole rotor")
    (root / "manifest.csv").write_text("\n".join(rows) + "\n")
    return root


def test_real_dataset_reads_a_photo_folder_and_holds_out_sequences(tmp_path):
    import csv

    root = _photo_folder(tmp_path / "photos")
    ds = D.RealDataset(root, augment=False)
    assert len(ds) == 4 and set(ds.sequences) == {"other"}
    s = ds.load(1)
    assert s.image.shape == (240, 320, 3) and list(s.instances.labels).count("blade") == 3
    x, t = ds[1]
    # The nacelle the split tells apart is not taught from a photo: an ignore box instead.
    assert x.shape == (3, 240, 320) and sorted(t["labels"].tolist()) == [1, 1, 1, 2]
    assert t["ignore_boxes"].shape == (1, 4)
    # A photo's split is kept as run lengths, not drawn masks (a user's thousands of 12 MP
    # photos: tens of GB), and reads back the same.
    again = ds.load(1)
    assert (again.instances.masks == s.instances.masks).all()
    assert (again.ignore == s.ignore).all() if s.ignore is not None else again.ignore is None
    labels, shapes, size, unknown = ds._cache[ds.keep[1]]
    assert all(isinstance(m.runs, np.ndarray) for m in shapes)
    assert sum(m.runs.nbytes for m in shapes) < s.instances.masks.size / 8 / 4  # < 1/4 of packed bits
    # A sequence column names the flights; holding one out leaves the others.
    rows = list(csv.reader((root / "manifest.csv").open()))
    rows[0].append("sequence")
    for k, r in enumerate(rows[1:]):
        r.append("f1" if k < 3 else "f2")
    with (root / "manifest.csv").open("w", newline="") as f:
        csv.writer(f).writerows(rows)
    assert len(D.RealDataset(root, holdout=("f2",))) == 3
    with pytest.raises(ConfigError, match="f9.*f1, f2"):
        D.RealDataset(root, holdout=("f9",))
    with pytest.raises(ConfigError, match="every photo is held out"):
        D.RealDataset(root, holdout=("f1", "f2"))


def test_real_share_per_batch_on_average_and_repeatable():
    from wtcli.segment.train import real_in_batch

    cfg = TrainConfig(batch_size=2, real_share=0.3, seed=4)
    ks = [real_in_batch(cfg, b) for b in range(4000)]
    assert set(ks) == {0, 1} and abs(np.mean(ks) / 2 - 0.3) < 0.02
    assert ks == [real_in_batch(cfg, b) for b in range(4000)]
    full = TrainConfig(batch_size=3, real_share=1.0)
    assert {real_in_batch(full, b) for b in range(50)} == {3}


def test_mixed_stream_resumes_where_it_stood(tmp_path, monkeypatch):
    from wtcli.segment.train import _mixed_batches

    monkeypatch.setattr(D, "collate", lambda b: list(b))

    class Keys(torch.utils.data.Dataset):
        def __getitem__(self, key):
            return key

    cfg = _tiny(tmp_path, batch_size=4, real_share=0.3, real=str(tmp_path))
    it = _mixed_batches(Keys(), cfg, 0)
    first = [next(it) for _ in range(6)]
    assert next(_mixed_batches(Keys(), cfg, 4)) == first[4]
    reals = [p for b in first for w, p in b if w == "real"]
    bases = [p for b in first for w, p in b if w == "base"]
    assert reals == list(range(len(reals))) and bases == list(range(len(bases)))  # no repeats


def test_train_mixes_real_photos_and_holds_a_sequence_out(tmp_path):
    root = _photo_folder(tmp_path / "photos")
    s = train(_tiny(tmp_path, real=str(root), real_share=0.5, eval_count=0, batch_size=2))
    assert s["iterations"] == 2 and s["config"]["real"] == str(root)
    meta = load_weights(build_model(), tmp_path / "run" / "model.pt")
    assert meta["real"] == str(root) and meta["real_share"] == 0.5
    with pytest.raises(ConfigError, match="--real-holdout-sequence needs --real"):
        train(_tiny(tmp_path, out=str(tmp_path / "r2"), real_holdout=("other",)))
    with pytest.raises(ConfigError, match="real-share"):
        train(_tiny(tmp_path, out=str(tmp_path / "r3"), real=str(root), real_share=0.0))


def test_train_refuses_a_folder_holding_a_run(tmp_path, cli):
    """As train-refiner: a run folder is continued with --resume or left alone (exit 3),
    never overwritten."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.json").write_text("{}")
    with pytest.raises(InputError, match="holds a run already.*--resume"):
        train(_tiny(tmp_path))
    assert (run / "metrics.json").read_text() == "{}"
    res = cli("train", "--iterations", "1", "--out", run)
    assert res.exit_code == ExitCode.INPUT and "holds a run already" in res.output
    res = cli("train", "--real", tmp_path / "no-photos", "--out", tmp_path / "r")
    assert res.exit_code == ExitCode.INPUT and "--real" in res.output


def test_view_mix_reaches_the_renders(tmp_path):
    from wtcli.segment.train import make_dataset

    plain = make_dataset(_tiny(tmp_path, augment=False))
    wide = make_dataset(_tiny(tmp_path, augment=False, view_mix="closeup"))
    assert wide.view_mix == "closeup" and plain.view_mix is None
    # A close-up fills much of the frame with a blade; the usual mix shows whole turbines.
    def largest(ds):
        return np.mean([float(ds[k][1]["masks"].flatten(1).sum(1).max()) / (96 * 72)
                        if len(ds[k][1]["labels"]) else 0.0 for k in range(4)])

    assert largest(wide) > 0.1 > largest(plain)
    assert not torch.equal(plain[0][0], wide[0][0])
    with pytest.raises(ConfigError, match="--view-mix"):
        train(_tiny(tmp_path, view_mix="front=x"))


def test_a_nacelle_the_mask_does_not_tell_apart_is_taught_as_nothing():
    """A photo's class 2 holds the nacelle; where it is not told apart, the tower's top must
    become neither a tower target nor background (the renders call it nacelle)."""
    from wtcli.segment.model import _in_ignored
    from wtcli.segment.real import split_semantic

    import cv2

    sem = np.zeros((320, 400), np.uint8)
    sem[150:, 192:208] = 2  # a shaft 16 px wide below the hub at (200, 150)
    sem[145:175, 186:214] = 2  # a nacelle only 1.75 shafts wide: not told apart
    for a in (90, 210, 330):
        cv2.fillPoly(sem, [_blade((200, 150), a)], 1)
    s = split_semantic(sem)
    assert "nacelle" not in list(s.instances.labels) and s.unknown is not None
    labels, masks, ignore = D.training_instances(s)
    tower = masks[list(labels).index("tower")]
    assert tower.any() and not (tower & ignore).any()
    assert ignore[170:180, 194:206].all() and not ignore[190:].any()
    box = D.ignore_boxes(ignore)
    assert len(box) == 1 and box[0, 1] <= 150 and box[0, 3] >= 175
    # Anchors and proposals over the nacelle are not background; those elsewhere still are.
    model = build_model()
    anchors = torch.tensor([[186.0, 150, 214, 175], [20, 20, 60, 60], [195, 250, 205, 300],
                            [192, 200, 208, 320]])
    gt = {"boxes": torch.tensor([[192.0, 200, 208, 320]]), "labels": torch.tensor([2]),
          "masks": torch.zeros((1, 320, 400), dtype=torch.uint8),
          "ignore_boxes": torch.from_numpy(box)}
    assert _in_ignored(anchors, gt["ignore_boxes"]).tolist() == [True, False, False, False]
    rpn_labels, _ = model.rpn.assign_targets_to_anchors([anchors], [gt])
    assert rpn_labels[0].tolist() == [-1.0, 0.0, 0.0, 1.0]
    model.train()
    _, _, roi_labels, _ = model.roi_heads.select_training_samples([anchors.clone()], [gt])
    assert sorted(roi_labels[0].tolist()) == [0, 0, 2, 2]  # the tower box and its ground truth
    without = dict(gt, ignore_boxes=torch.zeros((0, 4)))
    _, _, roi_labels, _ = model.roi_heads.select_training_samples([anchors.clone()], [without])
    assert sorted(roi_labels[0].tolist()) == [0, 0, 0, 2, 2]
    # The ignore region follows a flip and a crop like the masks do.
    img = np.zeros((320, 400, 3), np.uint8)
    sample = D.Sample(img, Instances(labels, masks), ignore)
    for seed in range(6):
        a = D.augment(sample, np.random.default_rng(seed))
        assert a.ignore is not None and a.ignore.shape == (320, 400)
        t = a.instances.masks[list(a.instances.labels).index("tower")]
        assert (t & a.ignore).sum() <= 0.005 * t.sum()  # resampled alike: apart
    _, target = D.to_target(sample)
    assert target["ignore_boxes"].shape == (1, 4)


def test_a_resume_that_asks_for_another_run_is_refused(tmp_path):
    from wtcli.errors import ConfigError

    train(_tiny(tmp_path, iterations=1, eval_count=0, seed=2))
    for other in (dict(seed=3), dict(lr=5e-4), dict(batch_size=1),
                  dict(view_mix="mixed=0.5,closeup=0.5")):
        with pytest.raises(ConfigError, match="the run was started with"):
            train(_tiny(tmp_path, **{"iterations": 2, "eval_count": 0, "seed": 2, "resume": True,
                                     **other}))
    # longer, elsewhere: fine
    s = train(_tiny(tmp_path, iterations=2, eval_count=0, seed=2, resume=True, threads=1))
    assert s["iterations"] == 2


def test_ctrl_c_keeps_the_steps_since_the_last_checkpoint(tmp_path):
    import torch as _t

    def stop(rec):
        if rec["iteration"] == 2:
            raise KeyboardInterrupt
    with pytest.raises(KeyboardInterrupt):
        train(_tiny(tmp_path, iterations=5, eval_count=0, checkpoint_every=100), progress=stop)
    assert int(_t.load(tmp_path / "run" / "last.ckpt", weights_only=True)["iteration"]) == 2
    assert train(_tiny(tmp_path, iterations=3, eval_count=0, checkpoint_every=100,
                       resume=True))["iterations"] == 3


def test_a_data_workers_error_reads_as_its_own_message():
    from wtcli.errors import InputError
    from wtcli.segment.train import _from_worker

    wrapped = InputError("Caught InputError in DataLoader worker process 0.\nOriginal Traceback "
                         "(most recent call last):\n  File \"x.py\", line 1, in f\n"
                         "wtcli.errors.InputError: photos/a.png: mask is 10x10, its image 20x20\n")
    got = _from_worker(wrapped)
    assert isinstance(got, InputError) and str(got) == "photos/a.png: mask is 10x10, its image 20x20"
    plain = InputError("a.png: not a readable image")
    assert _from_worker(plain) is plain


def test_a_colour_mask_is_refused_not_read_as_background(tmp_path):
    """OpenCV gives a palette or colour-coded PNG as colours: blade red (0, 0, 128 in BGR) and
    tower green would both read 0 in one channel, so the photo would train as background."""
    import cv2

    from wtcli.errors import InputError
    from wtcli.segment.real import RealPhoto, read_pair

    cv2.imwrite(str(tmp_path / "a.png"), np.full((8, 8, 3), 90, np.uint8))
    colour = np.zeros((8, 8, 3), np.uint8)
    colour[2:4, :, 2] = 128  # blade, red
    colour[5:7, :, 1] = 128  # tower, green
    cv2.imwrite(str(tmp_path / "m.png"), colour)
    photo = RealPhoto(tmp_path / "a.png", tmp_path / "m.png", "a", "s", "front", "")
    with pytest.raises(InputError, match="a colour mask"):
        read_pair(photo)
    grey = np.zeros((8, 8, 3), np.uint8)
    grey[2:4], grey[5:7] = 1, 2  # class numbers stored as RGB: read as they are
    cv2.imwrite(str(tmp_path / "m.png"), grey)
    assert sorted(np.unique(read_pair(photo)[1]).tolist()) == [0, 1, 2]


# ---- a user's own data: checked before training, drawn per draw, COCO semantics ------------
def _coco(root, images, annotations, categories=None, write_images=True):
    """A COCO folder: ``images`` as (file name, width, height), blank PNGs written for them."""
    import cv2

    (root / "images").mkdir(parents=True, exist_ok=True)
    doc = {"images": [{"id": k + 1, "file_name": n, "width": w, "height": h}
                      for k, (n, w, h) in enumerate(images)],
           "annotations": [dict(a, id=k + 1) for k, a in enumerate(annotations)],
           "categories": categories or [{"id": 1, "name": "blade"}, {"id": 2, "name": "tower"},
                                        {"id": 3, "name": "nacelle"}]}
    if write_images:
        for n, w, h in images:
            img = np.zeros((h, w, 3), np.uint8)
            img[h // 4: h // 2, w // 4: w // 2] = 200
            cv2.imwrite(str(root / "images" / n), img)
    (root / "instances.json").write_text(json.dumps(doc))
    return root


def _square(x, y, s):
    return [[x, y, x + s, y, x + s, y + s, x, y + s]]


def test_coco_masks_are_drawn_when_drawn_not_held(tmp_path):
    """Masks are drawn per item: making the dataset allocates nothing the size of an image
    (all masks drawn up front took 2.3 GB for 10 photos of 5472 x 3648 with 8 polygons each)."""
    import tracemalloc

    from wtcli.masks import read_instances

    w, h = 2000, 1500
    anns = [{"image_id": i, "category_id": 1 + k % 3, "iscrowd": 0,
             "segmentation": _square(100 + 200 * k, 100 + 100 * i, 150)} for i in (1, 2) for k in range(6)]
    root = _coco(tmp_path / "ds", [("a.png", w, h), ("b.png", w, h)], anns)
    tracemalloc.start()
    try:
        ds = D.CocoDataset(root, augment=False)
        held = tracemalloc.get_traced_memory()[0]  # (the JSON reader's peak is its read buffer)
    finally:
        tracemalloc.stop()
    assert held < 1e6, held  # 12 masks of 3 MB each, were they drawn
    for k, (_, truth) in enumerate(read_instances(root / "instances.json")):
        s = ds.load(k)
        assert list(s.instances.labels) == list(truth.labels)
        assert np.array_equal(s.instances.masks, truth.masks) and s.ignore is None


def _png_header(path, w, h):
    """A PNG of which only the header is whole: its size is read, never decoded."""
    import struct
    import zlib

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + ihdr
                     + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr)))


@pytest.mark.parametrize("case", ["missing", "other_size", "over_the_limit", "not_an_image"])
def test_coco_image_problems_are_found_before_training(tmp_path, cli, monkeypatch, case):
    import cv2

    anns = [{"image_id": i, "category_id": 1, "segmentation": _square(10, 10, 30)} for i in (1, 2, 3)]
    root = _coco(tmp_path / "ds", [("a.png", 96, 72), ("b.png", 96, 72), ("c.png", 96, 72)], anns)
    bad = root / "images" / "c.png"
    if case == "missing":
        bad.unlink()
        says = "'c.png' not found"
    elif case == "other_size":
        cv2.imwrite(str(bad), np.zeros((70, 96, 3), np.uint8))
        says = "image is 96x70 but"
    elif case == "over_the_limit":
        _png_header(bad, 20_000, 20_000)
        says = "20000x20000 is 400,000,000 pixels"
    else:
        bad.write_bytes(b"not an image at all")
        says = "not a readable image"
    if case != "not_an_image":  # a header that says it all: decoded by nothing
        monkeypatch.setattr(cv2, "imread", lambda *a, **k: pytest.fail("decoded up front"))
    with pytest.raises(InputError, match=says) as e:
        D.CocoDataset(root, augment=False)
    assert "c.png" in str(e.value)
    monkeypatch.undo()
    seen = []
    with pytest.raises(InputError, match=says):
        train(_tiny(tmp_path, data=str(root), train_sizes=(72,), eval_count=0), progress=seen.append)
    assert not seen and not (tmp_path / "run" / "last.ckpt").exists()
    res = cli("train", "--data", root, "--out", tmp_path / "r2", "--iterations", "1",
              "--workers", "0", "--eval-count", "0")
    assert res.exit_code == ExitCode.INPUT and "c.png" in res.stderr and says in res.stderr
    assert res.stderr.count("\n") == 1  # one line


def test_val_data_is_checked_before_training(tmp_path):
    anns = [{"image_id": 1, "category_id": 1, "segmentation": _square(10, 10, 30)}]
    root = _coco(tmp_path / "val", [("a.png", 96, 72)], anns)
    (root / "images" / "a.png").unlink()
    seen = []
    with pytest.raises(InputError, match="a.png"):
        train(_tiny(tmp_path, val=str(root), eval_count=1), progress=seen.append)
    assert not seen and not (tmp_path / "run" / "last.ckpt").exists()


def test_photo_exif_orientation_is_read_as_the_labels_were_drawn(tmp_path):
    """A JPEG stored 40 x 30 that its EXIF says to turn a quarter: labels sized 40 x 30 were
    drawn on the stored pixels, labels sized 30 x 40 on the turned photo; either is accepted."""
    import struct

    import cv2

    img = np.zeros((30, 40, 3), np.uint8)
    img[:, :10] = 255
    jpg = cv2.imencode(".jpg", img)[1].tobytes()
    tiff = (b"MM\0*" + struct.pack(">IH", 8, 1) + struct.pack(">HHIHH", 0x0112, 3, 1, 6, 0)
            + struct.pack(">I", 0))
    app1 = b"Exif\0\0" + tiff
    for (w, h), name in (((40, 30), "stored"), ((30, 40), "turned")):
        anns = [{"image_id": 1, "category_id": 1, "segmentation": _square(2, 2, 20)}]
        root = _coco(tmp_path / name, [("a.jpg", w, h)], anns, write_images=False)
        (root / "images" / "a.jpg").write_bytes(jpg[:2] + b"\xff\xe1" + struct.pack(">H", len(app1) + 2)
                                                + app1 + jpg[2:])
        s = D.CocoDataset(root, augment=False).load(0)
        assert s.image.shape[:2] == (h, w), name
        assert (s.image[:, :10] > 200).all() == (name == "stored")  # the stored pixels as stored


def test_coco_semantics_crowd_boxes_other_categories_negatives(tmp_path, cli):
    """Categories matched by name whatever their ids; other categories skipped and counted;
    crowd regions and box-only annotations are ignore regions, neither instance nor
    background; images without annotations are negatives."""
    cats = [{"id": 7, "name": "Blade"}, {"id": 1, "name": "person"}, {"id": 2, "name": "tower"},
            {"id": 3, "name": "nacelle"}, {"id": 4, "name": "car"}]
    anns = [{"image_id": 1, "category_id": 7, "iscrowd": 0, "segmentation": _square(5, 5, 30)},
            {"image_id": 1, "category_id": 2, "iscrowd": 1, "bbox": [50, 10, 20, 40],
             "segmentation": {"counts": "compressed;text", "size": [72, 96]}},
            {"image_id": 1, "category_id": 7, "segmentation": [], "bbox": [10, 50, 10, 10]},
            {"image_id": 1, "category_id": 1, "segmentation": _square(80, 60, 5)},
            {"image_id": 1, "category_id": 1, "segmentation": _square(80, 60, 5)},
            {"image_id": 1, "category_id": 4, "segmentation": _square(80, 60, 5)}]
    root = _coco(tmp_path / "ds", [("a.png", 96, 72), ("b.png", 96, 72)], anns, cats)
    ds = D.CocoDataset(root, augment=False)
    s = ds.load(0)
    assert list(s.instances.labels) == ["blade"]
    assert s.ignore[10:50, 50:70].all() and s.ignore[50:60, 10:20].all()
    assert s.ignore.sum() == 20 * 40 + 10 * 10
    _, t = D.to_target(s)
    assert t["labels"].tolist() == [1] and t["ignore_boxes"].shape == (2, 4)
    neg = ds.load(1)
    assert len(neg.instances) == 0 and neg.ignore is None
    note, = ds.notes()
    for says in ("1 instance(s) in 2 image(s)", "1 image(s) with no instance (negatives: all background)",
                 "3 of categories not trained (person 2, car 1)", "1 crowd region(s)",
                 "1 box(es) without a mask"):
        assert says in note, note
    res = cli("train", "--data", root, "--out", tmp_path / "r", "--iterations", "1", "--width", "96",
              "--height", "72", "--sizes", "72", "--workers", "0", "--eval-count", "0")
    assert res.exit_code == 0, res.stderr
    assert res.stderr.count("ignored 3 of categories not trained") == 1
    # Nothing left to train as an instance: refused, saying what there was.
    only = _coco(tmp_path / "only", [("a.png", 96, 72)], anns[1:], cats)
    with pytest.raises(InputError, match=r"no annotation to train on.*person 2, car 1.*1 crowd"):
        D.CocoDataset(only)
    with pytest.raises(InputError, match="no category is blade, tower or nacelle"):
        D.CocoDataset(_coco(tmp_path / "none", [("a.png", 96, 72)], anns[3:4],
                            [{"id": 1, "name": "person"}]))
    bad = _coco(tmp_path / "bad", [("a.png", 96, 72)], [dict(anns[0], category_id=9)], cats)
    with pytest.raises(InputError, match=r"annotations\[0\]: category_id: expected one of the "
                                         r"categories' ids \[1, 2, 3, 4, 7\], got 9"):
        D.CocoDataset(bad)


def test_real_photo_problems_are_found_before_training(tmp_path):
    import cv2

    for case, says in (("values", r"expected classes 0, 1 \(blade\), 2 \(tower\), found \[7\]"),
                       ("size", "mask is 320x240 but its photo"),
                       ("huge", "20000x20000 is 400,000,000 pixels")):
        root = _photo_folder(tmp_path / case)
        mask, photo = root / "masks" / "s_03.png", root / "images" / "s_03.jpg"
        if case == "values":
            sem = cv2.imread(str(mask), cv2.IMREAD_UNCHANGED)
            sem[0, 0] = 7
            cv2.imwrite(str(mask), sem)
        elif case == "size":
            cv2.imwrite(str(photo), np.zeros((200, 320, 3), np.uint8))
        else:
            photo = photo.with_suffix(".png")
            _png_header(photo, 20_000, 20_000)
            man = root / "manifest.csv"
            man.write_text(man.read_text().replace("s_03.jpg", "s_03.png"))
        with pytest.raises(InputError, match=says) as e:
            D.RealDataset(root, augment=False)
        assert ("s_03.png" if case != "size" else "s_03.jpg") in str(e.value)


def test_manifest_with_a_bom_and_capitalised_columns_is_read(tmp_path):
    from wtcli.segment.real import read_folder

    root = _photo_folder(tmp_path / "p", n=2)
    man = root / "manifest.csv"
    text = man.read_text()
    man.write_text("\ufeff" + text.replace("image,mask,site,view", "Image, MASK ,Site,View"),
                   encoding="utf-8")
    photos = read_folder(root)
    assert [p.name for p in photos] == ["s_01", "s_02"] and photos[0].view == "front"
    man.write_text("Image,Mask,image\n" + "\n".join(text.splitlines()[1:]))
    with pytest.raises(InputError, match="column 'image' given twice"):
        read_folder(root)
    man.write_text("picture;mask\n" + "\n".join(text.splitlines()[1:]))
    with pytest.raises(InputError, match=r"missing image and mask \(it has 'picture;mask'\)"):
        read_folder(root)
    man.write_text("image,mask\nimages/s_01.jpg\n")
    with pytest.raises(InputError, match="line 2: no mask given"):
        read_folder(root)


@pytest.mark.parametrize("mix", ["mixed=-1", "mixed=-1,front=2", "mixed=1e400", "mixed=nan",
                                 "front=inf,mixed=1"])
def test_cli_view_mix_shares_out_of_range(cli, tmp_path, mix):
    """A bad option value: exit 4, as every other (``mixed=-1,front=2`` once trained on front
    views alone, ``mixed=1e400`` ended in exit 1)."""
    res = cli("train", "--view-mix", mix, "--out", tmp_path / "r")
    name = mix.split(",")[0].split("=")[0]
    assert res.exit_code == ExitCode.CONFIG, res.stderr
    assert f"--view-mix: expected a share in [0, 1e6] for {name}" in res.stderr
    assert res.stderr.count("\n") == 1 and not (tmp_path / "r").exists()


def test_sigterm_saves_the_steps_since_the_last_checkpoint(tmp_path):
    """SIGTERM (a batch scheduler's time limit, `timeout`, `kill`) right after step 1 of a run
    that checkpoints every 100: the step is saved, as on Ctrl-C, and the exit is 143."""
    import subprocess
    import sys
    import textwrap
    from pathlib import Path

    code = textwrap.dedent("""
        import os, signal, sys
        import wtcli.segment.train as T

        real = T.train

        def train(cfg, progress=None, note=None):
            def step(rec):
                progress(rec)
                if rec["iteration"] == 1:
                    os.kill(os.getpid(), signal.SIGTERM)
            return real(cfg, step, note)

        T.train = train
        from wtcli.cli import main
        main(["train", "--out", sys.argv[1], "--iterations", "5", "--width", "96", "--height", "72",
              "--workers", "0", "--eval-count", "0", "--checkpoint-every", "100", "--warmup", "1"])
    """)
    run = tmp_path / "run"
    done = subprocess.run([sys.executable, "-c", code, str(run)], capture_output=True, text=True,
                          cwd=Path(__file__).resolve().parents[1], timeout=600)
    assert done.returncode == 143, (done.returncode, done.stderr[-800:])
    assert done.stderr.endswith("interrupted (SIGTERM)\n")
    assert int(torch.load(run / "last.ckpt", weights_only=True)["iteration"]) == 1
    assert sorted(p.name for p in run.iterdir()) == ["last.ckpt"]  # no temporary left


def test_a_run_clears_the_temporaries_a_kill_left(tmp_path):
    """A kill during a checkpoint write leaves .last.ckpt.XXXXXXXX (tens of MB): the next run,
    started or resumed, removes those of its own files and nothing else."""
    run = tmp_path / "run"
    run.mkdir()
    ours = [run / ".last.ckpt.k2j4_x9q", run / ".model.pt.abcd1234", run / ".metrics.json.zz11yy22"]
    theirs = [run / ".notes.txt", run / ".other.ckpt.abcd1234"]
    for p in ours + theirs:
        p.write_bytes(b"half")
    train(_tiny(tmp_path, iterations=1, eval_count=0))
    assert sorted(p for p in run.iterdir() if p.name.startswith(".")) == sorted(theirs)
    (run / ".last.ckpt.q1w2e3r4").write_bytes(b"half")
    train(_tiny(tmp_path, iterations=1, eval_count=0, resume=True))
    assert not (run / ".last.ckpt.q1w2e3r4").exists()


def test_train_refiner_clears_the_temporaries_a_kill_left(tmp_path, monkeypatch):
    """As train: a kill while a data part or the checkpoint was written leaves
    .part-0000.npz.XXXXXXXX or .last.ckpt.XXXXXXXX; the next run removes them first."""
    from wtcli.segment import train_refine

    out = tmp_path / "ref"
    (out / "data").mkdir(parents=True)
    ours = [out / "data" / ".part-0000.npz.k2j4_x9q", out / "data" / ".photos.json.abcd1234",
            out / ".last.ckpt.zz11yy22", out / ".refiner.pt.q1w2e3r4"]
    theirs = [out / "data" / ".notes.npz", out / ".other.npz.abcd1234"]
    for p in ours + theirs:
        p.write_bytes(b"half")

    class Stop(Exception):
        pass

    def stop(*args, **kwargs):  # the data stage: the check is what came before it
        raise Stop
    monkeypatch.setattr(train_refine, "make_data", stop)
    with pytest.raises(Stop):
        train_refine.train_refiner(train_refine.RefinerConfig(out=str(out), images=4, epochs=1,
                                                              eval_count=0))
    assert sorted(p for p in out.rglob(".*")) == sorted(theirs)
