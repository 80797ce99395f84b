"""Hostile but realistic inputs and faults, each run through the command line as a user would.

Every case builds its input here (tiny images, hand-edited JSON and YAML, blocked or full
output locations, kills between write and rename) and asserts three things: the exit code
``docs/exit-codes.md`` documents, one message line on stderr naming the file, and the state of
the output folder afterwards (nothing stale, nothing half-written, nothing lost). No case may
end in the catch-all exit 1. The model runs only where the case is about segmenting (random
weights, 64 x 48 photos, no refiner, zoom or flip).
"""

from __future__ import annotations

import errno
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_images"
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0
FAST = ("--no-refine", "--no-zoom", "--no-flip", "--score-threshold", "0.0")


def one_error_line(result, code: int, *names: str, alone: bool = False) -> str:
    """The command ended with ``code`` and one stderr line (after any table or progress
    output; with ``alone``, nothing else at all) starting "error:" and naming every one of
    ``names``; returns that line."""
    assert result.exit_code == code, (result.exit_code, result.stderr[-800:])
    if alone:
        assert result.stderr.count("\n") == 1, result.stderr[-800:]
    assert "unexpected error" not in result.stderr and "Traceback" not in result.stderr
    lines = [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, result.stderr[-800:]
    assert result.stderr.rstrip("\n").endswith(lines[0])  # the last thing said, on one line
    for n in names:
        assert str(n) in lines[0], (n, lines[0])
    return lines[0]


def temp_leftovers(folder: Path) -> list[Path]:
    return [p for p in folder.rglob(".*") if p.is_file()]


# ---- fixtures --------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def weights(tmp_path_factory) -> Path:
    from wtcli.segment.model import build_model, save_weights

    torch.manual_seed(0)
    path = tmp_path_factory.mktemp("w") / "random.pt"
    save_weights(build_model(), path, meta={"note": "random"})
    return path


@pytest.fixture(scope="module")
def nan_weights(tmp_path_factory) -> Path:
    from wtcli.segment.model import build_model, save_weights

    torch.manual_seed(0)
    model = build_model()
    with torch.no_grad():
        next(model.parameters()).view(-1)[0] = float("nan")
    path = tmp_path_factory.mktemp("w") / "nan.pt"
    save_weights(model, path)
    return path


def _photo(path: Path, seed: int = 0, h: int = 48, w: int = 64) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.random.default_rng(seed).integers(0, 255, (h, w, 3), dtype=np.uint8))
    return path


@pytest.fixture
def photos(tmp_path) -> Path:
    d = tmp_path / "photos"
    _photo(d / "a.png", 1)
    _photo(d / "b.jpg", 2)
    return d


@pytest.fixture(scope="module")
def instances_doc() -> dict:
    return json.loads((SAMPLE / "instances.json").read_text())


def _write(path: Path, doc) -> Path:
    path.write_text(json.dumps(doc))
    return path


# ---- outputs: blocked, read-only, full, killed -------------------------------------------------
def test_segment_out_blocked_fails_before_the_model(cli, photos, tmp_path):
    # a file where the folder should be: exit 3 at once; the weights are not even looked at
    # (a missing weights file would otherwise give exit 7)
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    r = cli("segment", photos, "--out", blocker / "out", "--model", tmp_path / "none.pt")
    one_error_line(r, 3, blocker)
    r = cli("segment", photos, "--out", blocker, "--model", tmp_path / "none.pt")
    one_error_line(r, 3, blocker)
    assert blocker.read_text() == "x"


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc")
def test_read_only_location_fails_before_the_work(cli, photos, tmp_path):
    ro = Path("/proc/wtinspect-out")  # no process may create anything there, root included
    one_error_line(cli("segment", photos, "--out", ro, "--model", tmp_path / "none.pt"), 3, ro)
    one_error_line(cli("synth", ro, "--count", "1"), 3, ro)
    one_error_line(cli("contours", SAMPLE / "instances.json", "--out", ro / "c.json"), 3, ro)
    one_error_line(cli("pitch", SAMPLE / "instances.json", "--out", ro / "p.json"), 3, ro)
    t0 = time.monotonic()
    one_error_line(cli("plan", SAMPLE / "turbines.yaml", "--out", ro / "p.json"), 3, ro)
    assert time.monotonic() - t0 < 5  # refused before planning
    one_error_line(cli("train", "--out", ro, "--iterations", "1"), 3, ro)
    one_error_line(cli("train-refiner", "--out", ro), 3, ro)


def test_out_is_a_folder_or_under_a_file(cli, tmp_path):
    folder = tmp_path / "d"
    folder.mkdir()
    one_error_line(cli("contours", SAMPLE / "instances.json", "--out", folder), 3, folder)
    f = tmp_path / "f"
    f.write_text("")
    one_error_line(cli("synth", f, "--count", "1"), 3, f)
    one_error_line(cli("plan", SAMPLE / "turbines.yaml", "--out", f / "p.json"), 3, f)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d", "f"] and not any(folder.iterdir())


def test_an_output_through_a_link_is_written_there_and_a_pipe_is_not_replaced(cli, tmp_path):
    target = tmp_path / "real" / "contours.json"
    target.parent.mkdir()
    target.write_text("{}")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    assert cli("contours", SAMPLE / "instances.json", "--out", link).exit_code == 0
    assert link.is_symlink() and json.loads(target.read_text())["schema"] == "wtinspect.contours"
    pipe = tmp_path / "pipe.json"
    os.mkfifo(pipe)
    one_error_line(cli("contours", SAMPLE / "instances.json", "--out", pipe), 3, pipe)
    assert pipe.is_fifo()  # not replaced by a file
    from wtcli.errors import OutputError
    from wtcli.jsonio import atomic_write_bytes
    with pytest.raises(OutputError, match="not a regular file"):
        atomic_write_bytes(pipe, b"x")  # the write itself refuses too, not only the check first


def test_disk_full_stops_the_batch_naming_the_file_and_leaves_no_temporaries(cli, photos, weights,
                                                                             tmp_path, monkeypatch):
    out = tmp_path / "out"
    real_replace = os.replace

    def full(src, dst, *a, **k):  # the disk fills up when the overlays are written
        if str(dst).endswith(".png") and "overlay" in str(dst):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_replace(src, dst, *a, **k)

    monkeypatch.setattr("wtcli.jsonio.os.replace", full)
    r = cli("segment", photos, "--out", out, "--model", weights, *FAST)
    # Every later photo would fail the same way after the network ran: the batch stops, exit 3.
    assert r.exit_code == 3, r.stderr[-500:]
    assert "overlay/a.png: cannot write (No space left on device)" in r.stderr.splitlines()[-1]
    assert "stopped with 2 photo(s) not done" in r.stderr  # a.png, where it stopped, and b.jpg
    report = json.loads((out / "report.json").read_text())
    errors = {im["file"]: im["error"] for im in report["images"]}
    assert list(errors) == ["a.png"], errors
    assert "overlay/a.png: cannot write (No space left on device)" in errors["a.png"]
    assert temp_leftovers(out) == []
    assert not (out / "instances.json").exists() and report["instances"] is None


def test_resume_removes_temporaries_of_a_kill_and_redoes_a_damaged_photo(cli, photos, weights,
                                                                         tmp_path):
    out = tmp_path / "out"
    assert cli("segment", photos, "--out", out, "--model", weights, *FAST).exit_code == 0
    # SIGKILL between write and rename leaves .NAME.XXXXXXXX beside the file
    left = [out / "overlay" / ".a.png.k2j4_x9q", out / "instances" / ".b.json.abcd1234",
            out / ".report.json.zz11yy22"]
    for p in left:
        p.write_bytes(b"half")
    keep = out / "overlay" / ".notes.txt"  # a hidden file of the user's: not ours, kept
    keep.write_text("mine")
    (out / "instances" / "a.json").write_text('{"images": [')  # damaged: redo it, do not drop it
    r = cli("segment", photos, "--out", out, "--model", weights, "--resume", *FAST)
    assert r.exit_code == 0, r.stderr[-500:]
    assert temp_leftovers(out) == [keep]
    report = json.loads((out / "report.json").read_text())
    assert {im["file"]: im["status"] for im in report["images"]} == {"a.png": "ok", "b.jpg": "skipped"}
    files = {im["file_name"] for im in json.loads((out / "instances.json").read_text())["images"]}
    assert files == {"a.png", "b.jpg"}


def test_rerun_where_every_photo_fails_leaves_no_stale_instances(cli, photos, weights, tmp_path):
    out = tmp_path / "out"
    assert cli("segment", photos, "--out", out, "--model", weights, *FAST).exit_code == 0
    assert (out / "instances.json").is_file()
    for p in photos.iterdir():
        p.write_bytes(b"not an image any more")
    r = cli("segment", photos, "--out", out, "--model", weights, *FAST)
    assert r.exit_code == 9
    report = json.loads((out / "report.json").read_text())
    assert report["instances"] is None and report["n_failed"] == 2
    assert not (out / "instances.json").exists()  # contours cannot read the old run's data


def test_a_summary_that_cannot_be_written_is_said_beside_what_stopped_the_batch(
        cli, photos, weights, tmp_path, monkeypatch):
    """The disk fills at the last photo's overlay and stays full for the summary: the line says
    what stopped the batch, that the photo it stopped at is not done, that the summary was not
    written, and that --resume goes on."""
    out = tmp_path / "out"
    real_replace = os.replace
    full = {"overlay/b.png", "instances.json", "report.json"}

    def filling(src, dst, *a, **k):
        if any(str(dst).endswith(f"out/{name}") for name in full):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_replace(src, dst, *a, **k)

    monkeypatch.setattr("wtcli.jsonio.os.replace", filling)
    r = cli("segment", photos, "--out", out, "--model", weights, *FAST)
    line = one_error_line(r, 3, "overlay/b.png: cannot write (No space left on device)",
                          "stopped with 1 photo(s) not done", "instances.json", "--resume")
    assert "summary could not be written" in line
    assert not (out / "report.json").exists() and temp_leftovers(out) == []
    # Every photo done, only the summary failing: said so, with how to write it.
    full = {"report.json"}
    r = cli("segment", photos, "--out", out, "--model", weights, *FAST)
    one_error_line(r, 3, "report.json: cannot write (No space left on device)",
                   "2 photo(s) segmented are kept", "--resume")


def test_segment_clears_only_its_own_temporaries(cli, photos, weights, tmp_path):
    """A kill leaves .NAME.XXXXXXXX temporaries; a rerun removes those in segment's own
    subfolders and of its own two files, and nothing else under --out: another program's
    in-flight write or a user's hidden file of that shape is not segment's to delete."""
    out = tmp_path / "out"
    ours = [out / "overlay" / ".a.png.k2j4_x9q", out / "instances" / ".b.json.abcd1234",
            out / ".report.json.zz11yy22", out / ".instances.json.q1w2e3r4"]
    theirs = [out / "notes" / ".survey.json.ab12cd34", out / "other_run" / ".photo.png.zz99yy88",
              out / ".summary.json.ab12cd34"]
    for p in ours + theirs:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(b"half")
    r = cli("segment", photos, "--out", out, "--model", weights, *FAST)
    assert r.exit_code == 0, r.stderr[-500:]
    assert sorted(temp_leftovers(out)) == sorted(theirs)


def test_a_legal_name_near_the_limit_is_written_through_a_temporary_that_fits(tmp_path):
    from wtcli.jsonio import atomic_write_bytes, temp_prefix
    from wtcli.outputs import _TEMP_NAME, remove_temp_files

    for name in ("p" * 250 + ".json", "é" * 125 + ".png", "x" * 255):
        path = atomic_write_bytes(tmp_path / name, b"data")
        assert path.read_bytes() == b"data" and temp_leftovers(tmp_path) == []
        assert len(os.fsencode(temp_prefix(name) + "abcd1234")) <= 255
    # a cut temporary keeps its extension, so a rerun still knows it for one of ours
    left = tmp_path / (temp_prefix("p" * 250 + ".json") + "abcd1234")
    left.write_bytes(b"half")
    assert _TEMP_NAME.match(left.name) and remove_temp_files(tmp_path) == [left]
    # every kind of file a command writes is known by its temporary (site's YAML, exports, parts)
    for name in ("turbines.yaml", "site.geojson", "part-0000.npz", "00000.jpg", "m.kmz"):
        assert _TEMP_NAME.match(temp_prefix(name) + "abcd1234"), name


# ---- unreadable and odd inputs -----------------------------------------------------------------
def test_broken_and_looping_links_are_reported_not_skipped(cli, photos, weights, tmp_path):
    (photos / "gone.jpg").symlink_to(photos / "missing.jpg")
    (photos / "loop.png").symlink_to(photos / "loop.png")
    out = tmp_path / "out"
    r = cli("segment", photos, "--out", out, "--model", weights, *FAST)
    assert r.exit_code == 9, r.stderr[-500:]
    report = {im["file"]: im for im in json.loads((out / "report.json").read_text())["images"]}
    assert {f: im["status"] for f, im in report.items()} == {
        "a.png": "ok", "b.jpg": "ok", "gone.jpg": "error", "loop.png": "error"}
    assert "gone.jpg: broken symbolic link" in report["gone.jpg"]["error"]
    assert "loop.png: cannot read (Too many levels of symbolic links)" in report["loop.png"]["error"]
    one_error_line(cli("segment", photos / "gone.jpg", "--out", out), 3, "gone.jpg")


def _without_root_privilege() -> list[str] | None:
    """A command prefix under which file permissions bind (root without its DAC override
    capabilities, via setpriv), [] when not root, None where that cannot be had."""
    if not IS_ROOT:
        return []
    import shutil

    if shutil.which("setpriv") is None:
        return None
    prefix = ["setpriv", "--bounding-set", "-dac_override,-dac_read_search"]
    probe = Path(os.environ.get("TMPDIR", "/tmp")) / f".wtinspect-perm-probe-{os.getpid()}"
    probe.write_text("x")
    probe.chmod(0)
    try:
        ok = subprocess.run([*prefix, "cat", str(probe)], capture_output=True).returncode != 0
    except OSError:
        ok = False
    finally:
        probe.unlink()
    return prefix if ok else None


def test_unreadable_photo_and_folders_exit_3(photos, tmp_path):
    prefix = _without_root_privilege()
    if prefix is None:
        pytest.skip("cannot drop root's permission override here")

    def wtinspect(*args):
        return subprocess.run([*prefix, sys.executable, "-m", "wtcli", *map(str, args)],
                              capture_output=True, text=True, cwd=ROOT, timeout=300)

    out = tmp_path / "out"
    photo = photos / "a.png"
    photo.chmod(0)
    try:  # typer's own check would say exit 2 with a usage box
        for cmd in (["segment", photo, "--out", out], ["contours", photo], ["pitch", photo]):
            r = wtinspect(*cmd)
            assert r.returncode == 3 and r.stderr == f"error: {photo}: cannot read (permission denied)\n", r.stderr
    finally:
        photo.chmod(0o644)
    for mode, says in ((0, "cannot read (permission denied)"),
                       (0o600, "cannot list the folder (Permission denied)")):
        photos.chmod(mode)  # no permission at all; read but no execute (search)
        try:
            r = wtinspect("segment", photos, "--out", out)
        finally:
            photos.chmod(0o755)
        assert r.returncode == 3 and r.stderr == f"error: {photos}: {says}\n", r.stderr
    assert not out.exists() or not any(out.iterdir())  # nothing was written
    ro = tmp_path / "read-only"
    ro.mkdir(mode=0o555)
    try:  # refused before the model loads: the weights named do not exist (else exit 7)
        r = wtinspect("segment", photos, "--out", ro / "seg", "--model", tmp_path / "none.pt")
        assert r.returncode == 3 and r.stderr.startswith(f"error: {ro / 'seg'}: cannot write there (permission denied)"), r.stderr
        r = wtinspect("contours", SAMPLE / "instances.json", "--out", ro / "c.json")
        assert r.returncode == 3 and r.stderr.startswith(f"error: {ro / 'c.json'}: cannot write (permission denied"), r.stderr
    finally:
        ro.chmod(0o755)
    assert not any(ro.iterdir())


def test_unreadable_photo_and_folder_exit_3_simulated(cli, photos, weights, tmp_path, monkeypatch):
    # The same cases under root, which permissions do not stop: the OS answers EACCES.
    out = tmp_path / "out"
    real_fromfile, real_iterdir = np.fromfile, Path.iterdir

    def fromfile(f, *a, **k):
        if str(f).endswith("a.png"):
            raise PermissionError(errno.EACCES, "Permission denied", str(f))
        return real_fromfile(f, *a, **k)

    def iterdir(self):
        if self == photos:
            raise PermissionError(errno.EACCES, "Permission denied", str(self))
        return real_iterdir(self)

    monkeypatch.setattr("wtcli.segment.batch.np.fromfile", fromfile)
    r = cli("segment", photos / "a.png", "--out", out, "--model", weights, *FAST)
    line = one_error_line(r, 3, photos / "a.png")
    assert "Permission denied" in line
    monkeypatch.setattr(Path, "iterdir", iterdir)
    line = one_error_line(cli("segment", photos, "--out", out, "--model", weights), 3, photos)
    assert "cannot list the folder (Permission denied)" in line


def _png_bomb(path: Path) -> Path:
    """A PNG header declaring 100000 x 100000 pixels on a few bytes."""
    import struct
    import zlib

    ihdr = struct.pack(">IIBBBBB", 100_000, 100_000, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + ihdr
                     + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr)) + bytes(64))
    return path


def test_tiny_and_huge_photos_are_named(cli, weights, tmp_path):
    one = _photo(tmp_path / "one.png", h=1, w=1)
    one_error_line(cli("segment", one, "--out", tmp_path / "o", "--model", weights, *FAST), 3, one)
    bomb = _png_bomb(tmp_path / "bomb.png")
    line = one_error_line(cli("segment", bomb, "--out", tmp_path / "o", "--model", weights, *FAST),
                          3, bomb)
    assert "100000x100000" in line and "200,000,000" in line


def test_nan_weights_are_refused_at_load(cli, photos, nan_weights, tmp_path):
    out = tmp_path / "out"
    line = one_error_line(cli("segment", photos, "--out", out, "--model", nan_weights), 7, nan_weights)
    assert "NaN or infinite" in line
    assert not (out / "instances.json").exists() and not (out / "report.json").exists()


def test_code_carrying_weights_message_is_ours(cli, photos, tmp_path):
    class Evil:
        def __reduce__(self):
            return (os.system, ("echo owned",))

    evil = tmp_path / "evil.pt"
    torch.save({"state_dict": Evil()}, evil)
    line = one_error_line(cli("segment", photos, "--out", tmp_path / "o", "--model", evil), 7, evil)
    assert "could run code" in line and "weights_only" not in line and "two options" not in line


# ---- instances JSON: versions, numbers, sizes --------------------------------------------------
def _edited(doc: dict, edit) -> dict:
    d = json.loads(json.dumps(doc))
    edit(d)
    return d


INSTANCES_CASES = {
    "version99": (lambda d: d.update(schema_version=99), "schema_version 99"),
    "version0": (lambda d: d.update(schema_version=0), "schema_version"),
    "other_schema": (lambda d: d.update(schema="wtinspect.plan"), "got schema 'wtinspect.plan'"),
    "nan_score": (lambda d: d["annotations"][0].update(score=float("nan")), "NaN is not a finite"),
    "inf_bbox": (lambda d: d["annotations"][0]["bbox"].__setitem__(0, float("inf")),
                 "Infinity is not a finite"),
    "score_2": (lambda d: d["annotations"][0].update(score=2), "score: expected a number in [0, 1], got 2"),
    "negative_width": (lambda d: d["annotations"][0]["bbox"].__setitem__(2, -5), "got -5"),
    "short_bbox": (lambda d: d["annotations"][0].update(bbox=[1, 2]),
                   "bbox: expected [x, y, width, height], got [1, 2]"),
    "huge_image": (lambda d: d["images"][0].update(width=200_000, height=200_000),
                   "200000x200000 is 40,000,000,000 pixels"),
    "zero_width": (lambda d: d["images"][0].update(width=0), "width: expected an integer >= 1, got 0"),
    "negative_rle": (lambda d: d["annotations"][0]["segmentation"]["counts"].__setitem__(1, -7),
                     "counts[1]: expected an integer in [0, 307200], got -7"),
    "nan_polygon": (lambda d: d["annotations"][0].update(segmentation=[[1, 2, 30, 2, 30, "x"]]),
                    "got 'x'"),
    "far_polygon": (lambda d: d["annotations"][0].update(segmentation=[[1, 2, 1e12, 2, 30, 40]]),
                    "got 1000000000000.0"),
    "list_image_id": (lambda d: d["annotations"][0].update(image_id=[1]), "got [1]"),
    "category_9": (lambda d: d["annotations"][0].update(category_id=9), "category_id"),
    "file_name_5": (lambda d: d["images"][0].update(file_name=5), "file_name: expected a file name"),
    "file_name_long": (lambda d: d["images"][0].update(file_name="x" * 5000), "got 'xxxxx"),
}


@pytest.mark.parametrize("case", sorted(INSTANCES_CASES))
@pytest.mark.parametrize("command", ["contours", "pitch"])
def test_hostile_instances_json(cli, instances_doc, tmp_path, case, command):
    edit, says = INSTANCES_CASES[case]
    src = _write(tmp_path / f"{case}.json", _edited(instances_doc, edit))
    # (json.dumps writes float("nan") as NaN and float("inf") as Infinity, as some tools do)
    out = tmp_path / "out.json"
    line = one_error_line(cli(command, src, "--out", out), 3, src, alone=True)
    assert says in line, line
    assert len(line) < 400 and not out.exists()


CONTOURS_CASES = {
    "version7": (lambda d: d.update(schema_version=7), "schema_version 7"),
    "far_point": (lambda d: d["images"][0]["instances"][0]["contours"][0].__setitem__(0, [1e12, 5]),
                  "contours[0]: expected [x, y] integer pixel points"),
    "fraction_point": (lambda d: d["images"][0]["instances"][0]["contours"][0].__setitem__(0, [1.5, 5]),
                       "got [[1.5, 5]"),
    "huge_image": (lambda d: d["images"][0].update(image_size=[200_000, 200_000]),
                   "over the limit of 200,000,000"),
    "instances_5": (lambda d: d["images"][0].update(instances=5), "instances: expected a list, got 5"),
    "score_7": (lambda d: d["images"][0]["instances"][0].update(score=7), "expected score in [0, 1]"),
    "image_5": (lambda d: d["images"][0].update(image=5), "images[0].image: expected an object, got 5"),
    "images_5": (lambda d: d.update(images=5), "expected an 'images' list"),
    # a source that is not a path used to fail (exit 1) before the file was checked
    "source_5": (lambda d: d.update(source=5, images=5), "expected an 'images' list"),
}


@pytest.fixture(scope="module")
def contours_doc(tmp_path_factory) -> dict:
    from typer.testing import CliRunner

    from wtcli.cli import app

    out = tmp_path_factory.mktemp("c") / "c.json"
    r = CliRunner().invoke(app, ["contours", str(SAMPLE / "instances.json"), "--out", str(out)])
    assert r.exit_code == 0, r.stderr
    return json.loads(out.read_text())


@pytest.mark.parametrize("case", sorted(CONTOURS_CASES))
def test_hostile_contours_json(cli, contours_doc, tmp_path, case):
    edit, says = CONTOURS_CASES[case]
    src = _write(tmp_path / f"{case}.json", _edited(contours_doc, edit))
    out = tmp_path / "pitch.json"
    line = one_error_line(cli("pitch", src, "--out", out), 3, src, alone=True)
    assert says in line, line
    assert not out.exists()


def test_corrupt_mask_png_is_one_line(cli, tmp_path):
    bad = tmp_path / "mask.png"
    bad.write_bytes(b"\x89PNG\r\n\x1a\nxxxx")  # OpenCV logs its own complaint unless silenced
    one_error_line(cli("contours", bad), 3, bad, alone=True)
    one_error_line(cli("pitch", bad), 3, bad, alone=True)
    bomb = _png_bomb(tmp_path / "blade_bomb.png")
    assert "100000x100000" in one_error_line(cli("contours", bomb), 3, bomb, alone=True)


def test_number_past_float_range_and_deep_nesting(cli, instances_doc, tmp_path):
    src = _write(tmp_path / "big.json", instances_doc)
    src.write_text(src.read_text().replace('"score": 1.0', '"score": 1e400', 1))
    assert "1e400 is not a finite number" in one_error_line(cli("contours", src), 3, src)
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    one_error_line(cli("contours", deep), 3, deep)


# ---- YAML ------------------------------------------------------------------------------------
def _yaml(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


BOMB = "".join(f"{c}: &{c} [" + ", ".join([f"*{p}"] * 9 if p else ['"lol"'] * 9) + "]\n"
               for p, c in zip([None, *"abcdefgh"], "abcdefghi"))


def test_alias_bomb_refused_within_1_s_and_200_mb(tmp_path):
    from wtcli.errors import ConfigError
    from wtcli.yamlcheck import load_yaml

    for where in ("fleet:\n  uavs: *i\n", "turbines:\n  - id: T1\n    blade_azimuths_deg: *i\n"):
        bomb = _yaml(tmp_path, "bomb.yaml", BOMB + where)
        assert len(bomb.read_bytes()) < 1500  # ~1 KB expanding to 9**9 = 387 million strings
        # The whole process, interpreter and imports included, under a 2 GiB address-space cap
        # Peak RSS from VmHWM, which starts afresh at exec (ru_maxrss keeps pytest's peak).
        code = ("import resource, sys, time\n"
                "resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))\n"
                "from wtcli.cli import main\n"
                "t0 = time.monotonic()\n"
                "try:\n"
                f"    main(['plan', {str(bomb)!r}, '--out', {str(tmp_path / 'p.json')!r}])\n"
                "except SystemExit as e:\n"
                "    rc = e.code\n"
                "hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM')][0]\n"
                "print(rc, time.monotonic() - t0, int(hwm.split()[1]) // 1024)\n")
        run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             cwd=ROOT, timeout=120)
        rc, seconds, peak_mb = run.stdout.split()
        assert int(rc) == 4, run.stderr
        assert "holds over 100,000 values once its aliases are expanded" in run.stderr
        assert float(seconds) < 1.0 and int(peak_mb) < 200, (seconds, peak_mb)
        assert not (tmp_path / "p.json").exists()
    # and in the loading itself, measured by tracemalloc
    import tracemalloc

    tracemalloc.start()
    t0 = time.monotonic()
    with pytest.raises(ConfigError, match="alias bomb"):
        load_yaml(bomb)
    took = time.monotonic() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert took < 1.0 and peak < 20e6, (took, peak)


def test_yaml_duplicate_keys_and_self_reference(cli, tmp_path):
    text = (SAMPLE / "turbines.yaml").read_text()
    dup = _yaml(tmp_path, "dup.yaml", text + "turbines:\n  - id: T9\n    position: [0, 0, 0]\n")
    line = one_error_line(cli("plan", dup), 4, dup)
    assert "duplicate key 'turbines'" in line and "first given on line" in line
    loop = _yaml(tmp_path, "loop.yaml", "mission: &m {x: *m}\n")
    assert "refers to the value it is part of" in one_error_line(cli("plan", loop), 4, loop)


def test_yaml_value_in_brackets_is_shown(cli, tmp_path):
    text = (SAMPLE / "turbines.yaml").read_text().replace("position: [0.0, 0.0, 0.0]",
                                                           "position: [.nan, 0, 0]")
    bad = _yaml(tmp_path, "nan.yaml", text)
    line = one_error_line(cli("plan", bad), 4, bad.name)
    assert line.endswith("[nan, 0, 0]"), line  # not swallowed as console markup


def test_plan_options(cli, tmp_path):
    line = one_error_line(cli("plan", SAMPLE / "turbines.yaml", "--camera-pose", "inf,0,0,0,0,80"),
                          4, "--camera-pose")
    assert "'inf,0,0,0,0,80'" in line
    inst = SAMPLE / "instances.json"
    line = one_error_line(cli("plan", SAMPLE / "turbines.yaml", f"T9={inst}"), 2, f"T9={inst}")
    assert "no turbine 'T9'" in line and "T1, T2" in line


# ---- plan files ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def plan_doc(tmp_path_factory) -> dict:
    from wtcli.cli import app
    from typer.testing import CliRunner

    out = tmp_path_factory.mktemp("plan") / "plan.json"
    r = CliRunner().invoke(app, ["plan", str(SAMPLE / "turbines.yaml"), "--out", str(out)])
    assert r.exit_code == 0, r.stderr
    return json.loads(out.read_text())


PLAN_CASES = {
    "version2": (lambda d: d.update(schema_version=2), "schema_version 2"),
    "safe_distance_0": (lambda d: d.update(safe_distance_m=0), "safe_distance_m: expected"),
    "hub_1e300": (lambda d: d["turbines"][0].update(hub_height=1e300),
                  "turbines[0].hub_height: expected a number in [1, 1000], got 1e+300"),
    "speed_negative": (lambda d: d["routes"][0]["waypoints"][3].update(speed=-2),
                       "routes[0].waypoints[3].speed"),
    "pos_text": (lambda d: d["routes"][0]["waypoints"][3].update(pos="x"), "invalid plan"),
    "no_routes": (lambda d: d.pop("routes"), "missing key 'routes'"),
    # a waypoint moved 100 km by hand: refused before flying (the flight would take minutes)
    "waypoint_100km": (lambda d: d["routes"][0]["waypoints"][5]["pos"].__setitem__(0, 1e5),
                       "routes[0].waypoints[5] is"),
}


@pytest.mark.parametrize("case", sorted(PLAN_CASES))
def test_hostile_plan_file(cli, plan_doc, tmp_path, case):
    edit, says = PLAN_CASES[case]
    src = _write(tmp_path / f"{case}.json", _edited(plan_doc, edit))
    out = tmp_path / "report.json"
    line = one_error_line(cli("fly", src, "--scenario", "tiny", "--out", out), 3, src)
    assert says in line, line
    assert not out.exists()


def test_plan_file_with_nan_is_refused(cli, plan_doc, tmp_path):
    src = _write(tmp_path / "nan.json", plan_doc)
    src.write_text(src.read_text().replace('"safe_distance_m": 3.0', '"safe_distance_m": NaN'))
    assert "NaN" in one_error_line(cli("fly", src, "--scenario", "tiny"), 3, src)


# ---- train -----------------------------------------------------------------------------------
def test_train_options_and_damaged_checkpoint(cli, tmp_path):
    one_error_line(cli("train", "--sizes", "abc", "--out", tmp_path / "r"), 4, "--sizes")
    run = tmp_path / "run"
    run.mkdir()
    torch.save({"arch": "x"}, run / "last.ckpt")  # an edited checkpoint: no weights, no step
    line = one_error_line(cli("train", "--out", run, "--resume", "--iterations", "1",
                              "--device", "cpu"), 7, run / "last.ckpt")
    assert "state_dict" in line


def test_names_in_square_brackets_are_printed_as_written(cli, tmp_path):
    out = tmp_path / "[red]c[/red] [1].json"
    r = cli("contours", SAMPLE / "instances.json", "--out", out)
    # (rich wraps this note at 80 columns: compare with the line breaks taken out)
    assert r.exit_code == 0 and " ".join(f"-> {out}".split()) in " ".join(r.stderr.split()), r.stderr
    missing = tmp_path / "[bold]gone[/bold].json"
    one_error_line(cli("contours", missing), 3, missing, alone=True)


def test_corrupt_refiner_weights_are_refused(cli, photos, weights, tmp_path):
    from wtcli.segment.refine import ARCH, Refiner

    ref = Refiner((8, 4))
    state = {k: v.clone() for k, v in ref.state_dict().items()}
    next(v for v in state.values() if v.is_floating_point()).view(-1)[0] = float("nan")
    nan = tmp_path / "nan-refiner.pt"
    torch.save({"arch": ARCH, "hidden": [8, 4], "state_dict": state}, nan)
    wide = tmp_path / "wide-refiner.pt"  # would allocate a 10^9-wide layer before any check
    torch.save({"arch": ARCH, "hidden": [10**9], "state_dict": {}}, wide)
    for bad, says in ((nan, "NaN or infinite"), (wide, "are not 1..8192")):
        r = cli("segment", photos, "--out", tmp_path / "o", "--model", weights, "--refiner", bad)
        assert says in one_error_line(r, 7, bad)


@pytest.fixture(scope="module")
def pitch_file(tmp_path_factory) -> dict:
    from typer.testing import CliRunner

    from wtcli.cli import app

    out = tmp_path_factory.mktemp("p") / "pitch.json"
    r = CliRunner().invoke(app, ["pitch", str(SAMPLE / "instances.json"), "--out", str(out)])
    assert r.exit_code == 0, r.stderr
    return json.loads(out.read_text())


PITCH_CASES = {
    "version9": (lambda d: d.update(schema_version=9), "schema_version 9"),
    "images_5": (lambda d: d.update(images=5), "expected an 'images' list"),
    "image_5": (lambda d: d["images"].__setitem__(0, 5), "images[0] is not an object"),
    "theta_1e300": (lambda d: d["images"][0]["blades"][0].update(theta_deg=1e300), "theta_deg"),
}


@pytest.mark.parametrize("case", sorted(PITCH_CASES))
def test_hostile_pitch_json_given_to_plan(cli, pitch_file, tmp_path, case):
    edit, says = PITCH_CASES[case]
    src = _write(tmp_path / f"{case}.json", _edited(pitch_file, edit))
    out = tmp_path / "plan.json"
    line = one_error_line(cli("plan", SAMPLE / "turbines.yaml", f"T1={src}", "--out", out), 3, src)
    assert says in line, line
    assert not out.exists()


# ---- input files: missing, unreadable, too large ---------------------------------------------
def test_missing_or_unreadable_yaml_is_exit_3_its_content_exit_4(cli, tmp_path):
    # docs/exit-codes.md: a file that cannot be read is an INPUT error (3), whatever its kind;
    # CONFIG (4) is for what a readable YAML says
    missing = tmp_path / "missing.yaml"
    assert "file not found" in one_error_line(cli("plan", missing), 3, missing, alone=True)
    assert "is a folder" in one_error_line(cli("plan", tmp_path), 3, tmp_path, alone=True)
    one_error_line(cli("fly", "--scenario", missing), 3, missing, alone=True)
    # a scenario naming a turbines.yaml that is not there: that file named, exit 3
    scn = _yaml(tmp_path, "scn.yaml", f"mission: {tmp_path / 'gone.yaml'}\n")
    one_error_line(cli("fly", "--scenario", scn), 3, tmp_path / "gone.yaml")
    latin1 = tmp_path / "latin1.yaml"
    latin1.write_bytes("mission:\n  name: caf\xe9\n".encode("latin-1"))
    assert "not UTF-8" in one_error_line(cli("plan", latin1), 4, latin1)


def test_unreadable_yaml_is_exit_3(cli, tmp_path, monkeypatch):
    # (a permission error simulated: the tests may run as root, who reads any file)
    import builtins

    src = _yaml(tmp_path, "t.yaml", (SAMPLE / "turbines.yaml").read_text())
    real_open = builtins.open

    def deny(file, *a, **k):
        if str(file) == str(src):
            raise PermissionError(errno.EACCES, "Permission denied", str(file))
        return real_open(file, *a, **k)

    monkeypatch.setattr(builtins, "open", deny)
    line = one_error_line(cli("plan", src, "--out", tmp_path / "p.json"), 3, src)
    assert "cannot read (Permission denied)" in line
    assert not (tmp_path / "p.json").exists()


def _sparse(path: Path, size: int) -> Path:
    """A file of ``size`` bytes taking no disk space (a hole): enough to test a size limit."""
    with open(path, "wb") as f:
        f.truncate(size)
    return path


@pytest.mark.parametrize("command", ["contours", "pitch", "fly", "plan"])
def test_json_over_the_size_limit_is_refused_before_reading(cli, tmp_path, command):
    from wtcli.jsonio import MAX_JSON_BYTES

    big = _sparse(tmp_path / "big.json", 2_100_000_000)
    assert MAX_JSON_BYTES < 2_100_000_000
    args = {"contours": (big,), "pitch": (big,), "fly": (big, "--scenario", "tiny"),
            "plan": (SAMPLE / "turbines.yaml", f"T1={big}")}[command]
    t0 = time.monotonic()
    line = one_error_line(cli(command, *args), 3, big)
    assert "2.1 GB is over the 1 GB limit for a JSON input" in line, line
    assert time.monotonic() - t0 < 20  # refused from the size, not after reading 2 GB


def test_a_small_json_reads_under_a_memory_cap(tmp_path):
    """A batch job capped at 1 GB of address space read no JSON at all: the reader asked for
    its whole 1 GB limit in one buffer before reading a byte."""
    f = tmp_path / "small.json"
    f.write_text('{"a": [1, 2]}')
    code = ("import resource, sys\n"
            "from wtcli.jsonio import read_json\n"
            "resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))\n"
            "print(read_json(sys.argv[1]))\n")
    r = subprocess.run([sys.executable, "-c", code, str(f)], capture_output=True, text=True,
                       cwd=ROOT, timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == "{'a': [1, 2]}", r.stderr[-500:]


def test_yaml_over_the_size_limit_is_refused(cli, tmp_path):
    big = _sparse(tmp_path / "big.yaml", 20_000_000)
    assert "20 MB is over the 16 MB limit for a YAML input" in one_error_line(cli("plan", big), 3, big)
    scn = _sparse(tmp_path / "scn.yaml", 20_000_000)
    one_error_line(cli("fly", "--scenario", scn), 3, scn)


def test_a_pipe_is_read_only_up_to_the_limit(tmp_path, monkeypatch):
    # a FIFO has no size to check first: reading stops one byte past the limit
    from wtcli.errors import InputError
    from wtcli.jsonio import read_json

    with pytest.raises(InputError, match="more than 1 kB, the limit for a JSON input"):
        read_json("/dev/zero", max_bytes=1000)


# ---- image headers: every format segment and contours decode ----------------------------------
def _tiff_bomb(path: Path, order: bytes = b"II", big: bool = False, kind: int = 4) -> Path:
    """A TIFF whose first IFD claims ImageWidth x ImageLength = 60000 x 60000 (3.6 GP)."""
    import struct

    e = "<" if order == b"II" else ">"
    if big:  # BigTIFF: 8-byte offsets, 20-byte entries
        head = order + struct.pack(e + "HHHQ", 43, 8, 0, 16)
        fmt = {3: "HHQH6x", 4: "HHQI4x", 16: "HHQQ"}[kind]
        ifd = struct.pack(e + "Q", 2) + b"".join(struct.pack(e + fmt, tag, kind, 1, 60000)
                                                for tag in (256, 257)) + bytes(8)
    else:
        head = order + struct.pack(e + "HI", 42, 8)
        fmt = {3: "HHIH2x", 4: "HHII"}[kind]
        ifd = struct.pack(e + "H", 2) + b"".join(struct.pack(e + fmt, tag, kind, 1, 60000)
                                                for tag in (256, 257)) + bytes(4)
    path.write_bytes(head + ifd + bytes(64))
    return path


def _bmp_bomb(path: Path) -> Path:
    import struct

    dib = struct.pack("<IiiHHIIiiII", 40, 50000, -50000, 1, 8, 0, 0, 0, 0, 0, 0)
    path.write_bytes(b"BM" + struct.pack("<IHHI", 14 + 40 + 64, 0, 0, 54) + dib + bytes(64))
    return path


def test_tiff_and_bmp_headers_claiming_huge_images_are_refused(cli, weights, tmp_path):
    tif = _tiff_bomb(tmp_path / "bomb.tif")
    line = one_error_line(cli("segment", tif, "--out", tmp_path / "o", "--model", weights, *FAST),
                          3, tif)
    assert "60000x60000" in line and "200,000,000" in line, line
    assert not (tmp_path / "o" / "instances.json").exists()
    for mask in (_tiff_bomb(tmp_path / "mask.tiff", b"MM"), _bmp_bomb(tmp_path / "mask.bmp")):
        line = one_error_line(cli("contours", mask, "--out", tmp_path / "c.json"), 3, mask)
        assert "over the limit of 200,000,000" in line, line
    assert not (tmp_path / "c.json").exists()


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc")
def test_second_output_options_are_not_called_out(cli, tmp_path):
    # plan's --export-dir and --picture, fly's --pictures, pitch's --overlay-dir: the message
    # names the path and does not send the user to change --out
    ro = Path("/proc/wtinspect-out")
    yaml_ = SAMPLE / "turbines.yaml"
    for args in (("plan", yaml_, "--out", tmp_path / "p.json", "--export-dir", ro),
                 ("plan", yaml_, "--out", tmp_path / "p.json", "--picture", ro / "p.png"),
                 ("pitch", SAMPLE / "instances.json", "--out", tmp_path / "x.json",
                  "--overlay-dir", ro)):
        line = one_error_line(cli(*args), 3, ro)
        assert "--out" not in line and "choose another output" in line, line
    assert not (tmp_path / "p.json").exists() and not (tmp_path / "x.json").exists()


def test_site_geojson_is_read_as_every_json_input(cli, tmp_path):
    # NaN refused, the size capped: the one JSON reader (wtcli/jsonio.py)
    src = (SAMPLE / "osm_wind.geojson").read_text()
    nan = tmp_path / "nan.geojson"
    nan.write_text(src.replace('"features": [', '"features": [NaN, ', 1))
    out = tmp_path / "t.yaml"
    assert "NaN is not a finite number" in one_error_line(cli("site", nan, "--out", out), 3, nan)
    big = _sparse(tmp_path / "big.geojson", 2_100_000_000)
    assert "over the 1 GB limit" in one_error_line(cli("site", big, "--out", out), 3, big)
    assert not out.exists()


def test_site_csv_size_capped_and_bom_kept_working(cli, tmp_path):
    out = tmp_path / "t.yaml"
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + (SAMPLE / "uswtdb_sample.csv").read_bytes())
    r = cli("site", bom, "--out", out)
    assert r.exit_code == 0, r.stderr
    big = _sparse(tmp_path / "big.csv", 2_100_000_000)
    assert "2.1 GB is over the 1 GB limit for a CSV input" in one_error_line(
        cli("site", big, "--out", tmp_path / "u.yaml"), 3, big)
    latin1 = tmp_path / "latin1.csv"
    latin1.write_bytes((SAMPLE / "uswtdb_sample.csv").read_bytes() + "caf\xe9\n".encode("latin-1"))
    assert "not UTF-8" in one_error_line(cli("site", latin1, "--out", tmp_path / "v.yaml"), 3, latin1)
