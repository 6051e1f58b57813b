"""The MOVi recipes' exposure options: depth of field (``dof``) and the exposure coverage of
motion blur (``coverage_samples``); the ground truth is :mod:`kubric.annotations.exposure`
(docs/conventions.md, "Time inside a frame").

* ``dof=True``: the camera gets a thin lens, f-number U(min_fstop, max_fstop) and focus
  distance U(min_focus_distance, max_focus_distance) metres along the view axis, drawn from an
  rng derived from the seed (so the rest of the scene is the seed's without DoF); the renderer
  must render depth of field (Blender: Cycles' thin lens); the scene gets the ``defocus`` layer
  and ``metadata.depth_of_field`` {use_dof, aperture_fstop, focus_distance}.
* ``coverage_samples=K`` (> 0): ``coverage.npz``, the fraction of the exposure (the shutter of
  ``metadata.motion_blur`` frames, centred on the frame) at which each pixel shows each instance,
  from K raycast sub-frame renders per frame (with any backend: the raycast backend supplies the
  sub-frames).
"""

from __future__ import annotations

import numpy as np

from kubric.annotations.exposure import COVERAGE_FILE, coverage_archive, defocus
from kubric.annotations.segmentation import adjust_segmentation_idxs
from kubric.pipeline import Option

#: tag of the rng the lens is drawn from (derived from the seed: RandomState([seed, tag]))
LENS_RNG_TAG = 0x6C656E73


class ExposureOptions:
    """Mixin of the exposure options (module doc) for a recipe with a ``renderer`` option."""

    dof = Option(False, "depth of field: a thin-lens camera (f-number and focus distance drawn "
                 "from the ranges below); writes the defocus layer")
    min_fstop = Option(1.4, "smallest f-number with dof=True", low=0.1, high=64.0)
    max_fstop = Option(5.6, "largest f-number with dof=True", low=0.1, high=64.0)
    min_focus_distance = Option(6.0, "nearest focus distance with dof=True (m, along the view "
                                "axis)", low=0.1, high=1000.0)
    max_focus_distance = Option(14.0, "farthest focus distance with dof=True (m)", low=0.1,
                                high=1000.0)
    coverage_samples = Option(0, "sub-frame raycast renders per frame for coverage.npz, the "
                              "fraction of the exposure each pixel shows each instance "
                              "(0 = none)", low=0, high=256)

    def exposure_requests(self) -> dict[str, str]:
        """Renderer capabilities the exposure options ask for (see ``renderer_requests``)."""
        return {"depth_of_field": "dof=True"} if self.dof else {}

    def sample_lens(self, scene, seed: int) -> None:
        """With ``dof``: the camera's thin lens, from an rng derived from ``seed``; recorded in
        ``scene.metadata["depth_of_field"]``."""
        if not self.dof:
            return
        rng = np.random.RandomState([int(seed), LENS_RNG_TAG])
        camera = scene.camera
        camera.use_dof = True
        camera.aperture_fstop = float(rng.uniform(self.min_fstop, self.max_fstop))
        camera.focus_distance = float(rng.uniform(self.min_focus_distance,
                                                  self.max_focus_distance))
        scene.metadata["depth_of_field"] = {"use_dof": True,
                                            "aperture_fstop": camera.aperture_fstop,
                                            "focus_distance": camera.focus_distance}

    def add_defocus(self, scene, layers: dict) -> None:
        """With ``dof``: ``layers["defocus"]`` from the rendered ``z`` layer."""
        if self.dof:
            layers["defocus"] = defocus(scene.camera, layers["z"])

    def subframe_labels(self, scene, shutter: float):
        """With ``coverage_samples``: (T, K, H, W) raw labels at the shutter's sub-frame times
        (None without)."""
        if not self.coverage_samples:
            return None
        from kubric.renderer.raycast_subframes import shutter_segmentation
        return shutter_segmentation(scene, scene.frames, shutter, self.coverage_samples)

    @staticmethod
    def coverage_files(scene, labels, instances, shutter: float) -> dict:
        """{coverage.npz: arrays} with ``labels`` relabelled to ``instances`` ({} for None)."""
        if labels is None:
            return {}
        t, k, h, w = labels.shape
        relabelled = adjust_segmentation_idxs(labels.reshape(t * k, h, w), scene.assets,
                                              instances).reshape(t, k, h, w)
        return {COVERAGE_FILE: coverage_archive(relabelled, shutter)}
