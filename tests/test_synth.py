"""The synthetic renderer: determinism, masks that agree with the ground truth, files that round
trip, and the `wtinspect synth` command's exit codes and clean --json."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from wtcli.errors import ExitCode
from wtcli.masks import read_instances
from wtcli.pitch.angles import classify_theta
from wtcli.synth import SynthSample, render_dataset, render_sample, sample_seed

W, H = 320, 240


@pytest.fixture(scope="module")
def front_samples():
    return [render_sample(s, W, H, view="front") for s in range(8)]


def test_same_seed_same_bytes():
    a, b = render_sample(11, W, H), render_sample(11, W, H)
    assert a.image.tobytes() == b.image.tobytes()
    assert np.array_equal(a.instances.masks, b.instances.masks)
    assert list(a.instances.labels) == list(b.instances.labels)
    assert json.dumps(a.truth, sort_keys=True) == json.dumps(b.truth, sort_keys=True)


def test_different_seeds_differ():
    a, b = render_sample(1, W, H), render_sample(2, W, H)
    assert a.image.tobytes() != b.image.tobytes()
    assert a.truth["turbine"] != b.truth["turbine"]


def test_view_size_and_types():
    for view in ("front", "oblique", "side", "rear"):
        s = render_sample(3, 200, 150, view=view)
        assert isinstance(s, SynthSample)
        assert s.image.shape == (150, 200, 3) and s.image.dtype == np.uint8
        assert s.instances.masks.shape[1:] == (150, 200)
        assert s.truth["view"] == view
        assert set(s.instances.labels) <= {"blade", "tower", "nacelle"}


def test_inspection_stops_put_a_blade_straight_up_or_down_and_change_nothing_else():
    """Training's emphasis (``stops``): some rotors stand in a Y or an inverted Y. The rest of
    the photo's draws are kept, and without it (the held-out sets) the photo is unchanged."""
    az = []
    for seed in range(12):
        plain, stopped = render_sample(seed, W, H, view="front"), render_sample(seed, W, H, view="front", stops=1.0)
        assert render_sample(seed, W, H, view="front", stops=0.0).image.tobytes() == plain.image.tobytes()
        a = [b["rotor_azimuth_deg"] for b in stopped.truth["blades"]]
        az.append(min(abs((x - c + 180) % 360 - 180) for x in a for c in (90.0, 270.0)))
        assert stopped.truth["turbine"]["yaw_deg"] == plain.truth["turbine"]["yaw_deg"]
    assert max(az) <= 10.0 + 1e-9
    half = [render_sample(seed, W, H, stops=0.5).truth for seed in range(40)]
    near = sum(min(abs((b["rotor_azimuth_deg"] - c + 180) % 360 - 180) for b in t["blades"]
                   for c in (90.0, 270.0)) <= 10.0 for t in half)
    assert 15 <= near <= 35  # about half stopped, plus a few by chance (a third of the rest)
    with pytest.raises(ValueError, match="stops"):
        render_sample(0, W, H, stops=1.5)


def test_bad_arguments_raise_value_error():
    with pytest.raises(ValueError, match="seed"):
        render_sample(-1)
    with pytest.raises(ValueError, match="view"):
        render_sample(0, view="top")
    with pytest.raises(ValueError, match="width"):
        render_sample(0, 8, 8)


def test_truth_angles_in_range_and_classes(front_samples):
    for s in front_samples:
        assert len(s.truth["blades"]) == 3
        for b in s.truth["blades"]:
            assert 0 <= b["theta_deg"] < 180 and 0 <= b["phi_deg"] < 360
            assert math.isclose(b["theta_deg"], b["phi_deg"] % 180, abs_tol=1e-9)
            assert b["class"] == classify_theta(b["theta_deg"])


def test_blade_classes_follow_the_paper_intervals():
    assert [classify_theta(t) for t in (0, 30, 30.1, 60, 60.1, 119.9, 120, 149.9, 150, 179.9)] == [
        "horizontal", "horizontal", "acute", "acute", "vertical", "vertical", "acute", "acute",
        "horizontal", "horizontal"]


def _main_blades(s):
    owners = s.truth["instances"]
    return {o["blade"]: s.instances.masks[i] for i, o in enumerate(owners)
            if o["turbine"] == 0 and o["blade"] is not None}


def test_front_views_with_whole_rotor_show_three_blades(front_samples):
    checked = 0
    for s in front_samples:
        if s.truth["blades_whole_in_frame"] == 3:
            assert s.truth["blades_visible"] == 3
            assert len(_main_blades(s)) == 3
            checked += 1
    assert checked >= 2


def test_blade_masks_point_where_the_truth_says(front_samples):
    checked = 0
    for s in front_samples:
        hub = np.array(s.truth["hub_px"])
        for k, m in _main_blades(s).items():
            b = s.truth["blades"][k]
            if m.sum() < 150 or not b["tip_in_frame"]:
                continue
            ys, xs = np.nonzero(m)
            pts = np.stack([xs, ys], 1).astype(float)
            c = pts.mean(0)
            evals, evecs = np.linalg.eigh(np.cov((pts - c).T))
            v = evecs[:, -1]
            if v @ (c - hub) < 0:  # orient hub -> blade
                v = -v
            phi = math.degrees(math.atan2(-v[1], v[0])) % 360
            err = abs((phi - b["phi_deg"] + 180) % 360 - 180)
            assert err < 10, (s.truth["seed"], k, phi, b["phi_deg"])
            checked += 1
    assert checked >= 6


def test_masks_do_not_overlap_and_sit_where_the_image_changes():
    s = render_sample(5, W, H, view="front")
    assert s.instances.masks.sum(0).max() <= 1  # one owner per pixel (occlusion respected)
    assert len(s.instances) >= 3


def test_outline_labels_widen_the_half_labels_by_the_blur_and_keep_the_photo():
    widening = {}
    for seed in range(8):
        o, h = (render_sample(seed, 320, 240, view="front", labels=lab) for lab in ("outline", "half"))
        assert o.image.tobytes() == h.image.tobytes()
        assert (o.truth["labels"], h.truth["labels"]) == ("outline", "half")
        assert o.instances.masks.sum(0).max() <= 1
        ou, hu = o.instances.masks.any(0), h.instances.masks.any(0)
        assert not (hu & ~ou).any()  # every half-covered pixel is outlined too
        ob, hb = (s.instances.of("blade").union() for s in (o, h))
        assert ob.sum() > hb.sum()
        blur = o.truth["camera_effects"].get("blur")
        widening.setdefault(blur["kind"] if blur else "sharp", []).append(
            (ob.sum() - hb.sum()) / max(_edge_length(hb), 1))
    # Sharp photos: the partly covered pixels, under a pixel per edge pixel; a blurred photo's
    # outline reaches further.
    assert 0.1 < np.mean(widening["sharp"]) < 1.0
    blurred = widening.get("defocus", []) + widening.get("motion", [])
    assert blurred and np.mean(blurred) > np.mean(widening["sharp"])


def _edge_length(mask):
    inner = mask[1:-1, 1:-1] & mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & mask[1:-1, 2:]
    return int(mask[1:-1, 1:-1].sum() - inner.sum())


def test_dataset_files_round_trip(tmp_path):
    summary = render_dataset(tmp_path / "ds", 3, seed=4, width=160, height=120, progress=False)
    assert summary["images"] == 3
    rows = read_instances(tmp_path / "ds" / "instances.json")
    assert [img["file_name"] for img, _ in rows] == [f"images/{i:05d}.jpg" for i in range(3)]
    gt = json.loads((tmp_path / "ds" / "ground_truth.json").read_text())
    assert gt["schema"] == "wtinspect.synth_truth" and gt["schema_version"] == 1
    assert gt["params"]["labels"] == "outline"
    for i, (img, inst) in enumerate(rows):
        again = render_sample(sample_seed(4, i), 160, 120)
        assert np.array_equal(inst.masks, again.instances.masks)
        assert list(inst.labels) == list(again.instances.labels)
        truth = gt["images"][img["file_name"]]
        assert truth["seed"] == sample_seed(4, i)
        assert len(truth["instances"]) == len(inst)
        assert (tmp_path / "ds" / img["file_name"]).stat().st_size > 1000


def test_cli_json_summary_is_clean(cli, tmp_path):
    r = cli("synth", tmp_path / "out", "--count", 2, "--seed", 7, "--width", 96, "--height", 64,
            "--json")
    assert r.exit_code == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["schema"] == "wtinspect.synth_summary" and doc["images"] == 2
    assert (tmp_path / "out" / "images" / "00001.jpg").exists()


def test_cli_same_seed_same_files(cli, tmp_path):
    for name in ("a", "b"):
        assert cli("synth", tmp_path / name, "-n", 2, "-s", 3, "--width", 96, "--height", 64,
                   "--view", "front").exit_code == 0
    for f in ("images/00000.jpg", "images/00001.jpg", "instances.json"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes()


@pytest.mark.parametrize("args, code, words", [
    (["--count", "0"], ExitCode.CONFIG, "--count"),
    (["--seed", "-3"], ExitCode.CONFIG, "--seed"),
    (["--width", "5"], ExitCode.CONFIG, "--width"),
    (["--view", "top"], ExitCode.CONFIG, "--view"),
    (["--labels", "wide"], ExitCode.CONFIG, "--labels"),
])
def test_cli_bad_options(cli, tmp_path, args, code, words):
    r = cli("synth", tmp_path / "o", *args)
    assert r.exit_code == code and words in r.stderr and r.stdout == ""
    assert len(r.stderr.strip().splitlines()) == 1


def test_cli_out_is_a_file(cli, tmp_path):
    f = tmp_path / "file.txt"
    f.write_text("x")
    r = cli("synth", f, "--count", 1)
    assert r.exit_code == ExitCode.INPUT and "not a folder" in r.stderr


def test_a_dataset_replaces_a_dataset_and_nothing_else(cli, tmp_path):
    out = tmp_path / "ds"
    args = ("--width", 64, "--height", 48, "--view", "front")
    assert cli("synth", out, "-n", 3, "-s", 1, *args).exit_code == 0
    (out / "images" / ".00001.jpg.abcd1234").write_bytes(b"half")  # a kill's temporary
    r = cli("synth", out, "-n", 2, "-s", 2, *args)
    assert r.exit_code == 0, r.stderr
    # the old dataset's third image goes: the folder holds what its index lists
    assert sorted(p.name for p in (out / "images").iterdir()) == ["00000.jpg", "00001.jpg"]
    assert [img["file_name"] for img, _ in read_instances(out / "instances.json")] == [
        "images/00000.jpg", "images/00001.jpg"]
    for name, where in (("photo.JPG", "photo.JPG"), ("images/IMG_0001.jpg", "images/IMG_0001.jpg"),
                        ("labels.csv", "labels.csv")):
        folder = tmp_path / name.replace("/", "_")
        (folder / name).parent.mkdir(parents=True)
        (folder / name).write_bytes(b"someone's")
        r = cli("synth", folder, "-n", 1, *args)
        assert r.exit_code == ExitCode.INPUT and where in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1
        assert (folder / name).read_bytes() == b"someone's" and not (folder / "instances.json").exists()
    coco = tmp_path / "coco"
    (coco / "images").mkdir(parents=True)
    (coco / "images" / "00000.jpg").write_bytes(b"a user's photo")
    (coco / "instances.json").write_text('{"images": [], "annotations": [], "categories": []}')
    r = cli("synth", coco, "-n", 1, *args)
    assert r.exit_code == ExitCode.INPUT and "instances.json" in r.stderr
    assert (coco / "images" / "00000.jpg").read_bytes() == b"a user's photo"


def test_a_stopped_run_leaves_no_index_over_other_images(tmp_path, monkeypatch):
    from wtcli.synth import render as render_mod

    out = tmp_path / "ds"
    render_dataset(out, 2, seed=1, width=64, height=48, view="front", progress=False)
    calls = []

    def stop(i):
        calls.append(i)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render_mod.render_dataset(out, 2, seed=9, width=64, height=48, view="front",
                                  progress=False, on_image=stop)
    assert calls == [0] and not (out / "instances.json").exists()
    assert not (out / "ground_truth.json").exists()


@pytest.mark.parametrize("size", [(32, 32), (33, 47)])
def test_tiny_images_render_cleanly(size):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = render_sample(5, *size)
    assert s.image.shape == (size[1], size[0], 3)


def test_truth_lists_every_instance_and_distant_turbines_are_labelled():
    found_distant = False
    for seed in range(12):
        s = render_sample(seed, W, H)
        owners = s.truth["instances"]
        assert len(owners) == len(s.instances)
        for o, label in zip(owners, s.instances.labels):
            assert (o["blade"] is not None) == (label == "blade")
        main_blades = {o["blade"] for o in owners if o["turbine"] == 0 and o["blade"] is not None}
        assert {b["index"] for b in s.truth["blades"] if b["visible"]} == main_blades
        found_distant |= any(o["turbine"] > 0 for o in owners)
    assert found_distant


# ---- the wider views (opt-in: closeup, nadir, hub, cut, broadside, overtower, distant) --------
from wtcli.geometry import Camera, Turbine  # noqa: E402
from wtcli.geometry.projection import part_id_map  # noqa: E402
from wtcli.synth import ALL_VIEWS, WIDE_VIEWS, parse_view_mix  # noqa: E402
from wtcli.synth import clutter  # noqa: E402
from wtcli.synth.render import ROUND_TIP_CHORDS, blade_image_angle, draw_view  # noqa: E402

WW, WH = 200, 150


def _digest(s):
    import hashlib

    d = hashlib.sha256()
    d.update(s.image.tobytes())
    d.update(np.packbits(s.instances.masks).tobytes())
    d.update(json.dumps(list(s.instances.labels)).encode())
    d.update(json.dumps(s.truth, sort_keys=True).encode())
    return d.hexdigest()[:16]


def test_default_renders_stay_byte_identical():
    """The wider views are opt-in: the default mix and the four whole-rotor views render what
    they rendered before them (the held-out benchmark and trained models depend on it). The
    digests (image, masks, labels, truth) were taken before the wider views existed; the truth's
    turbine records have since gained the blade thickness and nacelle position keys (the
    image and mask bytes did not change).

    Two digests are pinned for two of them: numpy computes float64 sin, cos, exp and log with
    its own AVX-512 kernels on a CPU that has AVX-512 and with the C library's elsewhere, and
    the two differ in the last bit, which moves these renders' truth and edge pixels. The first
    digest of each pair was taken on an AVX-512 x86 CPU, the second on an AVX2-only one (numpy
    2.4.6; disabling AVX2 there gives the same bytes)."""
    assert _digest(render_sample(0, 96, 64)) == "95c035e899a51af5"
    assert _digest(render_sample(3, 96, 64, view="front")) in ("55599ae6657a8650", "f21b608a1a93001a")
    assert _digest(render_sample(4, 96, 64, view="rear", labels="half")) in ("4e3ad72116eed8e1",
                                                                             "9693b9516423409b")


@pytest.fixture(scope="module")
def wide_samples():
    return {v: [render_sample(s, WW, WH, view=v) for s in (1, 2)] for v in WIDE_VIEWS}


def test_wide_views_render_with_consistent_truth(wide_samples):
    assert ALL_VIEWS[:4] == ("front", "oblique", "side", "rear")  # seeds of old views unchanged
    for view, samples in wide_samples.items():
        for s in samples:
            assert s.image.shape == (WH, WW, 3) and s.image.dtype == np.uint8
            assert s.truth["view"] == view and "view_detail" in s.truth
            assert s.instances.masks.shape[1:] == (WH, WW)
            assert set(s.instances.labels) <= {"blade", "tower", "nacelle"}
            assert s.instances.masks.sum(0).max() <= 1 if len(s.instances) else True
            owners = s.truth["instances"]
            assert len(owners) == len(s.instances)
            for o, label in zip(owners, s.instances.labels):
                assert (o["blade"] is not None) == (label == "blade")
            assert any(o["turbine"] == 0 for o in owners), (view, s.truth["seed"])
    again = render_sample(2, WW, WH, view="nadir")
    assert _digest(again) == _digest(wide_samples["nadir"][1])


def test_closeup_blade_fills_the_frame_and_its_mask_is_the_projected_blade():
    """A close-up's blade mask is the blade the one geometry projects, its tip rounded as the
    wider views draw it (half-coverage labels, so no blur widens it); half of the close-ups
    have the chord across a quarter of the frame or more."""
    fills = []
    for seed in range(8):
        s = render_sample(seed, 240, 180, view="closeup", labels="half")
        t, cam = Turbine.from_dict(s.truth["turbine"]), Camera.from_dict(s.truth["camera"])
        k = s.truth["view_detail"]["blade"]
        ids = part_id_map(t, cam, t.mesh(round_tip=ROUND_TIP_CHORDS))
        masks = _main_blades(s)
        assert k in masks, seed
        m, ref = masks[k], ids == k
        iou = (m & ref).sum() / (m | ref).sum()
        assert iou > 0.93, (seed, iou)
        fills.append(m.mean())
    assert min(fills) > 0.01 and np.median(fills) > 0.08, fills
    assert sum(f > 0.25 for f in fills) >= 2, fills


def test_a_rounded_tip_stays_inside_the_blade_and_reaches_its_tip():
    """The wider views' rounded blade ends only take away from the blade's planform near the
    tip (labels never claim sky the geometry does not hold) and still end at the tip."""
    t = Turbine.with_rotor_azimuth(30.0, id="T", base=(0, 0, 0), hub_height=90, rotor_diameter=120,
                                   yaw_deg=20.0)
    flat, rnd = t.mesh(), t.mesh(round_tip=ROUND_TIP_CHORDS)
    for k in range(t.n_blades):
        d, c, n = t.blade_frame(k)
        V = rnd.vertices[np.unique(rnd.faces[rnd.face_part == k])] - t.hub_center
        s, x, y = V @ d, V @ c, V @ n
        assert s.max() == pytest.approx(t.tip_radius)
        f = (s - t.blade_root_offset) / (t.tip_radius - t.blade_root_offset)
        A, B = t.blade_semi_axes(f)
        assert ((x / A) ** 2 + (y / B) ** 2 <= 1 + 1e-6).all()
        # the last half tip chord before the cap's point: every ring narrower than the planform
        end = (s > t.tip_radius - 0.5 * t.blade_tip_chord) & (s < t.tip_radius - 1e-9)
        assert end.any() and (np.abs(x) / A)[end].max() < 0.9
    assert len(rnd.vertices) > len(flat.vertices) - 40


def test_a_tip_band_edge_runs_straight_across_the_blade():
    """Both triangles of a quad between two rings get one paint colour: a band's edge follows a
    ring, as a painted edge runs across a real blade (by face centroid the halves split and a
    close-up showed the edge as a sawtooth)."""
    from wtcli.synth.render import _shade
    from wtcli.synth.scene import Environment

    t = Turbine.with_rotor_azimuth(0.0, id="T", base=(0, 0, 0), hub_height=90, rotor_diameter=120,
                                   yaw_deg=0.0)
    m = t.mesh(round_tip=ROUND_TIP_CHORDS)
    corners = m.vertices[m.faces]
    normal = m.face_normals()
    env = Environment(sky="clear", sun_azimuth_deg=0.0, sun_elevation_deg=40.0, sun_strength=0.8,
                      backlit=False, visibility_m=2e4, cloud_cover=0.0, ground="fields",
                      sea_distance_m=None, sea_bearing_deg=0.0, hills=0,
                      turbine_albedo=(0.9, 0.9, 0.9), tip_bands=True, logo=False)
    owner = np.zeros(len(m.faces), np.int32)
    albedo, _ = _shade([t], owner, m.face_part.astype(np.int32), corners.mean(axis=1), normal,
                       env, np.random.default_rng(3), np.ones(3, np.float32),
                       np.ones(3, np.float32), corners)
    red = albedo[:, 2] > 2 * albedo[:, 0]
    for k in range(t.n_blades):
        tube = np.nonzero(m.face_part == k)[0][:-20]  # the quads; the last `around` faces: cap
        assert red[tube].any() and not red[tube].all()
        pairs = red[tube].reshape(-1, 2)  # _tube_faces writes each quad's two triangles in turn
        assert (pairs[:, 0] == pairs[:, 1]).all()

def test_recorded_blade_angles_come_from_the_geometry(wide_samples):
    for samples in wide_samples.values():
        for s in samples:
            t, cam = Turbine.from_dict(s.truth["turbine"]), Camera.from_dict(s.truth["camera"])
            for b in s.truth["blades"]:
                k = b["index"]
                assert b["phi_deg"] == pytest.approx(blade_image_angle(t, cam, k), abs=1e-9)
                ends = np.array([t.hub_center, t.blade_tips()[k]])
                if (cam.to_camera(ends)[:, 2] > 0.5).all():
                    assert b["phi_deg"] == pytest.approx(cam.image_angle_deg(*ends), abs=1e-9)
                assert b["theta_deg"] == pytest.approx(b["phi_deg"] % 180, abs=1e-9)


def test_blade_angle_along_the_blade_when_the_hub_is_behind_the_camera():
    t = Turbine.with_rotor_azimuth(0.0, id="T", base=(0, 0, 0), hub_height=100, rotor_diameter=100,
                                   yaw_deg=0.0)
    cam = Camera(640, 480, 8.8, 13.2)
    # Looking at the blade's outer half from beside the hub, the hub behind the camera.
    cam = cam.looking_at(t.hub_center + np.array([15.0, 20.0, 0.0]),
                         t.hub_center + np.array([45.0, 0.0, 0.0]))
    assert cam.to_camera(t.hub_center[None])[0, 2] < 0
    phi = blade_image_angle(t, cam, 0)
    a, b = t.hub_center + 30 * t.blade_direction(0), t.hub_center + 40 * t.blade_direction(0)
    assert phi == pytest.approx(cam.image_angle_deg(a, b), abs=1e-6)


def test_distractors_never_enter_the_masks():
    """Distractors are never labelled: with half-coverage labels every mask pixel lies on a
    projected turbine part (main, others, spare blades), and no mask pixel lies wholly under
    a structure standing in front of the turbines (redrawn from the ground truth)."""
    hidden = 0
    for seed in (2, 9, 13, 18):
        s = render_sample(seed, WW, WH, view="distant", labels="half")
        cam = Camera.from_dict(s.truth["camera"])
        front = [clutter.Structure("x", np.array(d["members"]), np.array(d["radius"]), (0, 0, 0), True)
                 for d in s.truth["distractor_members"] if d["foreground"]]
        assert front, seed
        cov = clutter.foreground_coverage(cam, front, 2).reshape(WH, 2, WW, 2).all(axis=(1, 3))
        union = s.instances.masks.any(0) if len(s.instances) else np.zeros((WH, WW), bool)
        assert not (union & cov).any(), seed
        parts = np.zeros((WH, WW), bool)
        for td in [s.truth["turbine"]] + s.truth["other_turbines"]:
            parts |= part_id_map(Turbine.from_dict(td), cam) >= 0
        grown = cv2.dilate(parts.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        assert not (union & ~grown).any(), seed
        hidden += int((parts & cov).sum())
    assert hidden > 0  # some structure does stand in front of a turbine


def test_nadir_spare_blades_lie_on_the_ground_labelled_as_blades():
    found = 0
    for seed in (0, 3, 6):
        s = render_sample(seed, WW, WH, view="nadir")
        assert s.truth["view_detail"]["camera_pitch_deg"] <= -50
        spares = [Turbine.from_dict(d) for d in s.truth["spare_blades"]]
        assert len(spares) == s.truth["view_detail"]["spare_blades"] >= 2
        for sp in spares:
            z = clutter.blade_mesh(sp, 20, 40).vertices[:, 2]
            assert -1e-6 < z.min() < 0.2  # resting on the ground, not in it
            assert abs(sp.blade_direction(0)[2]) < 1e-9  # flat
        for o, label in zip(s.truth["instances"], s.instances.labels):
            if o["turbine_id"].startswith("S"):
                assert label == "blade"
                found += 1
    assert found >= 4


def test_view_mix_shares_and_determinism():
    assert parse_view_mix("front,closeup") == {"front": 0.5, "closeup": 0.5}
    assert parse_view_mix({"nadir": 3, "hub": 1}) == {"nadir": 0.75, "hub": 0.25}
    mixed = parse_view_mix("mixed=0.5,distant=0.5")
    assert mixed["distant"] == 0.5 and mixed["front"] == pytest.approx(0.21)
    for bad, words in (("", "at least one"), ("top", "'top'"), ("front=x", "number"),
                       ("front=-1", "share"), ("front=0", "positive"),
                       ("mixed=-1", "for mixed"), ("mixed=1e400", "for mixed"),
                       ("nadir=nan", "for nadir"), ("front=1e300,hub=1e300", "share"),
                       ({"hub": True}, "for hub")):
        with pytest.raises(ValueError, match=words):
            parse_view_mix(bad)
    mix = parse_view_mix("closeup=0.7,nadir=0.3")
    draws = [draw_view(i, WW, WH, mix) for i in range(200)]
    assert 120 <= draws.count("closeup") <= 160
    a = render_sample(5, 96, 64, view_mix=mix)
    b = render_sample(5, 96, 64, view=draw_view(5, 96, 64, mix))
    assert a.image.tobytes() == b.image.tobytes() and a.truth["view_mix"] == mix
    with pytest.raises(ValueError, match="both"):
        render_sample(5, 96, 64, view="front", view_mix=mix)


def test_cli_view_mix(cli, tmp_path):
    r = cli("synth", tmp_path / "m", "-n", 2, "-s", 1, "--width", 96, "--height", 64,
            "--view-mix", "closeup,nadir", "--json")
    assert r.exit_code == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["view"] == "mix" and doc["view_mix"] == {"closeup": 0.5, "nadir": 0.5}
    assert sum(doc["views"].values()) == 2 and set(doc["views"]) <= {"closeup", "nadir"}
    for args in (["--view-mix", "top"], ["--view-mix", "front=x"], ["--view", "front", "--view-mix", "nadir"]):
        r = cli("synth", tmp_path / "o", *args)
        assert r.exit_code == ExitCode.CONFIG and "--view-mix" in r.stderr and r.stdout == ""
        assert len(r.stderr.strip().splitlines()) == 1


def test_wide_views_render_tiny_images_cleanly():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for view in WIDE_VIEWS:
            assert render_sample(1, 33, 47, view=view).image.shape == (47, 33, 3)


def test_cut_views_cut_their_part_at_the_named_edge():
    """A 'cut' frame's nacelle (with the hub) reaches the frame edge its truth names."""
    checked = 0
    for seed in range(12):
        s = render_sample(seed, WW, WH, view="cut", labels="half")
        d = s.truth["view_detail"]
        if d["cut"] not in ("nacelle", "hub"):
            continue
        nac = [s.instances.masks[i] for i, o in enumerate(s.truth["instances"])
               if o["turbine"] == 0 and s.instances.labels[i] == "nacelle"]
        assert nac, seed
        m = nac[0]
        edge = {"left": m[:, 0], "right": m[:, -1], "top": m[0], "bottom": m[-1]}[d["edge"]]
        assert edge.any(), (seed, d)
        checked += 1
    assert checked >= 4


def test_scene_sampler_takes_the_view_mix():
    from wtcli.synth.scene import sample_scene

    views = [sample_scene(np.random.default_rng(i), 160, 120, None,
                          view_mix={"nadir": 0.5, "front": 0.5}).view for i in range(24)]
    assert set(views) == {"nadir", "front"}
    plain = sample_scene(np.random.default_rng(3), 160, 120, None)
    again = sample_scene(np.random.default_rng(3), 160, 120, None, view_mix=None)
    assert plain.to_dict() == again.to_dict() and plain.spares == () and plain.detail == {}
