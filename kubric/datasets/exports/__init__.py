"""Every export of scene directories to another tool's format, one module per format, run as
``kubric export FORMAT`` (:mod:`.cli`; conventions: docs/exports.md).

:data:`FORMATS` is the one registry: format name → its :class:`ExportFormat` (the export function
and its command's texts). Adding a format is a module ``exports/<name>.py`` defining
``export_<name>(scenes, out)`` plus its row here (docs/architecture.md, Example 5).
The modules import only core, io, annotations and assets (never the packer or the pipeline), so a
recipe may write an export into its scenes (the multi-view recipes' NeRF transforms, ``vbr``'s
LASR sequence). The exports of packed datasets (``hf``, ``webdataset``: :mod:`.hub`, with options
of their own) read through the loader and form a layer above :mod:`kubric.datasets`.
"""

import dataclasses
import importlib


@dataclasses.dataclass(frozen=True)
class ExportFormat:
    """One row of :data:`FORMATS`: the export function and its ``kubric export`` sub-command's
    texts (options beyond SCENES and --out, if any, are added in :mod:`.cli`)."""

    target: str          # "module:function"; called as function(SCENES, OUT, **options)
    help: str            # one line in `kubric export --help`
    description: str     # the sub-command's --help text
    out_help: str        # what --out names


#: format name → its row (the ``kubric export`` sub-commands, in this order)
FORMATS = {
    "coco": ExportFormat(
        "kubric.datasets.exports.coco:export_coco",
        "COCO instance annotations (one image per frame / view / rig camera's frame)",
        "One JSON file: images (file_name relative to SCENES; a camera rig's every camera), "
        "instance annotations with RLE masks, boxes [x, y, w, h] in pixels, areas and "
        "categories from the recipe's labels; every asset's licence (licenses, attribution).",
        "output file (.json)"),
    "bop": ExportFormat(
        "kubric.datasets.exports.bop:export_bop",
        "BOP 6D object-pose dataset (models, poses, masks, depth)",
        "BOP's layout: OUT/models (PLY in mm, models_info.json) and OUT/SPLIT/SCENE_ID/ with "
        "rgb, depth, mask, mask_visib, scene_camera.json, scene_gt.json, scene_gt_info.json "
        "(a camera rig's every camera as images of the scene) and licenses.json (every "
        "asset's licence).",
        "output folder (the BOP dataset root)"),
    "tapvid": ExportFormat(
        "kubric.datasets.exports.tapvid:export_tapvid",
        "point tracks in TAP-Vid's pickle layout",
        "Pickle {scene name: {video, points, occluded, target_points, query_points, licenses}} "
        "(TAP-Vid's tapvid_davis.pkl layout) of every scene's tracks.npz.",
        "output file (.pkl)"),
    "nerf": ExportFormat(
        "kubric.datasets.exports.nerf:export_nerf",
        "scenes as NeRF / instant-ngp / nerfstudio folders (multi-view, video, camera rigs)",
        "OUT/SCENE/ with a multi-view scene's transforms_{train,val,test}.json, or a video "
        "scene's transforms.json (nerfstudio's fields, D-NeRF's time; every camera and frame of "
        "a camera rig), each with every asset's licence (licenses), and the files their frames "
        "name (RGBA PNGs, depth, segmentation, ...), nothing else.",
        "output folder (must not exist)"),
    "lasr": ExportFormat(
        "kubric.datasets.exports.lasr:export_lasr",
        "one scene as a LASR / ViSER video sequence (DAVIS layout)",
        "OUT/DAVIS/{JPEGImages,Annotations,FlowFW,FlowBW,Cameras,CamerasWorld}/"
        "Full-Resolution/SEQ/, OUT/configs/SEQ.config and OUT/export.json (with every asset's "
        "licence: licenses) for one scene directory (a camera rig's one camera: --camera).",
        "the LASR folder to create"),
    "hf": ExportFormat(
        "kubric.datasets.exports.hub.hf:export_hf",
        "a packed dataset as Hugging Face `datasets` Parquet with its dataset card",
        "OUT/data/SPLIT-0000k-of-0000n.parquet (one row group per scene), OUT/README.md (the "
        "Hub's YAML header, the card) and OUT/card/*.png; `datasets.load_dataset(OUT)` reads it "
        "(docs/hub.md).",
        "output folder (must not exist, or be empty)"),
    "webdataset": ExportFormat(
        "kubric.datasets.exports.hub.webdataset:export_webdataset",
        "a packed dataset as WebDataset tar shards",
        "OUT/SPLIT-00000k.tar (one sample per scene, or per frame), OUT/shards.json and the "
        "card OUT/README.md (docs/hub.md).",
        "output folder (must not exist, or be empty)"),
}


def exporter(name: str):
    """The export function registered as ``name`` (imports its module)."""
    if name not in FORMATS:
        raise ValueError(f"unknown export format {name!r}; allowed: {list(FORMATS)}")
    module, function = FORMATS[name].target.split(":")
    return getattr(importlib.import_module(module), function)
