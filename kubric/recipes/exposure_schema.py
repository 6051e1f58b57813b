"""Schemas of the MOVi scenes made with the exposure options (:mod:`kubric.recipes.exposure_options`):
for every MOVi variant ``X``, ``X_dof`` (``--set dof=True``: the ``defocus`` layer and the lens)
and ``X_coverage`` (``--set coverage_samples=K``: ``coverage.npz``), each packed with
``kubric pack DIR --schema X_dof`` (or ``X_coverage``)."""

from __future__ import annotations

from kubric.annotations.exposure import COVERAGE_FIELDS, COVERAGE_FILE
from kubric.io.schema import Feature, register_schema
from kubric.recipes import movi_schema

F = Feature
#: the features ``dof=True`` adds
DOF_FEATURES = (
    F("defocus", "float32", ("T", "H", "W", 1), "layer:defocus", "zlib", unit="px",
      doc="circle-of-confusion diameter of the surface seen through the pixel centre "
      "(thin lens, from z; docs/conventions.md)"),
    F("camera/aperture_fstop", "float32", (), "meta:depth_of_field.aperture_fstop",
      doc="f-number N: aperture diameter = focal_length / N"),
    F("camera/focus_distance", "float32", (), "meta:depth_of_field.focus_distance", unit="m",
      doc="distance of the plane in focus, along the view axis"),
)
#: the features ``coverage_samples=K`` adds (one row per (frame, pixel, label) entry P)
COVERAGE_FEATURES = (
    F("coverage/num_samples", "int32", (), f"npz:{COVERAGE_FILE}:num_samples",
      doc="K: sub-frame times per frame"),
    F("coverage/shutter", "float32", (), f"npz:{COVERAGE_FILE}:shutter", unit="frames",
      doc="shutter length, centred on the frame"),
    *(F(f"coverage/{key}", dtype, shape, f"npz:{COVERAGE_FILE}:{key}", unit=unit, doc=doc)
      for key, dtype, shape, unit, doc in COVERAGE_FIELDS),
)
_BASES = {s.name: s for s in (movi_schema.MOVI_A, movi_schema.MOVI_B, movi_schema.MOVI_C,
                              movi_schema.MOVI_D, movi_schema.MOVI_E, movi_schema.MOVI_F)}
#: MOVi variant name → (its ``_dof`` schema, its ``_coverage`` schema)
EXPOSURE_VARIANTS = {name: (
    register_schema(base.extend(f"{name}_dof", DOF_FEATURES, description=f"{base.description} "
                                "With depth of field (dof=True): the defocus layer.")),
    register_schema(base.extend(f"{name}_coverage", COVERAGE_FEATURES,
                                description=f"{base.description} With the exposure coverage "
                                "(coverage_samples=K): coverage.npz.")))
    for name, base in _BASES.items()}
