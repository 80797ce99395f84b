"""Convert the shipped segmenter and edge refiner for ``wtcli.segment.cvnet`` (the torch-free path
``plan`` and ``pitch`` take on photos): ``models/wtseg-r18s.cv2.npz``.

    .venv/bin/python -m pip install onnx   # only to convert; wtinspect never needs it to run
    .venv/bin/python -m wtcli.segment.export_cv2

Exports the network's dense part, box head and mask head to ONNX (torch's exporter, without
constant folding, so BatchNorm stays unfolded and every weight keeps the ``.pt``'s float16
value exactly), stores the weights as float16 (about 12 MB in all), adds the refiner's layers
and the torchvision settings ``cvnet`` replays, and the SHA-256 of both ``.pt`` files: after a
retrain the old file no longer matches and the torch path runs until this is run again. Checks
that cv2.dnn reads each graph and gives torch's outputs on a random input before writing.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
from pathlib import Path

import numpy as np
import torch

from wtcli.errors import ModelError
from wtcli.segment import cvnet
from wtcli.segment.infer import load_model
from wtcli.segment.refine import load_refiner


class _Dense(torch.nn.Module):
    def __init__(self, model):
        super().__init__()
        self.backbone, self.head = model.backbone, model.rpn.head

    def forward(self, x):
        f = self.backbone(x)
        obj, deltas = self.head([f[n] for n in ("0", "1", "2", "pool")])
        return (f["0"], f["1"], f["2"], f["p2"], *obj, *deltas)


class _Box(torch.nn.Module):
    def __init__(self, model):
        super().__init__()
        self.head, self.predictor = model.roi_heads.box_head, model.roi_heads.box_predictor

    def forward(self, x):
        return self.predictor(self.head(x))


class _Mask(torch.nn.Module):
    def __init__(self, model):
        super().__init__()
        self.head, self.predictor = model.roi_heads.mask_head, model.roi_heads.mask_predictor

    def forward(self, x):
        return self.predictor(self.head(x))


def _onnx_fp16(module: torch.nn.Module, example: torch.Tensor, inputs: list[str], outputs: list[str],
               dynamic: dict) -> bytes:
    import onnx
    from onnx import TensorProto, numpy_helper

    buf = io.BytesIO()
    torch.onnx.export(module.eval(), (example,), buf, dynamo=False, input_names=inputs,
                      output_names=outputs, dynamic_axes=dynamic, opset_version=17,
                      do_constant_folding=False)
    proto = onnx.load_from_string(buf.getvalue())
    for t in proto.graph.initializer:
        if t.data_type == TensorProto.FLOAT:
            a = numpy_helper.to_array(t)
            half = a.astype(np.float16)
            if np.array_equal(half.astype(np.float32), a):  # only values float16 holds exactly
                t.CopyFrom(numpy_helper.from_array(half, t.name))
    return proto.SerializeToString()


def _check(blob: bytes, module: torch.nn.Module, x: torch.Tensor, names: list[str], what: str) -> float:
    import cv2

    net = cv2.dnn.readNetFromONNX(np.frombuffer(blob, np.uint8))
    net.setInput(x.numpy())
    got = net.forward(names)
    with torch.inference_mode():
        ref = module(x)
    ref = ref if isinstance(ref, (tuple, list)) else (ref,)
    worst = max(float(np.abs(g - r.numpy()).max() / (np.abs(r.numpy()).max() + 1e-6))
                for g, r in zip(got, ref))
    if worst > 1e-3:
        raise ModelError(f"cv2.dnn's {what} differs from torch's by {worst:.2e} of the largest output")
    return worst


def export(out: Path = cvnet.CONVERTED) -> dict:
    model = load_model(None, "cpu", "fp32")
    refiner = load_refiner(None, "fp32")
    torch.manual_seed(0)
    dense, box, mask = _Dense(model), _Box(model), _Mask(model)
    n_lvl = 4
    dense_out = ["f0", "f1", "f2", "p2"] + [f"o{i}" for i in range(n_lvl)] + [f"d{i}" for i in range(n_lvl)]
    x = torch.randn(1, 3, 576, 768)
    blobs = {
        "dense": _onnx_fp16(dense, x, ["x"], dense_out, {"x": {2: "h", 3: "w"}}),
        "box": _onnx_fp16(box, torch.randn(5, 128, 7, 7), ["rois"], ["logits", "deltas"],
                          {"rois": {0: "n"}}),
        "mask": _onnx_fp16(mask, torch.randn(5, 128, 14, 14), ["rois"], ["masks"], {"rois": {0: "n"}}),
    }
    errors = {"dense": _check(blobs["dense"], dense, torch.randn(1, 3, 576, 1024), dense_out, "dense part"),
              "box": _check(blobs["box"], box, torch.randn(7, 128, 7, 7), ["logits", "deltas"], "box head"),
              "mask": _check(blobs["mask"], mask, torch.randn(3, 128, 14, 14), ["masks"], "mask head")}
    rpn, rh, t = model.rpn, model.roi_heads, model.transform
    layers = [m for m in refiner.net if isinstance(m, torch.nn.Linear)]
    meta = {
        "format": cvnet.FORMAT,
        "sha256": {name: cvnet._sha256(cvnet.MODELS_DIR / name) for name in cvnet.SOURCES},
        "mask_offset_px": float(model.mask_offset_px),
        "image_mean": [float(v) for v in t.image_mean], "image_std": [float(v) for v in t.image_std],
        "min_size": int(t.min_size[0]), "max_size": int(t.max_size), "size_divisible": int(t.size_divisible),
        "anchor_sizes": [list(s) for s in rpn.anchor_generator.sizes],
        "aspect_ratios": [list(a) for a in rpn.anchor_generator.aspect_ratios],
        "rpn_levels": n_lvl, "rpn_pre_nms_top_n": int(rpn._pre_nms_top_n["testing"]),
        "rpn_post_nms_top_n": int(rpn._post_nms_top_n["testing"]), "rpn_nms_thresh": float(rpn.nms_thresh),
        "rpn_min_size": float(rpn.min_size), "rpn_score_thresh": float(rpn.score_thresh),
        "box_weights": [float(w) for w in rh.box_coder.weights],
        "box_score_thresh": float(rh.score_thresh), "box_nms_thresh": float(rh.nms_thresh),
        "detections_per_img": int(rh.detections_per_img),
        "canonical_scale": 224, "canonical_level": 4,
        "sampling_ratio": int(rh.box_roi_pool.sampling_ratio),
        "dense_outputs": dense_out, "refiner_layers": len(layers),
    }
    arrays = {k: np.frombuffer(v, np.uint8) for k, v in blobs.items()}
    for i, lin in enumerate(layers):
        arrays[f"refiner_w{i}"] = lin.weight.detach().numpy().astype(np.float32)
        arrays[f"refiner_b{i}"] = lin.bias.detach().numpy().astype(np.float32)
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), np.uint8)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    from wtcli.jsonio import atomic_write_bytes

    atomic_write_bytes(out, buf.getvalue())
    return {"path": str(out), "bytes": out.stat().st_size, "max_relative_difference": errors}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=cvnet.CONVERTED)
    args = ap.parse_args(argv)
    try:
        import onnx  # noqa: F401
    except ImportError:
        print("converting needs the onnx package: .venv/bin/python -m pip install onnx", file=sys.stderr)
        return 2
    print(json.dumps(export(args.out)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
