"""Rotor azimuths from oblique photos: back-projected from the pose the photo records (as a DJI
camera writes it) against the S_p assumption, through the whole photo chain.

    python benchmarks/photo_pose_accuracy.py [--n 40] [--seed 0] [--width 1024] [--height 768]

Each sample is a synthetic render (``wtcli.synth.render.render_sample``, view ``oblique``: the
camera 25-65 deg round the rotor axis). The photo goes through segment -> contours -> pitch
(``wtcli.chain.photo_to_pitch``, the shipped model); its blade directions are back-projected
(``wtcli.plan.zone.azimuths_from_pitch``) twice: from the pose a DJI camera would record there
(position and altitude, gimbal yaw, pitch and roll at two decimals, converted through a site
origin by ``wtcli.photo_pose.pose_from_metadata``), and from S_p looking at the rotor centre.
Printed: photos whose pitch stage found the rotor, then per pose the median, 90th percentile and
max of the worst blade's azimuth error, and the share within 1 and 2 deg. Photos the pitch stage
refuses (a blade missed or merged) are counted, not scored.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from wtcli.chain import photo_to_pitch  # noqa: E402
from wtcli.geometry import Camera, Turbine  # noqa: E402
from wtcli.photo_pose import PhotoMetadata, pose_from_metadata  # noqa: E402
from wtcli.plan.geodesy import enu_to_geodetic  # noqa: E402
from wtcli.plan.zone import azimuths_from_pitch  # noqa: E402
from wtcli.synth.render import render_sample  # noqa: E402

ORIGIN = {"lat": 53.5511, "lon": 9.9937, "alt": 12.0}


def recorded(cam: Camera, roll_deg: float, base) -> PhotoMetadata:
    """The tags a DJI camera at ``cam`` records (two decimals, relative altitude above take-off
    at the tower base)."""
    lat, lon, h = enu_to_geodetic(cam.position[None], ORIGIN)[0]
    ground = enu_to_geodetic(np.asarray(base, float)[None], ORIGIN)[0][2]
    f = cam.forward
    return PhotoMetadata(lat=float(lat), lon=float(lon), relative_alt_m=round(float(h - ground), 2),
                         gimbal_yaw_deg=round(math.degrees(math.atan2(f[0], f[1])), 2),
                         gimbal_pitch_deg=round(math.degrees(math.asin(f[2])), 2),
                         gimbal_roll_deg=round(-roll_deg, 2), where={"lat": "EXIF GPS"})


def worst_error(got, truth) -> float:
    return max(min(abs((a - b + 180) % 360 - 180) for b in got) for a in truth)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--width", type=int, default=1024)
    ap.add_argument("--height", type=int, default=768)
    a = ap.parse_args(argv)
    errs = {"photo's pose": [], "S_p": []}
    refused, t0 = 0, time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(a.n):
            s = render_sample(a.seed + k, a.width, a.height, view="oblique")
            tr = s.truth
            t = Turbine.from_dict(tr["turbine"])
            cam = Camera.from_dict(tr["camera"])
            path = Path(tmp) / f"{k:04d}.jpg"
            cv2.imwrite(str(path), s.image, [cv2.IMWRITE_JPEG_QUALITY, 95])
            found = photo_to_pitch(path, t.n_blades)
            if found.error is not None:
                refused += 1
                continue
            pose = pose_from_metadata(recorded(cam, tr["roll_deg"], t.base_xyz), t, ORIGIN, cam)
            for key, p in (("photo's pose", pose.camera_pose()), ("S_p", None)):
                try:
                    az = azimuths_from_pitch(t, found.result, cam, p)
                    errs[key].append(worst_error(az, t.azimuths_deg))
                except ValueError:  # the rays miss the rotor plane from this pose
                    errs[key].append(float("inf"))
    dt = time.perf_counter() - t0
    print(f"{a.n} oblique renders {a.width}x{a.height} (seeds {a.seed}..{a.seed + a.n - 1}); "
          f"pitch found the rotor in {a.n - refused}, refused {refused}; {dt / a.n:.1f} s/photo")
    print("| pose | median | p90 | max | within 1 deg | within 2 deg |")
    print("| --- | --- | --- | --- | --- | --- |")
    for key, e in errs.items():
        e = np.asarray(e)
        if not len(e):
            continue
        print(f"| {key} | {np.median(e):.2f} | {np.percentile(e, 90):.2f} | {e.max():.2f} | "
              f"{np.mean(e <= 1):.0%} | {np.mean(e <= 2):.0%} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
