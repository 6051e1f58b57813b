"""Exports of scene directories to the formats other tools train on (``kubric export``):
COCO instance annotations (:mod:`.coco`), BOP 6D-pose datasets (:mod:`.bop`) and TAP-Vid point
tracks (:mod:`kubric.annotations.track_files`). Conventions: docs/exports.md."""
