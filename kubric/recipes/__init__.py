"""Built-in recipes (importing this registers them; no engine is imported here)."""

from kubric.recipes import bench, movi, multiview, pose_estimation, vbr  # noqa: F401
