"""What keeps `wtinspect plan` quick (benchmarks/plan_latency.py): nothing loaded or compiled
that the plan does not use. Each check runs a fresh interpreter, as a user's command does."""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_images" / "turbines.yaml"


def _python(code: str, env: dict | None = None, timeout: int = 600) -> dict:
    """Run ``code`` in a fresh interpreter at the repo root; it prints one JSON line last."""
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT, text=True,
                          capture_output=True, timeout=timeout, env={**os.environ, **(env or {})})
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_segmenter_imports_torchvision_without_the_compiler():
    got = _python("""
        import json, sys
        import wtcli.segment.infer
        from wtcli.segment.model import build_model
        n = sum(p.numel() for p in build_model().parameters())
        before = sorted(m for m in sys.modules if m.startswith("torch._dynamo"))
        # the stand-in is gone: the compiler still imports, and roi_align's use of it works
        import torch._dynamo.utils
        ra = sys.modules["torchvision.ops.roi_align"]
        print(json.dumps({"params": n, "dynamo_before": before,
                          "real": sys.modules["torch._dynamo.utils"].is_compile_supported("cpu"),
                          "via_torchvision": ra.is_compile_supported("cpu"),
                          "has_eval_frame": hasattr(torch._dynamo, "optimize")}))
    """)
    assert got["dynamo_before"] == []
    assert got["params"] > 1_000_000
    assert got["real"] is True and got["via_torchvision"] is True and got["has_eval_frame"]


def test_plan_from_pitch_json_loads_no_torch_and_compiles_no_kernel(tmp_path):
    """After set-up (``python -m wtcli.warmup``, here into an empty numba cache), a plan from a
    pitch JSON takes every compiled kernel from the cache and never imports torch."""
    import numpy as np

    from wtcli.geometry import Camera
    from wtcli.geometry.projection import instance_masks
    from wtcli.jsonio import document, write_json
    from wtcli.masks import Instances
    from wtcli.pitch import PITCH_SCHEMA, PITCH_VERSION, pitch_from_instances
    from wtcli.plan.zone import default_photo_camera
    from wtcli.plan.config import load_mission

    t = load_mission(SAMPLE).turbine("T2")
    inst = instance_masks(t, default_photo_camera(t, Camera(800, 600, 16, 23.2)))
    res = pitch_from_instances(Instances(np.array([lb for lb, _, _ in inst], dtype=object),
                                         np.array([m for _, _, m in inst])), expected_blades=3)
    pj = tmp_path / "pitch.json"
    write_json(pj, document(PITCH_SCHEMA, PITCH_VERSION, {"images": [{**res.to_dict(), "error": None}]}))

    env = {"NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    warm = subprocess.run([sys.executable, "-m", "wtcli.warmup"], cwd=ROOT, env={**os.environ, **env},
                          capture_output=True, text=True, timeout=900)
    assert warm.returncode == 0, warm.stderr[-2000:]
    got = _python(f"""
        import json, sys
        from numba.core.registry import CPUDispatcher
        from wtcli.cli import main
        try:
            main(["plan", {str(SAMPLE)!r}, "T2={pj}", "--out", {str(tmp_path / "plan.json")!r}])
        except SystemExit as e:
            code = e.code
        hits, misses = [], []
        for name, mod in list(sys.modules.items()):
            if name.startswith("wtcli"):
                for k, v in vars(mod).items():
                    if isinstance(v, CPUDispatcher):
                        hits += [f"{{name}}.{{k}}"] * sum(v.stats.cache_hits.values())
                        misses += [f"{{name}}.{{k}}"] * sum(v.stats.cache_misses.values())
        print(json.dumps({{"code": code, "torch": sorted(m for m in sys.modules if m == "torch"
                                                           or m.startswith(("torch.", "torchvision"))),
                           "hits": hits, "misses": misses}}))
    """, env)
    assert got["code"] == 0
    assert got["torch"] == []
    assert got["hits"], "the plan used no compiled kernel: this check checks nothing"
    assert got["misses"] == [], f"compiled at run time, not by wtcli.warmup: {got['misses']}"


def test_cli_lets_openmp_threads_sleep_unless_told_otherwise():
    code = """
        import json, os
        import wtcli.cli
        print(json.dumps(os.environ.get("OMP_WAIT_POLICY")))
    """
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT, text=True,
                          capture_output=True, timeout=120, env=env)
    assert json.loads(done.stdout.splitlines()[-1]) == "PASSIVE"
    assert _python(code, {"OMP_WAIT_POLICY": "ACTIVE"}) == "ACTIVE"


def test_fast_photo_chain_runs_the_network_once_and_reads_the_same_angles(monkeypatch):
    """``plan --fast``: one backbone pass instead of four on the sample photo (its turbine is
    small enough for a second look; each look detects the photo and its mirror), and the
    blade angles within half a degree of the full chain's."""
    from wtcli.chain import photo_to_pitch
    from wtcli.segment.infer import load_model

    model = load_model()
    passes = []
    forward = model.backbone.forward
    monkeypatch.setattr(model.backbone, "forward", lambda x: passes.append(1) or forward(x))
    photo = ROOT / "sample_images" / "images" / "00000.jpg"
    full = photo_to_pitch(photo, 3, one_short_ok=True)
    n_full = len(passes)
    fast = photo_to_pitch(photo, 3, one_short_ok=True, fast=True)
    assert (n_full, len(passes) - n_full) == (4, 1)
    assert full.error is None and fast.error is None
    a = sorted(b.phi_deg for b in full.result.blades)
    b = sorted(b.phi_deg for b in fast.result.blades)
    assert len(a) == len(b) == 3
    assert max(abs((x - y + 180) % 360 - 180) for x, y in zip(a, b)) < 0.5


def test_plan_runs_with_its_imports_out_of_the_collectors_way_and_gives_them_back(tmp_path,
                                                                                 monkeypatch):
    """While ``plan`` runs, what it imported (the libraries, the planner's modules) is frozen out of
    the collector's full passes; after it, nothing stays frozen for a caller in the same
    process (only ``main``, where the process ends, leaves it so), and what a caller froze
    stays frozen."""
    import gc

    from typer.testing import CliRunner

    import wtcli.plan.mission as mission
    from wtcli.cli import app

    seen = []
    real = mission.plan_mission
    monkeypatch.setattr(mission, "plan_mission",
                        lambda *a, **k: seen.append(gc.get_freeze_count()) or real(*a, **k))
    gc.unfreeze()  # what an earlier test's ``main`` left
    done = CliRunner().invoke(app, ["plan", str(SAMPLE), "--out", str(tmp_path / "plan.json")])
    assert done.exit_code == 0, done.output
    assert seen and seen[0] > 1000
    assert gc.get_freeze_count() == 0
    # a caller that froze objects of its own keeps them frozen
    gc.freeze()
    try:
        frozen = gc.get_freeze_count()
        done = CliRunner().invoke(app, ["plan", str(SAMPLE), "--out", str(tmp_path / "plan.json")])
        assert done.exit_code == 0, done.output
        assert gc.get_freeze_count() >= 0.9 * frozen  # not unfrozen (0)
    finally:
        gc.unfreeze()
