"""Exports of a packed dataset to where trainers already are (docs/hub.md): Hugging Face
``datasets`` Parquet (:mod:`.hf`), WebDataset tar shards (:mod:`.webdataset`) and the dataset card
(:mod:`.card`, ``kubric datasets card``), registered in :data:`kubric.datasets.exports.FORMATS`.

Unlike the scene-directory exports beside it, this package reads through the loader
(:func:`kubric.datasets.load`): an exported example is the loader's example, feature by feature.
It is therefore a layer above :mod:`kubric.datasets` (docs/architecture.md), and nothing below
imports it.
"""
