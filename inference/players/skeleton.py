"""The COCO-17 skeleton, the keypoint layout used everywhere in rally3d (pose I/O, players, generator)."""
from __future__ import annotations

#: COCO-17 keypoint order (the order of every (…, 17, …) keypoint array).
COCO17: tuple[str, ...] = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
    "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
)
#: Bones to draw between COCO-17 joints (index pairs).
COCO17_BONES: tuple[tuple[int, int], ...] = (
    (5, 7), (7, 9), (6, 8), (8, 10), (5, 6), (5, 11), (6, 12), (11, 12),
    (11, 13), (13, 15), (12, 14), (14, 16), (0, 5), (0, 6),
)
#: Index of each joint by name.
JOINT = {name: i for i, name in enumerate(COCO17)}
