"""The dataset card (``kubric datasets card DATASET``, and README.md of ``kubric export hf``):
splits and counts; objects per scene, categories, visibility, flow-magnitude and depth
histograms, track counts (PNG bar charts, their numbers in ``card/stats.json``); a contact sheet
of random scenes; every asset source's licence and the attribution list it requires; the
generating command and versions.

Statistics are accumulated one example at a time (:class:`CardStats`: fixed-bin histograms and
a reservoir of a few frames), so the card of any number of scenes takes flat memory. Licences,
the command and the versions come from the scene folders' ``metadata.json`` (a packed dataset
does not hold them): every asset :func:`kubric.datasets.exports.licences.scene_licences` finds
(objects, background HDRI, PBR image sets, characters and motion clips) is attributed.
"""

from __future__ import annotations

import collections
import dataclasses
import json
import pathlib

import numpy as np

from kubric.core.camera_geometry import BACKGROUND_DEPTH
from kubric.datasets.exports import licences
from kubric.datasets.exports.hub import plots
from kubric.datasets.exports.hub.common import progress_bar, scene_examples, splits_of, writing
from kubric.datasets.layout import read_info
from kubric.datasets.tfds_io import flatten
from kubric.io import scene_dir
from kubric.io.json_io import read_json
from kubric.io.scene_reader import dequantise
from kubric.io.schema import Schema

#: the card's pictures, in the output folder
CARD_DIR = "card"
#: histogram bin edges: flow magnitude (pixels per frame), depth (metres), visible fraction
FLOW_EDGES = (0, 0.25, 0.5, 1, 2, 4, 8, 16, 32, 64, np.inf)
DEPTH_EDGES = (0, 0.5, 1, 2, 4, 8, 16, 32, 64, 128, np.inf)
VISIBILITY_EDGES = (0, 1e-9, 0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0 + 1e-9)
#: licences (their SPDX id, the text before the first space) a card may name in its header,
#: most permissive first: a dataset mixing them carries the last one present
OPEN_LICENCES = ("cc0-1.0", "cc-by-4.0")


def _edge_labels(edges, unit="") -> list[str]:
    out = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        out.append(f">={lo:g}{unit}" if hi == np.inf else f"{lo:g}-{hi:g}")
    return out


class CardStats:
    """The card's numbers, accumulated over examples (:meth:`add`), in flat memory."""

    def __init__(self, schema: Schema, dims: dict, sheet_size: int = 8, seed: int = 0):
        self.schema, self.dims = schema, dict(dims)
        self.by_name = {f.name: f for f in schema.features}
        self.counts: collections.Counter = collections.Counter()
        self.objects: collections.Counter = collections.Counter()
        self.categories = {f.name: collections.Counter() for f in schema.features
                           if f.encoding == "class_label" and f.sequence}
        self.visibility = np.zeros(len(VISIBILITY_EDGES) - 1, np.int64)
        self.flow = np.zeros(len(FLOW_EDGES) - 1, np.int64)
        self.depth = np.zeros(len(DEPTH_EDGES) - 1, np.int64)
        self.background = 0
        self.tracks: collections.Counter = collections.Counter()
        self.rng = np.random.RandomState(seed)
        self.sheet_size, self.seen = sheet_size, 0
        self.sheet: list[tuple[str, np.ndarray]] = []

    def add(self, split: str, example: dict) -> None:
        flat = flatten(example)
        self.counts[split] += 1
        instance = next((f for f in self.schema.features if f.sequence == "instances/"), None)
        if instance is not None:
            self.objects[len(flat[instance.name])] += 1
        for name, counter in self.categories.items():
            names = self.by_name[name].names
            counter.update(names[int(i)] for i in np.asarray(flat[name]).reshape(-1))
        if "instances/visibility" in flat and len(flat["instances/visibility"]):
            area = float(self.dims["H"] * self.dims["W"])
            fraction = np.asarray(flat["instances/visibility"], np.float64).reshape(-1) / area
            self.visibility += np.histogram(fraction, VISIBILITY_EDGES)[0]
        flow = self._physical(flat, "forward_flow")
        if flow is not None:
            self.flow += np.histogram(np.linalg.norm(flow, axis=-1), FLOW_EDGES)[0]
        depth = self._physical(flat, "depth")
        if depth is not None:
            background = depth >= BACKGROUND_DEPTH * 0.999
            self.background += int(background.sum())
            self.depth += np.histogram(depth[~background], DEPTH_EDGES)[0]
        tracked = [f for f in self.schema.features if f.name.startswith("tracks/")
                   and f.shape[:1] == ("P",)]
        if tracked:
            self.tracks[len(flat[tracked[0].name])] += 1
        self._sample(flat)

    def _physical(self, flat: dict, name: str):
        """Layer ``name`` in its unit (a uint16 layer dequantised with its range), or None."""
        if name not in flat:
            return None
        value = flat[name]
        key = f"metadata/{name}_range"
        if value.dtype == np.uint16 and key in flat:
            return dequantise(value, flat[key])
        return np.asarray(value, np.float32)

    def _sample(self, flat: dict) -> None:
        """Reservoir sampling: each example has the same chance to be on the sheet."""
        if "video" not in flat:
            return
        self.seen += 1
        item = (str(flat.get("metadata/video_name", self.seen)), np.asarray(flat["video"][0]))
        if len(self.sheet) < self.sheet_size:
            self.sheet.append(item)
        else:
            j = self.rng.randint(0, self.seen)
            if j < self.sheet_size:
                self.sheet[j] = item


@dataclasses.dataclass
class Provenance:
    """What the scene folders say: assets to attribute, the command, the versions."""

    assets: dict = dataclasses.field(default_factory=dict)   # (kind, asset) → AssetLicence
    command: str = ""
    versions: dict = dataclasses.field(default_factory=dict)
    seeds: tuple[int, int] | None = None
    characters: collections.Counter = dataclasses.field(default_factory=collections.Counter)
    clips: collections.Counter = dataclasses.field(default_factory=collections.Counter)

    @property
    def licences(self) -> collections.Counter:
        return collections.Counter(a.license for a in self.assets.values())

    @property
    def license_id(self) -> str:
        """The Hub header's licence: the assets' own when they are all open ones (the most
        restrictive of them), else ``other``."""
        ids = {lic.split(" ", 1)[0].lower() for lic in self.licences}
        if ids and ids <= set(OPEN_LICENCES):
            return [i for i in OPEN_LICENCES if i in ids][-1]
        return "other"


def _people(meta: dict, out: Provenance) -> None:
    """The characters and motion clips of a scene's people, counted."""
    for instance in meta.get("instances", []):
        for key, counter in (("character_id", out.characters), ("motion_id", out.clips)):
            if isinstance(instance.get(key), str):
                counter[instance[key]] += 1


def generating_command(flags: dict) -> str:
    """``kubric generate RECIPE --set KEY=VALUE ...`` of a scene's options (``flags``)."""
    sets = []
    for key, value in sorted(flags.items()):
        if key in ("recipe", "seed") or value is None:
            continue
        if isinstance(value, (list, tuple)):
            value = ("x" if key == "resolution" else ",").join(str(v) for v in value)
        elif isinstance(value, bool):
            value = str(value).lower()
        sets.append(f"--set {key}={value}")
    return " ".join(["kubric generate", str(flags.get("recipe", "RECIPE")), *sets])


def provenance(scenes_dir) -> Provenance:
    """Licences, command and versions from the complete scenes of ``scenes_dir``."""
    out = Provenance()
    if scenes_dir is None:
        return out
    root = pathlib.Path(scenes_dir)
    paths = [root] if scene_dir.is_complete(root) else scene_dir.survey(root)[0]
    seeds = []
    for path in paths:
        meta = read_json(path / scene_dir.METADATA_FILE)
        for asset in licences.scene_licences(meta):
            out.assets.setdefault(asset.key, asset)
        _people(meta, out)
        if not out.command:
            out.command = generating_command(meta.get("flags", {}))
            out.versions = dict(meta.get("metadata", {}).get("versions", {}))
        seeds.append(int(meta.get("metadata", {}).get("seed", -1)))
    if seeds:
        out.seeds = (min(seeds), max(seeds))
    return out


@dataclasses.dataclass
class Card:
    name: str
    description: str
    stats: CardStats
    provenance: Provenance
    pictures: dict          # title → path relative to the card's folder
    kubric_version: str

    @property
    def license_id(self) -> str:
        return self.provenance.license_id

    def numbers(self) -> dict:
        """The card's numbers as JSON (``card/stats.json``): counts, histograms with their bin
        edges, licences and attribution."""
        s, p = self.stats, self.provenance
        edges = lambda e: [float(v) for v in e]  # noqa: E731 (inf is JSON's Infinity)
        return {
            "splits": dict(s.counts), "dims": s.dims,
            "objects_per_scene": {str(k): v for k, v in sorted(s.objects.items())},
            "categories": {k: dict(sorted(v.items())) for k, v in s.categories.items()},
            "visibility": {"edges": edges(VISIBILITY_EDGES), "counts": s.visibility.tolist()},
            "flow_magnitude_px": {"edges": edges(FLOW_EDGES), "counts": s.flow.tolist()},
            "depth_m": {"edges": edges(DEPTH_EDGES), "counts": s.depth.tolist(),
                        "background": s.background},
            "tracks_per_scene": {str(k): v for k, v in sorted(s.tracks.items())},
            "licences": dict(p.licences),
            "attribution": licences.as_json(licences.merged([p.assets.values()])),
            "characters": dict(sorted(p.characters.items())),
            "clips": dict(sorted(p.clips.items())),
            "command": p.command, "versions": p.versions,
        }

    def markdown(self, citation: str | None = None) -> str:
        s, p = self.stats, self.provenance
        lines = [f"# {self.name}", "", self.description, "", "## Splits", "",
                 "| split | scenes |", "|---|---|"]
        lines += [f"| {k} | {v} |" for k, v in s.counts.items()]
        lines += ["", f"Frames per scene: {s.dims.get('T')}; resolution "
                  f"{s.dims.get('W')}×{s.dims.get('H')} pixels.", "", "## Contents", ""]
        if s.objects:
            total = sum(k * v for k, v in s.objects.items())
            lines.append(f"Objects per scene: {min(s.objects)}–{max(s.objects)}, mean "
                         f"{total / sum(s.objects.values()):.2f} ({total} in all).")
        for name, counter in s.categories.items():
            lines.append(f"`{name}`: " + ", ".join(f"{k} {v}" for k, v in
                                                    sorted(counter.items())) + ".")
        if s.tracks:
            lines.append("Point tracks per scene: " + ", ".join(
                f"{k} ({v} scenes)" for k, v in sorted(s.tracks.items())) + ".")
        if s.background:
            lines.append(f"Background pixels (no surface): {s.background}.")
        for what, counter in (("Characters", p.characters), ("Motion clips", p.clips)):
            if counter:
                lines.append(f"{what} (instances): " + ", ".join(
                    f"{k} {v}" for k, v in sorted(counter.items())) + ".")
        lines.append("")
        for title, path in self.pictures.items():
            lines += [f"### {title}", "", f"![{title}]({path})", ""]
        lines += ["## Licences and attribution", ""]
        if not p.assets:
            lines += ["No asset licences recorded (give the scene folders: `--scenes`).", ""]
        else:
            lines += ["| licence | assets |", "|---|---|"]
            lines += [f"| {lic} | {n} |" for lic, n in sorted(p.licences.items())]
            lines += ["", "Attribution (every asset the scenes use):", ""]
            lines += [f"- `{a.asset}`{f' ({a.description})' if a.description else ''}: "
                      f"{a.license}" for a in licences.merged([p.assets.values()])]
            lines.append("")
        lines += ["## How it was made", ""]
        if p.command:
            seeds = f"# seeds {p.seeds[0]} to {p.seeds[1]}\n" if p.seeds else ""
            lines += [f"```sh\n{seeds}{p.command}\n```", ""]
        versions = {"kubric (pack)": self.kubric_version, **p.versions}
        lines += ["Versions: " + ", ".join(f"{k} {v}" for k, v in versions.items()) + ".", ""]
        if citation:
            lines += ["## Citation", "", "```bibtex", citation, "```", ""]
        return "\n".join(lines)


def _pictures(stats: CardStats, folder: pathlib.Path) -> dict:
    folder.mkdir(parents=True, exist_ok=True)
    out = {}

    def chart(title, file, labels, values):
        plots.bar_chart(labels, list(values), title, folder / file)
        out[title] = f"{CARD_DIR}/{file}"

    if stats.objects:
        keys = list(range(min(stats.objects), max(stats.objects) + 1))
        chart("Objects per scene", "objects.png", keys, [stats.objects[k] for k in keys])
    for name, counter in stats.categories.items():
        chart(f"Categories ({name})", f"{name.replace('/', '-')}.png", sorted(counter),
              [counter[k] for k in sorted(counter)])
    if stats.visibility.any():
        chart("Visible fraction of the image per instance and frame", "visibility.png",
              ["0"] + _edge_labels(VISIBILITY_EDGES[1:]), stats.visibility)
    if stats.flow.any():
        chart("Forward flow magnitude (pixels per frame)", "flow.png",
              _edge_labels(FLOW_EDGES), stats.flow)
    if stats.depth.any():
        chart("Depth (metres, background left out)", "depth.png", _edge_labels(DEPTH_EDGES),
              stats.depth)
    if stats.tracks:
        keys = sorted(stats.tracks)
        chart("Point tracks per scene", "tracks.png", keys, [stats.tracks[k] for k in keys])
    if stats.sheet:
        names, frames = zip(*sorted(stats.sheet), strict=True)
        plots.contact_sheet(list(frames), list(names), folder / "contact_sheet.png")
        out["Random scenes (first frame)"] = f"{CARD_DIR}/contact_sheet.png"
    return out


def build_card(dataset_dir, scenes_dir, out_dir, stats: CardStats | None = None,
               progress: bool = True) -> Card:
    """The card of a packed dataset; its pictures are written into ``out_dir/card/``.
    ``stats`` already accumulated over every example (an export's pass) are used as they are;
    else the examples are read here."""
    info = read_info(dataset_dir)
    schema = Schema.from_json(info["schema_json"])
    if stats is None:
        stats = CardStats(schema, info["dims"])
        counts = splits_of(pathlib.Path(dataset_dir))
        bar = progress_bar(sum(counts.values()), "card", progress)
        for split in counts:
            for example in scene_examples(dataset_dir, split):
                stats.add(split, example)
                bar.update(1)
        bar.close()
    pictures = _pictures(stats, pathlib.Path(out_dir) / CARD_DIR)
    card = Card(str(info["name"]), schema.description, stats, provenance(scenes_dir), pictures,
                str(info.get("kubric_version", "")))
    (pathlib.Path(out_dir) / CARD_DIR / "stats.json").write_text(
        json.dumps(card.numbers(), indent=1) + "\n")
    return card


def write_card(dataset_dir, out, scenes_dir=None, progress: bool = True) -> pathlib.Path:
    """``kubric datasets card``: ``out/README.md`` and ``out/card/*.png`` (written whole or not
    at all)."""
    with writing(out) as work:
        card = build_card(dataset_dir, scenes_dir, work, progress=progress)
        (work / "README.md").write_text(card.markdown())
    return pathlib.Path(out)


__all__ = ["Card", "CardStats", "Provenance", "build_card", "generating_command",
           "provenance", "write_card"]
