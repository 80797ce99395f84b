"""Segmentation defaults shared down the chain, defined once here (the lowest module that needs
them) and imported by ``segment``'s inference and command, and by ``pitch`` and ``chain``.
Importing this module loads neither torch nor the network.
"""

DEFAULT_SCORE_THRESHOLD = 0.5  # an instance scoring at least this is found (segment, pitch, plan)
# Blades scoring at least this (and below the threshold) are kept as rotor-completion candidates
# for pitch (docs/pitch.md: its choice on development renders, seeds 9 500 000+).
CANDIDATE_FLOOR = 0.2
DEFAULT_MAX_SIZE = 1600  # a photo's longer side is downscaled to this for inference (px)
