"""Segment one photo or a folder of photos into files (the library half of `wtinspect segment`).

For each image ``REL`` (its path relative to the input folder, or its name) named ``NAME``
(``REL`` without its suffix; ``REL`` itself where two photos would share a name, ``output_names``),
under ``OUT``:

- ``instances/NAME.json``: that image's instances (COCO-compatible, uncompressed RLE, scores,
  boxes), the photo's SHA-256 and the settings, written when the image is done; ``--resume``
  skips images whose four files exist and hold this very photo (other settings are refused);
- ``background_removed/NAME.png``: I_t, the photo with everything but the turbine black;
- ``overlay/NAME.png``: the photo with the instances drawn on it;
- ``classes/NAME.png``: the class map, each pixel's category id (0 background, 1 blade, 2 tower,
  3 nacelle) from the instances scoring the threshold, one class a pixel
  (``Instances.class_map``), to compare with semantic labels;

and once the batch ends, ``instances.json`` (every finished image in one COCO file, ready for
``contours`` and ``pitch``) and ``report.json`` (per file: ok / error, counts, what was found,
outputs; and how many photos held a rotor, a single blade, a tower only or nothing).
Every file is written atomically. A failing image is recorded and the batch goes on; a broken
or looping symbolic link to an image is such a failure too, not skipped, and so is an output
name too long for the disk. An output that cannot be written otherwise (a full disk, a
read-only subfolder) stops the batch instead: every later image would fail the same way after
the network ran. Each run first removes temporaries a kill left (``.NAME.k2x9q0ab``) in the
four subfolders and of the two files above, nothing else under ``OUT``; ``--resume`` redoes an
image whose instances file cannot be read; a run where no image succeeds removes an earlier
``instances.json`` rather than leave it beside a report that says ``instances: null``.
"""

from __future__ import annotations

import errno
import hashlib
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import cv2
import numpy as np

from wtcli.errors import ConfigError, InputError, OutputError, WtError
from wtcli.jsonio import (atomic_write_bytes, document, missing, os_reason, read_json,
                          write_json)
from wtcli.outputs import remove_stale, remove_temp_files
from wtcli.masks import (INSTANCES_SCHEMA, INSTANCES_VERSION, LABELS, Instances,
                         check_declared_size, instances_document, read_instances, write_instances,
                         write_instances_streamed)
from wtcli.segment.defaults import DEFAULT_SCORE_THRESHOLD

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".tif", ".tiff")
# Photos a drone's or a phone's folder holds that segment does not read, by kind: said, not
# silently left out (a DJI drone saves a .DNG beside each .JPG; phones save .HEIC).
NOT_READ = {**dict.fromkeys((".dng", ".arw", ".cr2", ".cr3", ".nef", ".orf", ".raf", ".rw2",
                             ".raw"), "raw"),
            ".heic": "HEIF", ".heif": "HEIF", ".webp": "WebP", ".bmp": "BMP", ".gif": "GIF",
            ".jp2": "JPEG 2000"}
REPORT_SCHEMA = "wtinspect.segment_report"
MAX_DECODE_PIXELS = 1 << 30  # OpenCV's CV_IO_MAX_IMAGE_PIXELS default
FOUND = ("rotor", "single_blade", "tower_only", "nothing")  # what a photo holds (found_in)
SUBFOLDERS = ("instances", "background_removed", "overlay", "classes")
# The settings that change what a photo's files hold: a --resume with other values is refused.
RESUME_KEYS = ("score_threshold", "max_size", "zoom", "wide", "flip", "model", "mirror_model",
               "refiner")


def found_in(inst: Instances, score_threshold: float = DEFAULT_SCORE_THRESHOLD) -> str:
    """What a photo holds, from its instances scoring at least ``score_threshold``:
    ``rotor`` (two or more blades, or a nacelle with a blade), ``single_blade`` (exactly one
    blade and no nacelle: a close-up), ``tower_only`` (a tower or nacelle, no blade) or
    ``nothing``."""
    labels = list(inst.labels[inst.scores >= score_threshold])
    blades, nacelle = labels.count("blade"), "nacelle" in labels
    if blades >= 2 or (blades == 1 and nacelle):
        return "rotor"
    if blades == 1:
        return "single_blade"
    return "tower_only" if labels else "nothing"


@dataclass
class ImageResult:
    rel: str  # path relative to the input folder (or the file name of a single image)
    source: str
    status: str  # "ok" | "skipped" (resumed) | "error"
    error: str | None = None
    counts: dict[str, int] = field(default_factory=dict)
    found: str | None = None  # one of FOUND; None for an error
    width: int = 0
    height: int = 0
    # Its instances are in its instances/NAME.json (instances.json is made from those files at
    # the end: holding every photo's full-size masks took ~70 MB a 12 MP photo).
    done: bool = False
    name: str = ""  # the outputs' NAME (output_names); "" -> rel without its suffix
    sha256: str | None = None  # of the photo's bytes: --resume tells this photo from another

    def to_dict(self, out: Path) -> dict[str, Any]:
        d = {"file": self.rel, "source": self.source, "status": self.status, "error": self.error,
             "counts": self.counts, "width": self.width, "height": self.height}
        if self.status != "error":
            d["found"] = self.found
            d["outputs"] = {k: str(v) for k, v in output_paths(out, self.rel, self.name).items()}
        return d


@dataclass
class Batch:
    results: list[ImageResult]
    stopped: OutputError | None = None  # an output could not be written: the batch ended there
    interrupted: bool = False  # Ctrl-C or SIGTERM: the photos done are in results, not the one under way


def find_images(path: Path, recursive: bool = False, out: Path | None = None
                ) -> tuple[Path, list[Path]]:
    """(root, images): a single image -> (its folder, [it]); a folder -> its jpg/png/tif files.
    With ``recursive``, subfolders too, except hidden ones, ``out`` and any other segment output
    folder (``is_output_folder``): a second run would take its overlays for photos."""
    try:
        path.stat()
    except FileNotFoundError:
        kind = "broken symbolic link" if path.is_symlink() else "no such file or folder"
        raise InputError(f"{path}: {kind}") from None
    except OSError as e:
        raise InputError(f"{path}: cannot read ({os_reason(e)})") from None
    if path.is_file():
        if path.suffix.lower() in NOT_READ:
            raise _not_read_photo(path)
        if path.suffix.lower() not in IMAGE_SUFFIXES:
            raise InputError(f"{path}: not an image (expected {', '.join(IMAGE_SUFFIXES)})")
        return path.parent, [path]
    if not path.is_dir():
        raise InputError(f"{path}: not a file or folder")
    files = [p for p in _candidates(path, recursive, out) if p.suffix.lower() in IMAGE_SUFFIXES]
    if not files:
        hint = "" if recursive else " (add --recursive to look in subfolders)"
        other = not_read_text(photos_not_read(path, recursive, out))
        raise InputError(f"{path}: no images ({', '.join(IMAGE_SUFFIXES)}) in this folder{hint}"
                         + (f"; it holds photos segment does not read: {other}" if other else ""))
    return path, files


def _candidates(path: Path, recursive: bool, out: Path | None) -> list[Path]:
    """The folder's files (and subfolders' with ``recursive``), sorted, hidden ones left out."""
    try:
        it = _walk(path, out) if recursive else list(path.iterdir())
        # A link whose target is missing or loops is kept, so it fails visibly in the report.
        return sorted(p for p in it if (p.is_file() or (p.is_symlink() and not p.exists()))
                      and not any(part.startswith(".") for part in p.relative_to(path).parts))
    except OSError as e:  # no read or no execute (search) permission on the folder
        raise InputError(f"{path}: cannot list the folder ({os_reason(e)})") from None


def photos_not_read(path: Path, recursive: bool = False, out: Path | None = None) -> dict[str, int]:
    """How many photos of each suffix (as written, e.g. ".DNG") in the folder ``segment`` does
    not read (``NOT_READ``); {} for a single file."""
    if not path.is_dir():
        return {}
    counts: dict[str, int] = {}
    for p in _candidates(path, recursive, out):
        if p.suffix.lower() in NOT_READ:
            counts[p.suffix] = counts.get(p.suffix, 0) + 1
    return counts


def not_read_text(counts: dict[str, int]) -> str:
    """"3 .DNG (raw), 1 .heic (HEIF) — " and what to do; "" for none."""
    if not counts:
        return ""
    kinds = ", ".join(f"{n} {sfx} ({NOT_READ[sfx.lower()]})" for sfx, n in sorted(counts.items()))
    return f"{kinds} — {not_read_advice(list(counts), sum(counts.values()))}"


def not_read_advice(suffixes: list[str], n: int = 1) -> str:
    them, file = ("them", "each raw file") if n > 1 else ("it", "the raw file")
    raw = any(NOT_READ.get(sfx.lower()) == "raw" for sfx in suffixes)
    return ((f"use the JPEG the camera saved beside {file}, or convert {them}" if raw
             else f"convert {them}") + f" to {', '.join(IMAGE_SUFFIXES)}")


def _not_read_photo(path: Path) -> InputError:
    return InputError(f"{path}: a {NOT_READ[path.suffix.lower()]} photo, which wtinspect does "
                      f"not read; {not_read_advice([path.suffix])}")


def is_output_folder(folder: Path) -> bool:
    """A folder ``segment`` wrote into (its per-photo subfolders are there), finished or not."""
    return all((folder / sub).is_dir() for sub in ("instances", "overlay", "background_removed"))


def _walk(root: Path, out: Path | None) -> list[Path]:
    """Every file under ``root``, not descending into hidden folders or output folders."""
    skip = os.path.abspath(out) if out is not None else None
    found: list[Path] = []

    def fail(e: OSError) -> None:
        raise e

    for folder, dirs, names in os.walk(root, onerror=fail, followlinks=False):
        here = Path(folder)
        dirs[:] = [d for d in dirs if not d.startswith(".")
                   and os.path.abspath(here / d) != skip and not is_output_folder(here / d)]
        found += [here / n for n in names]
    return found


def output_names(rels: list[str]) -> dict[str, str]:
    """Each photo's outputs' NAME (``outputs.distinct_names``): its path without the suffix, or
    with it where two photos would share one (``dup.jpg`` and ``dup.png``; compared ignoring
    case, as disks on macOS and Windows do), and a ``~2``, ``~3`` after names that differ only
    in case."""
    from wtcli.outputs import distinct_names

    # room: the longest extension output_paths adds (".json")
    return dict(zip(rels, distinct_names([Path(r).as_posix() for r in rels], room=len(".json"))))


def output_paths(out: Path, rel: str, name: str = "") -> dict[str, Path]:
    stem = name or str(Path(rel).with_suffix(""))
    return {"instances": out / "instances" / f"{stem}.json",
            "background_removed": out / "background_removed" / f"{stem}.png",
            "overlay": out / "overlay" / f"{stem}.png",
            "classes": out / "classes" / f"{stem}.png"}


def read_image(path: Path) -> np.ndarray:
    """BGR uint8 [H, W, 3] as a viewer shows it (turned upright by its EXIF Orientation); 16-bit
    and grey images are converted, alpha dropped; anything else is InputError."""
    try:
        data = np.fromfile(str(path), dtype=np.uint8)
    except FileNotFoundError:
        raise InputError(f"{path}: {missing(path)}") from None
    except OSError as e:
        raise InputError(f"{path}: cannot read ({os_reason(e)})") from None
    check_declared_size(data, path)
    try:
        # As a viewer shows it: turned by its EXIF Orientation (IMREAD_UNCHANGED would not).
        flags = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR
        img = cv2.imdecode(data, flags) if data.size else None
    except cv2.error as e:  # OpenCV refuses to allocate a decompression bomb
        if "CV_IO_MAX_IMAGE_PIXELS" in str(e):
            raise InputError(f"{path}: image too large to decode (over {MAX_DECODE_PIXELS:,} pixels, "
                             "OpenCV's limit); downscale it first") from None
        raise InputError(f"{path}: not a readable image ({e.__class__.__name__})") from None
    if img is None:
        if path.suffix.lower() in NOT_READ:
            raise _not_read_photo(path)
        raise InputError(f"{path}: not a readable image (corrupt or unsupported format)")
    if img.dtype == np.uint16:
        img = (img / 257).astype(np.uint8)
    elif img.dtype != np.uint8:
        raise InputError(f"{path}: unsupported pixel type {img.dtype}")
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    return img


def _png(img: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise InputError("could not encode a PNG")
    return buf.tobytes()


def counts_of(inst: Instances) -> dict[str, int]:
    return {l: int((inst.labels == l).sum()) for l in LABELS}


def segment_paths(path: Path, out: Path, segment: Callable[[np.ndarray], Instances],
                  recursive: bool = False, resume: bool = False,
                  on_progress: Callable[[ImageResult], None] | None = None,
                  score_threshold: float = DEFAULT_SCORE_THRESHOLD,
                  settings: dict[str, Any] | None = None) -> Batch:
    """Run ``segment`` (BGR image -> Instances) over an image or folder, writing the files above;
    ``score_threshold`` is the one ``segment`` kept instances at (for ``found_in``); ``settings``
    go into each photo's instances file, and a ``resume`` over files made with other values of
    ``RESUME_KEYS`` is refused (ConfigError)."""
    root, files = find_images(path, recursive, out)
    # Temporaries a kill left, in the folders and of the files segment writes: anything else
    # under --out (a user's notes, another program's writes) is not ours to delete.
    for sub in SUBFOLDERS:
        remove_temp_files(out / sub)
    remove_temp_files(out, r"instances\.json|report\.json")
    rels = [str(f.relative_to(root)) if path.is_dir() else f.name for f in files]
    names = output_names(rels)
    batch = Batch([])
    try:
        for f, rel in zip(files, rels):
            outs = output_paths(out, rel, names[rel])
            res = ImageResult(rel=rel, source=str(f), status="ok", name=names[rel])
            try:
                digest = _sha256(f)
                done = _finished(outs, rel, digest, settings) if resume else None
                if done is not None:
                    img_rec, inst = done
                    res.status, res.sha256 = "skipped", digest
                    res.width, res.height = int(img_rec["width"]), int(img_rec["height"])
                else:
                    img = read_image(f)
                    inst = segment(img)
                    res.sha256 = digest
                    res.height, res.width = img.shape[:2]
                    from wtcli.segment.infer import overlay, remove_background

                    atomic_write_bytes(outs["background_removed"], _png(remove_background(img, inst)))
                    atomic_write_bytes(outs["overlay"], _png(overlay(img, inst)))
                    sure = inst[inst.scores >= score_threshold] if len(inst) else inst
                    atomic_write_bytes(outs["classes"], _png(sure.class_map()))
                    # The instances file last: its presence marks the image as done for --resume.
                    write_instances(outs["instances"], [_image_record(1, rel, f, res)], [inst],
                                    extra={"settings": settings} if settings is not None else None)
                res.counts = counts_of(inst)
                res.found = found_in(inst, score_threshold)
                res.done = True
            except OutputError as e:
                res.status, res.error = "error", str(e)
                # A name too long for the disk is this photo's alone; anything else (a full
                # disk, a read-only folder) would fail the next photo too, after the network.
                if e.errno != errno.ENAMETOOLONG:
                    batch.stopped = e
            except ConfigError:
                raise
            except WtError as e:
                res.status, res.error = "error", _naming(str(e), f)
            except OSError as e:
                res.status = "error"
                res.error = f"{e.filename or f}: {os_reason(e)}"
            except (ValueError, cv2.error, MemoryError) as e:
                res.status = "error"
                res.error = _naming(f"{e.__class__.__name__}: {e}", f)
            batch.results.append(res)
            if on_progress:
                on_progress(res)
            if batch.stopped:
                break
    except KeyboardInterrupt:  # the files of the photos done are kept; the caller sums them up
        batch.interrupted = True
    return batch


def _sha256(path: Path) -> str | None:
    """The photo's SHA-256 (None where it cannot be read: read_image then says why)."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
    except OSError:
        return None
    return h.hexdigest()


def _finished(outs: dict[str, Path], rel: str, digest: str | None,
              settings: dict[str, Any] | None) -> tuple[dict, Instances] | None:
    """(image record, instances) of this photo as a previous run finished it, or None: outputs
    missing, an instances file that cannot be read (damaged, edited), or one of another photo
    (another name, or other bytes under this name) -- then the image is redone. Made with other
    settings (``RESUME_KEYS``): ConfigError, as the batch would mix two segmentations."""
    if not all(p.is_file() for p in outs.values()):
        return None
    try:
        items = read_instances(outs["instances"])
    except InputError:
        return None
    if len(items) != 1:
        return None
    rec = items[0][0]
    if rec.get("file_name") != rel or (rec.get("sha256") is not None and rec["sha256"] != digest):
        return None
    if settings is not None:
        try:
            before = read_json(outs["instances"], header_required=False).get("settings")
        except InputError:
            return None
        if isinstance(before, dict):  # files from before settings were recorded: taken as they are
            for k in RESUME_KEYS:
                if k in before and k in settings and before[k] != settings[k]:
                    raise ConfigError(
                        f"--resume: {outs['instances']} was made with {k} {before[k]!r}, this run "
                        f"asks {settings[k]!r}; give the same settings, another --out, or run "
                        "without --resume to redo every photo")
    return items[0]


def _naming(message: str, source: Path) -> str:
    """An image's error message, naming the image if it does not already."""
    return message if str(source) in message else f"{source}: {message}"


def _image_record(iid: int, rel: str, src: Path, res: ImageResult) -> dict[str, Any]:
    rec = {"id": iid, "file_name": rel, "path": str(src), "width": res.width, "height": res.height}
    if res.sha256:
        rec["sha256"] = res.sha256
    return rec


def batch_report(out: Path, results: list[ImageResult], settings: dict[str, Any],
                 interrupted: bool = False, not_read: dict[str, int] | None = None
                 ) -> dict[str, Any]:
    """What report.json holds. ``interrupted``: the batch was stopped (Ctrl-C, SIGTERM) before
    its last photos, which it leaves out. ``not_read``: ``photos_not_read``'s counts."""
    done = any(r.done for r in results)
    return document(REPORT_SCHEMA, 1, {
        "settings": settings,
        "images": [r.to_dict(out) for r in results],
        "n_images": len(results), "n_failed": sum(r.status == "error" for r in results),
        "n_skipped": sum(r.status == "skipped" for r in results),
        # Added within schema_version 1 (an optional field; readers of older reports ignore it).
        "n_found": {k: sum(r.found == k for r in results if r.status != "error") for k in FOUND},
        "instances": str(out / "instances.json") if done else None,
        "interrupted": interrupted,  # added within schema_version 1, as n_found
        "not_read": dict(sorted((not_read or {}).items())),  # added within schema_version 1
    })


def _annotations(out: Path, res: ImageResult, combined: Path) -> list[dict]:
    path = output_paths(out, res.rel, res.name)["instances"]
    try:
        anns = read_json(path, INSTANCES_SCHEMA, INSTANCES_VERSION)["annotations"]
        if not isinstance(anns, list):
            raise InputError(f"{path}: annotations is not a list")
    except (InputError, KeyError) as e:  # changed or removed while the batch ran
        raise InputError(f"{combined}: not written: {res.rel}'s instances file could not be read "
                         f"back ({e})") from None
    return anns


def write_batch_files(out: Path, results: list[ImageResult], report: dict[str, Any]) -> None:
    """The combined instances.json (finished images, their annotations read back from their
    instances/NAME.json one at a time) and ``report`` (``batch_report``) as report.json."""
    done = [r for r in results if r.done]
    images = [_image_record(k + 1, r.rel, Path(r.source), r) for k, r in enumerate(done)]
    lost = None  # a photo's file changed or removed while the batch ran: the report still goes out
    if done:
        combined = out / "instances.json"
        try:
            write_instances_streamed(combined, images,
                                     (_annotations(out, r, combined) for r in done),
                                     extra={"settings": report["settings"]})
        except InputError as e:
            lost = e
    else:
        remove_stale(out / "instances.json")  # it would hold an earlier run's images
    write_json(out / "report.json", report)
    if lost is not None:
        raise lost


__all__ = ["FOUND", "IMAGE_SUFFIXES", "NOT_READ", "not_read_text", "photos_not_read", "SUBFOLDERS", "Batch", "ImageResult", "batch_report",
           "found_in", "find_images",
           "is_output_folder", "output_names", "output_paths", "read_image", "segment_paths",
           "write_batch_files", "instances_document"]
