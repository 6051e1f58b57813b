"""Schemas of the MOVi scenes made with the exposure options
(:mod:`kubric.recipes.exposure_options`): for every MOVi variant ``X``, ``X_dof`` (``--set
dof=True``: the ``defocus`` layer and the lens), ``X_events`` (``--set events=true``:
``events.h5``), ``X_rolling_shutter`` (``--set rolling_shutter=d``) and, for MOVi-F,
``movi_f_coverage`` (``--set coverage_samples=K``: ``coverage.npz``, ``exposure_flow``), each
packed with ``kubric pack DIR --schema NAME``."""

from __future__ import annotations

from kubric.annotations.exposure import COVERAGE_FIELDS, COVERAGE_FILE
from kubric.io.event_h5 import EVENTS_H5_FILE
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
#: the features ``rolling_shutter=d`` adds
ROLLING_FEATURES = (
    F("camera/rolling_shutter_duration", "float32", (), "meta:rolling_shutter.duration",
      unit="frames", doc="readout time from the top edge to the bottom edge; row r of frame f "
      "is read at f + d·((r + 0.5)/H − 1/2) and every layer and track is at its row's time"),
)
#: the features ``coverage_samples=K`` adds (one row per (frame, pixel, label) entry P)
COVERAGE_FEATURES = (
    F("coverage/num_samples", "int32", (), f"npz:{COVERAGE_FILE}:num_samples",
      doc="K: sub-frame times per frame"),
    F("coverage/shutter", "float32", (), f"npz:{COVERAGE_FILE}:shutter", unit="frames",
      doc="shutter length, centred on the frame"),
    *(F(f"coverage/{key}", dtype, shape, f"npz:{COVERAGE_FILE}:{key}", unit=unit, doc=doc)
      for key, dtype, shape, unit, doc in COVERAGE_FIELDS),
    F("exposure_flow", "uint16", ("T", "H", "W", 2), "layer:exposure_flow", "zlib", unit="px",
      doc="(Δrow, Δcol) of the seen surface point from shutter open to close, scaled by "
      "metadata/exposure_flow_range"),
    F("metadata/exposure_flow_range", "float32", (2,), "range:exposure_flow", unit="px",
      doc="min, max of exposure_flow: v = q / 65535 · (max − min) + min"),
)
#: the features ``events=true`` adds (one row per event P; events.h5 in DSEC's layout)
EVENT_FEATURES = (
    F("event_stream/x", "uint16", ("P",), f"npz:{EVENTS_H5_FILE}:events/x", unit="px",
      doc="pixel column"),
    F("event_stream/y", "uint16", ("P",), f"npz:{EVENTS_H5_FILE}:events/y", unit="px",
      doc="pixel row"),
    F("event_stream/t", "int64", ("P",), f"npz:{EVENTS_H5_FILE}:events/t", unit="µs",
      doc="time, 0 at frame_start (events.h5's t_offset is 0)"),
    F("event_stream/p", "uint8", ("P",), f"npz:{EVENTS_H5_FILE}:events/p",
      doc="polarity: 1 = ON (brighter), 0 = OFF"),
    F("event_stream/contrast_thresholds", "float32", (2, "H", "W"),
      f"npz:{EVENTS_H5_FILE}:contrast_thresholds", doc="per-pixel (C+, C−), log intensity"),
    F("event_stream/refractory_us", "float32", (), "meta:event_camera.refractory_us", unit="µs",
      doc="refractory period of the sensor"),
)
_BASES = {s.name: s for s in (movi_schema.MOVI_A, movi_schema.MOVI_B, movi_schema.MOVI_C,
                              movi_schema.MOVI_D, movi_schema.MOVI_E, movi_schema.MOVI_F)}
#: MOVi variant name → its ``_dof``, ``_events`` and ``_rolling_shutter`` schemas, and for MOVi-F
#: (the one with a shutter) its ``_coverage`` schema
EXPOSURE_VARIANTS = {name: (
    register_schema(base.extend(f"{name}_dof", DOF_FEATURES, description=f"{base.description} "
                                "With depth of field (dof=True): the defocus layer.")),
    register_schema(base.extend(f"{name}_events", EVENT_FEATURES,
                                description=f"{base.description} With the event stream "
                                "(events=true): events.h5.")),
    register_schema(base.extend(f"{name}_rolling_shutter", ROLLING_FEATURES,
                                description=f"{base.description} With a rolling shutter "
                                "(rolling_shutter=d).")),
    *((register_schema(base.extend(f"{name}_coverage", COVERAGE_FEATURES,
                                   description=f"{base.description} With the exposure coverage "
                                   "(coverage_samples=K): coverage.npz and exposure_flow.")),)
      if name == "movi_f" else ()))
    for name, base in _BASES.items()}
