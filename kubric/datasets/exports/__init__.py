"""Every export of scene directories to another tool's format, one module per format, run as
``kubric export FORMAT`` (:mod:`.cli`; conventions: docs/exports.md).

:data:`FORMATS` is the one registry: format name → ``"module:function"`` of its export function.
The modules import only core, io, annotations and assets (never the packer or the pipeline), so a
recipe may write an export into its scenes (the multi-view recipes' NeRF transforms, ``vbr``'s
LASR sequence).
"""

#: format name → "module:function" (the ``kubric export`` sub-commands, in this order)
FORMATS = {
    "coco": "kubric.datasets.exports.coco:export_coco",
    "bop": "kubric.datasets.exports.bop:export_bop",
    "tapvid": "kubric.datasets.exports.tapvid:export_tapvid",
    "nerf": "kubric.datasets.exports.nerf:export_nerf",
    "lasr": "kubric.datasets.exports.lasr:export_lasr",
}


def exporter(name: str):
    """The export function registered as ``name`` (imports its module)."""
    import importlib

    if name not in FORMATS:
        raise ValueError(f"unknown export format {name!r}; allowed: {list(FORMATS)}")
    module, function = FORMATS[name].split(":")
    return getattr(importlib.import_module(module), function)
