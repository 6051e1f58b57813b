"""Our hand-written PNG / TIFF codecs against maintained libraries, side by side.

``handwritten`` is the codec ``kubric/io`` had before this comparison (``handwritten_codecs.py``:
numpy + zlib PNG encoder at "up" rows / zlib level 2 / default strategy, numpy or pypng PNG
reader, our TIFF writer and strip-TIFF reader); ``kubric`` is what the package uses now (the same
encoders, zlib's run-length strategy for 8-bit colour PNGs, libpng / libtiff readers via
imagecodecs).

For each kind of file a scene directory stores, at 256² and 512², each codec that can write that
kind encodes and decodes one realistic frame (the synthetic scene of ``bench_file_io``: smooth
shaded spheres over a checker floor, render noise, seeded rng). Printed per codec: median encode
and decode milliseconds of CPU time of the calling thread (every codec here runs on it; the
machine is shared, and CPU time is not inflated by other processes the way wall time is) over
interleaved repeats, bytes, whether the decode gives back exactly the input (``exact``; palette
PNGs: labels and palette), whether two encodes give the same bytes (``det``), and encode / decode
/ size ratios against ``handwritten`` measured in the same run (< 1: faster or smaller). A codec
that cannot store a kind (Pillow and 48-bit PNG, OpenCV and palette PNG) says why.

zlib level: the libraries run at level 2 and, marked ``:default``, at their own default where it
differs; ``kubric-settings``: the filter and strategy our encoder uses; ``paeth+rle``: Paeth rows
and run-length zlib (smaller 16-bit files that decode slower). Libraries that are not installed
are skipped. Run: ``.venv/bin/python benchmarks/bench_codecs.py [--repeats N] [--sizes 256 512]``.
"""

from __future__ import annotations

import argparse
import io
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import handwritten_codecs as hw  # noqa: E402
import smoke_mode  # noqa: E402
from bench_file_io import synthetic_scene  # noqa: E402

from kubric.io import png_io, tiff_io  # noqa: E402

LEVEL = 2
KINDS = {
    "rgba8": "8-bit RGBA PNG (rgba)",
    "palette8": "8-bit palette PNG (segmentation ≤ 255 labels)",
    "grey16": "16-bit grey PNG (segmentation > 255 labels)",
    "flow16": "16-bit RGB PNG (forward_flow, scaled to its range)",
    "normal16": "16-bit RGB PNG (normal)",
    "coords16": "16-bit RGB PNG (object_coordinates)",
    "float32": "float32 1-channel TIFF (depth)",
}
RGB16 = ("flow16", "normal16", "coords16")


def layer_frames(size: int, seed: int = 0) -> dict[str, np.ndarray]:
    """One frame of every kind, (H, W, C), from the seeded synthetic scene."""
    rng = np.random.default_rng(seed)
    scene = synthetic_scene(rng, frames=1, size=size, num_objects=12)
    seg = scene["segmentation"][0]
    ids = rng.permutation(np.arange(256, 65536))[: int(seg.max()) + 1]  # large instance ids
    ids[0] = 0
    normal = scene["normal"][0].astype(np.float64)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    flow = scene["forward_flow"][0]
    flow = np.concatenate([flow, np.zeros_like(flow[..., :1])], -1)
    return {
        "rgba8": scene["rgba"][0],
        "palette8": seg.astype(np.uint8),
        "grey16": ids[seg].astype(np.uint16),
        "flow16": png_io.scale_to_uint16(flow, flow.min(), flow.max()),
        "normal16": np.rint((normal + 1) / 2 * 65535).astype(np.uint16),
        "coords16": np.rint(scene["object_coordinates"][0] * 65535.0).astype(np.uint16),
        "float32": scene["depth"][0],
    }


# ------------------------------------------------------------------------------------ codecs
def _package(encode_png, decode_png, decode_tiff):
    """A codec set of the package: ``handwritten`` (before) or ``kubric`` (now)."""
    palette = png_io.default_palette()
    png = (encode_png, lambda b: decode_png(b)[0])
    return {**{k: png for k in ("rgba8", "grey16") + RGB16},
            "palette8": (lambda a: encode_png(a, palette=palette), decode_png),
            "float32": (tiff_io.encode_tiff, decode_tiff)}


def _kubric_deflate():
    return {"float32": (lambda a: tiff_io.encode_tiff(a, compress=True), tiff_io.decode_tiff)}


def _pillow(level: int | None):
    from PIL import Image

    kwargs = {} if level is None else {"compress_level": level}
    palette = png_io.default_palette().tobytes()

    def save(img, fmt="PNG", **extra):
        buf = io.BytesIO()
        img.save(buf, fmt, **extra)
        return buf.getvalue()

    def decode(data, channels):
        with Image.open(io.BytesIO(data)) as img:
            return np.asarray(img).reshape(img.height, img.width, channels)

    def enc_palette(a):
        img = Image.fromarray(a[..., 0])
        img.putpalette(palette)
        return save(img, **kwargs)

    def dec_palette(data):
        with Image.open(io.BytesIO(data)) as img:
            pal = np.array(img.getpalette(), np.uint8).reshape(-1, 3)
            return np.asarray(img)[..., None], pal

    codecs = {
        "rgba8": (lambda a: save(Image.fromarray(a, "RGBA"), **kwargs), lambda b: decode(b, 4)),
        "palette8": (enc_palette, dec_palette),
        "grey16": (lambda a: save(Image.fromarray(a[..., 0]), **kwargs),
                   lambda b: decode(b, 1).astype(np.uint16)),
        **{k: "Pillow stores 48-bit RGB as 8 bits per sample" for k in RGB16},
    }
    if level is None:
        codecs["float32"] = (lambda a: save(Image.fromarray(a[..., 0], "F"), "TIFF"),
                             lambda b: decode(b, 1))
    return codecs


def _pypng(level: int | None):
    import png

    def encode(a, **extra):
        h, w, c = a.shape
        writer = png.Writer(w, h, greyscale=c < 3, alpha=c in (2, 4), bitdepth=a.dtype.itemsize * 8,
                            compression=level, **extra)
        buf = io.BytesIO()
        writer.write_array(buf, a.reshape(-1))
        return buf.getvalue()

    def decode(data):
        w, h, pixels, info = png.Reader(bytes=data).read_flat()
        dtype = np.uint16 if info["bitdepth"] == 16 else np.uint8
        arr = np.asarray(pixels, dtype).reshape(h, w, info["planes"])
        if "palette" in info:
            return arr, np.array(info["palette"], np.uint8)
        return arr

    palette = [tuple(c) for c in png_io.default_palette().tolist()]

    def enc_palette(a):
        h, w, _ = a.shape
        buf = io.BytesIO()
        png.Writer(w, h, palette=palette, bitdepth=8, compression=level).write_array(
            buf, a.reshape(-1))
        return buf.getvalue()

    return {**{k: (encode, decode) for k in ("rgba8", "grey16") + RGB16},
            "palette8": (enc_palette, decode)}


def _opencv(level: int | None):
    import cv2

    params = [] if level is None else [cv2.IMWRITE_PNG_COMPRESSION, level]

    def encode(a, conversion=None):
        img = a if conversion is None else cv2.cvtColor(a, conversion)
        ok, buf = cv2.imencode(".png", img, params)
        assert ok
        return buf.tobytes()

    def decode(data, conversion=None, channels=None):
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        img = img if conversion is None else cv2.cvtColor(img, conversion)
        return img.reshape(img.shape[0], img.shape[1], -1)

    codecs = {
        "rgba8": (lambda a: encode(a, cv2.COLOR_RGBA2BGRA),
                  lambda b: decode(b, cv2.COLOR_BGRA2RGBA)),
        "palette8": "OpenCV writes no palette PNG (reads palette PNGs as colours)",
        "grey16": (encode, decode),
        **{k: (lambda a: encode(a, cv2.COLOR_RGB2BGR), lambda b: decode(b, cv2.COLOR_BGR2RGB))
           for k in RGB16},
    }
    if level is None:
        def enc_tiff(a):
            ok, buf = cv2.imencode(".tiff", a[..., 0])
            assert ok
            return buf.tobytes()
        codecs["float32"] = (enc_tiff, decode)
    return codecs


def _imagecodecs(level: int | None, settings: str = ""):
    """libpng; settings "kubric": our encoder's (up rows, per-bit-depth strategy); "paeth+rle"."""
    import imagecodecs as ic

    def decode(b):
        x = ic.png_decode(b)
        return x.reshape(x.shape[0], x.shape[1], -1)

    def encode(a):
        kwargs = {}
        if settings == "kubric":
            strategy = png_io.default_strategy(8 * a.itemsize)
            kwargs = {"filter": ic.PNG.FILTER.UP, "strategy": png_io.STRATEGIES[strategy]}
        elif settings == "paeth+rle":
            kwargs = {"filter": ic.PNG.FILTER.PAETH, "strategy": ic.PNG.STRATEGY.RLE}
        return ic.png_encode(a, level=level, **kwargs)

    libpng = (encode, decode)
    return {**{k: libpng for k in ("rgba8", "grey16") + RGB16},
            "palette8": "imagecodecs.png_encode takes no palette"}


def _spng(level: int | None):
    import imagecodecs as ic

    def decode(b):
        x = ic.spng_decode(b)
        return x.reshape(x.shape[0], x.shape[1], -1)

    spng = (lambda a: ic.spng_encode(a, level=level), decode)
    return {**{k: spng for k in ("rgba8", "grey16") + RGB16},
            "palette8": "imagecodecs.spng_encode takes no palette"}


def _tifffile(level: int | None):
    import tifffile

    def encode(a, **kwargs):
        buf = io.BytesIO()
        tifffile.imwrite(buf, a[..., 0], metadata=None, software=False, **kwargs)
        return buf.getvalue()

    def decode(b):
        return tifffile.imread(io.BytesIO(b))[..., None]

    if level is None:
        return {"float32": (encode, decode)}
    return {"float32": (lambda a: encode(a, compression="zlib", compressionargs={"level": level},
                                         predictor=True), decode)}


def _libtiff(level: int | None):
    import imagecodecs as ic

    def decode(b):
        x = ic.tiff_decode(b)
        return x.reshape(x.shape[0], x.shape[1], -1)

    if level is None:
        return {"float32": (lambda a: ic.tiff_encode(a[..., 0]), decode)}
    return {"float32": (lambda a: ic.tiff_encode(a[..., 0], level=level, compression="deflate",
                                                 predictor=True), decode)}


def codec_table() -> dict[str, dict]:
    """codec name → {kind: (encode, decode) or the reason it cannot store that kind}."""
    makers = [  # (row label, factory, its arguments)
        ("handwritten", _package, (hw.encode_png, hw.decode_png, hw.decode_tiff)),
        ("kubric", _package, (png_io.encode_png, png_io.decode_png, tiff_io.decode_tiff)),
        ("kubric:tiff-deflate", _kubric_deflate, ()),
        ("pillow:2", _pillow, (LEVEL,)),
        ("pillow:default", _pillow, (None,)),
        ("pypng:2", _pypng, (LEVEL,)),
        ("opencv:2", _opencv, (LEVEL,)),
        ("opencv:default", _opencv, (None,)),
        ("imagecodecs.png:2", _imagecodecs, (LEVEL,)),
        ("imagecodecs.png:default", _imagecodecs, (None,)),
        ("imagecodecs.png:kubric-settings", _imagecodecs, (LEVEL, "kubric")),
        ("imagecodecs.png:2+paeth+rle", _imagecodecs, (LEVEL, "paeth+rle")),
        ("imagecodecs.spng:2", _spng, (LEVEL,)),
        ("tifffile:raw", _tifffile, (None,)),
        ("tifffile:deflate2+pred", _tifffile, (LEVEL,)),
        ("imagecodecs.tiff:raw", _libtiff, (None,)),
        ("imagecodecs.tiff:deflate2+pred", _libtiff, (LEVEL,)),
    ]
    table = {}
    for label, make, args in makers:
        try:
            table[label] = make(*args)
        except ImportError as err:
            print(f"skipping {label}: {err}")
    return table


# ------------------------------------------------------------------------------ measurement
def exact(kind: str, image: np.ndarray, decoded) -> bool:
    if kind == "palette8":
        labels, palette = decoded
        ref = png_io.default_palette()
        return (np.array_equal(labels.reshape(image.shape), image)
                and np.array_equal(np.asarray(palette)[: len(ref)], ref))
    decoded = np.asarray(decoded)
    if decoded.shape != image.shape or decoded.dtype != image.dtype:
        return False
    if kind == "float32":
        return np.array_equal(decoded.view(np.uint32), image.view(np.uint32))
    return np.array_equal(decoded, image)


def measure(image, codec, kind: str) -> tuple[dict, bytes]:
    encode, decode = codec
    data = encode(image)
    row = {"bytes": len(data), "exact": exact(kind, image, decode(data)),
           "det": encode(image.copy()) == data, "enc": [], "dec": []}
    return row, data


def run(sizes, repeats: int) -> None:
    table = codec_table()
    print(f"thread CPU ms, median of {repeats} interleaved repeats; ratios are codec / handwritten "
          "(same run)")
    for size in sizes:
        frames = layer_frames(size)
        for kind, title in KINDS.items():
            image = frames[kind]
            rows, data = {}, {}
            for name, codecs in table.items():
                codec = codecs.get(kind)
                if codec is None:
                    continue
                if isinstance(codec, str):
                    rows[name] = codec
                    continue
                try:
                    rows[name], data[name] = measure(image, codec, kind)
                except Exception as err:  # a library that cannot handle this kind: say so
                    rows[name] = f"fails: {type(err).__name__}: {err}"

            runnable = [n for n, r in rows.items() if isinstance(r, dict)]
            order = np.random.default_rng(size)
            for _ in range(repeats):  # interleaved in a fresh order each time: no codec always
                for name in order.permutation(runnable):  # first, none always after the same one
                    encode, decode = table[name][kind]
                    start = time.thread_time()
                    encode(image)
                    middle = time.thread_time()
                    decode(data[name])
                    rows[name]["enc"].append(middle - start)
                    rows[name]["dec"].append(time.thread_time() - middle)
            print(f"\n{size}² {title}")
            print(f"  {'codec':32s} {'enc ms':>8s} {'dec ms':>8s} {'bytes':>9s} {'exact':>5s} "
                  f"{'det':>4s} {'enc×':>6s} {'dec×':>6s} {'size×':>6s}")
            base = rows["handwritten"]
            base_enc, base_dec = np.median(base["enc"]), np.median(base["dec"])
            for name, row in rows.items():
                if isinstance(row, str):
                    print(f"  {name:32s} {row}")
                    continue
                enc, dec = np.median(row["enc"]) * 1e3, np.median(row["dec"]) * 1e3
                print(f"  {name:32s} {enc:8.2f} {dec:8.2f} {row['bytes']:9d} "
                      f"{'yes' if row['exact'] else 'NO':>5s} {'yes' if row['det'] else 'NO':>4s} "
                      f"{enc / base_enc / 1e3:6.2f} {dec / base_dec / 1e3:6.2f} "
                      f"{row['bytes'] / base['bytes']:6.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=smoke_mode.size(21, 1))
    parser.add_argument("--sizes", type=int, nargs="+", default=smoke_mode.size([256, 512], [32]))
    args = parser.parse_args()
    run(args.sizes, args.repeats)


if __name__ == "__main__":
    main()
