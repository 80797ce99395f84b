"""Segmentation: a slim Mask R-CNN (model), its training data (data), training loop (train),
inference on photos (infer) and metrics (evaluate)."""
