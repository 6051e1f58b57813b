"""kubric.file_io: every encoding round-trips (hypothesis), atomic writes, scene directories."""

import io
import json
import os
import pathlib
import tempfile

import numpy as np
import png
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from PIL import Image

import kubric as kb
from kubric import file_io as fio
from kubric.core.color import Color
from kubric.core.quaternion import Quaternion
from kubric.io import json_io, paths, png_io

SETTINGS = settings(max_examples=30, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])
STEP16 = 1.0 / 65535


def _dims(max_side=9):
    return st.tuples(st.integers(1, max_side), st.integers(1, max_side))


def _png_header(path):
    return png_io.png_header(pathlib.Path(path).read_bytes())


def _pypng_samples(path):
    """Independent decode with pypng (its own unfiltering), (H, W, planes)."""
    width, height, pixels, info = png.Reader(filename=str(path)).read_flat()
    return np.asarray(pixels).reshape(height, width, info["planes"])


# ------------------------------------------------------------------------------------- PNG
@SETTINGS
@given(data=st.data(), dtype=st.sampled_from([np.uint8, np.uint16]),
       channels=st.integers(1, 4), dims=_dims())
def test_png_round_trip_8_and_16_bit_1_to_4_channels(data, dtype, channels, dims):
    image = data.draw(hnp.arrays(dtype, dims + (channels,)))
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "img.png"
        fio.write_png(image, path)
        back = fio.read_png(str(path))
        header = _png_header(path)
        independent = _pypng_samples(path)
    stored_channels = 3 if channels == 2 else channels
    assert header["bitdepth"] == (8 if dtype == np.uint8 else 16)
    assert back.dtype == dtype and back.shape == dims + (stored_channels,)
    np.testing.assert_array_equal(back[..., :channels], image)
    np.testing.assert_array_equal(independent, back)
    if channels == 2:  # padded with a zero channel
        assert not back[..., 2].any()


@SETTINGS
@given(data=st.data(), channels=st.integers(1, 4), dims=_dims())
def test_png_float_input_stored_16_bit_truncated_like_upstream(data, channels, dims):
    """Floats become floor(x · 65535) (upstream's truncation): reading back loses less than one
    step and never rounds up."""
    image = data.draw(hnp.arrays(np.float64, dims + (channels,),
                                 elements=st.floats(0.0, 1.0)))
    with tempfile.TemporaryDirectory() as tmp:
        fio.write_png(image, pathlib.Path(tmp) / "f.png")
        raw = fio.read_png(pathlib.Path(tmp) / "f.png")
        back = fio.read_png(pathlib.Path(tmp) / "f.png", rescale_range=(0.0, 1.0))
    assert raw.dtype == np.uint16
    expected = [[[int(v * 65535) for v in px] for px in row] for row in image]  # int() truncates
    np.testing.assert_array_equal(raw[..., :channels], np.array(expected).reshape(image.shape))
    assert back.dtype == np.float32
    error = image - back[..., :channels].astype(np.float64)
    assert np.all(error > -1e-7) and np.all(error < STEP16 + 1e-7)


@SETTINGS
@given(data=st.data(), dims=_dims(), max_label=st.sampled_from([1, 7, 255]))
def test_palette_png_round_trip_8_bit(data, dims, max_label):
    labels = data.draw(hnp.arrays(np.uint32, dims + (1,), elements=st.integers(0, max_label)))
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "seg.png"
        fio.write_palette_png(labels, path)
        back, palette = fio.read_palette_png(path, return_palette=True)
        header = _png_header(path)
        with Image.open(path) as img:
            mode = img.mode
    assert header["color_type"] == 3 and header["bitdepth"] == 8 and mode == "P"
    assert back.dtype == np.uint32
    np.testing.assert_array_equal(back, labels)
    np.testing.assert_array_equal(palette[:256], fio.default_palette())


@SETTINGS
@given(data=st.data(), dims=_dims(),
       big=st.integers(256, 65535), dtype=st.sampled_from([np.uint16, np.uint32, np.int64]))
def test_palette_png_16_bit_grey_beyond_255_labels_never_wraps(data, dims, big, dtype):
    labels = data.draw(hnp.arrays(dtype, dims + (1,), elements=st.integers(0, 65535)))
    labels.flat[0] = big  # guarantee > 255 labels
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "seg.png"
        fio.write_palette_png(labels, path)
        back, palette = fio.read_palette_png(path, return_palette=True)
        header = _png_header(path)
    assert header["color_type"] == 0 and header["bitdepth"] == 16 and palette is None
    np.testing.assert_array_equal(back, labels.astype(np.uint32))
    assert back.flat[0] == big


def test_palette_png_rejects_bad_labels(tmp_path):
    with pytest.raises(ValueError, match="65536 exceeds 65535"):
        fio.write_palette_png(np.full((2, 2, 1), 65536, np.uint32), tmp_path / "a.png")
    with pytest.raises(ValueError, match="≥ 0"):
        fio.write_palette_png(np.full((2, 2, 1), -1, np.int32), tmp_path / "a.png")
    with pytest.raises(TypeError, match="integer dtype, got float32"):
        fio.write_palette_png(np.zeros((2, 2, 1), np.float32), tmp_path / "a.png")
    with pytest.raises(ValueError, match="channel count 3"):
        fio.write_palette_png(np.zeros((2, 2, 3), np.uint8), tmp_path / "a.png")
    with pytest.raises(ValueError, match="label 5 has no palette entry"):
        fio.write_palette_png(np.full((2, 2, 1), 5, np.uint8), tmp_path / "a.png",
                              palette=np.zeros((3, 3), np.uint8))
    with pytest.raises(ValueError, match="palette cannot be used for a 16-bit"):
        fio.write_palette_png(np.full((2, 2, 1), 300, np.uint16), tmp_path / "a.png",
                              palette=np.zeros((256, 3), np.uint8))
    assert not list(tmp_path.iterdir())  # nothing written on bad input


def test_palette_png_custom_palette_is_stored(tmp_path):
    palette = np.array([[0, 0, 0], [255, 0, 0], [0, 255, 0]], np.uint8)
    labels = np.array([[[0], [1]], [[2], [1]]], np.uint8)
    fio.write_palette_png(labels, tmp_path / "p.png", palette=palette)
    with Image.open(tmp_path / "p.png") as img:
        rgb = np.asarray(img.convert("RGB"))
    np.testing.assert_array_equal(rgb, palette[labels[..., 0]])


@SETTINGS
@given(data=st.data(), channels=st.integers(1, 4), dims=_dims(),
       constant=st.booleans())
def test_scaled_png_round_trip_within_quantisation_step(data, channels, dims, constant):
    finite = st.floats(-1e4, 1e4, allow_nan=False, width=32)
    if constant:
        image = np.full(dims + (channels,), data.draw(finite), np.float32)
    else:
        image = data.draw(hnp.arrays(np.float32, dims + (channels,), elements=finite))
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "s.png"
        value_range = fio.write_scaled_png(image, path)
        back = fio.read_scaled_png(path, value_range)
        header = _png_header(path)
    assert header["bitdepth"] == 16
    assert value_range == {"min": float(image.min()), "max": float(image.max())}
    assert all(type(v) is float for v in value_range.values())
    step = (value_range["max"] - value_range["min"]) / 65535
    tol = 0.5 * step + 1e-6 * max(1.0, np.abs(image).max())
    np.testing.assert_allclose(back[..., :channels], image, atol=tol, rtol=0)
    if constant:
        np.testing.assert_array_equal(back[..., :channels], image)


def test_scaled_png_rejects_non_finite_and_integers(tmp_path):
    with pytest.raises(ValueError, match="NaN or inf"):
        fio.write_scaled_png(np.array([[[0.0], [np.nan]]]), tmp_path / "a.png")
    with pytest.raises(TypeError, match="expected float data, got dtype int64"):
        fio.write_scaled_png(np.zeros((2, 2, 1), np.int64), tmp_path / "a.png")
    with pytest.raises(ValueError, match="needs 'min' and 'max'"):
        fio.read_scaled_png(tmp_path / "a.png", {"lo": 0})


def test_write_png_validation_names_value_and_allowed(tmp_path):
    target = tmp_path / "bad.png"
    with pytest.raises(ValueError, match=r"channel count 5 .*allowed: \[1, 2, 3, 4\]"):
        fio.write_png(np.zeros((2, 2, 5), np.uint8), target)
    with pytest.raises(ValueError, match=r"\(H, W, C\) array, got shape \(2, 2\)"):
        fio.write_png(np.zeros((2, 2), np.uint8), target)
    with pytest.raises(ValueError, match=r"\[0, 65535\].*\[70000, 70000\].*never wrapped"):
        fio.write_png(np.array([[[70000]]], np.uint32), target)
    with pytest.raises(ValueError, match=r"\[0, 1\], got range \[-0.5, 0.5\]"):
        fio.write_png(np.array([[[-0.5]], [[0.5]]]), target)
    with pytest.raises(TypeError, match="dtype complex128 cannot be written"):
        fio.write_png(np.zeros((1, 1, 1), complex), target)
    assert not target.exists()


def test_png_encoder_is_deterministic_and_readable_by_pillow():
    rng = np.random.default_rng(1)
    image = rng.integers(0, 256, (5, 6, 4), dtype=np.uint8)
    first, second = fio.encode_png(image), fio.encode_png(image.copy())
    assert first == second
    with Image.open(io.BytesIO(first)) as img:
        assert img.mode == "RGBA"
        np.testing.assert_array_equal(np.asarray(img), image)
    for method in png_io.FILTERS:  # every filter and strategy decodes identically (libpng, pypng)
        for strategy in png_io.STRATEGIES:
            image16 = rng.integers(0, 65536, (4, 7, 3), dtype=np.uint16)
            data = fio.encode_png(image16, filter_method=method, strategy=strategy)
            np.testing.assert_array_equal(fio.decode_png(data)[0], image16)
            _, _, pixels, _ = png.Reader(bytes=data).read_flat()
            np.testing.assert_array_equal(np.asarray(pixels).reshape(4, 7, 3), image16)
    with pytest.raises(ValueError, match="zlib strategy must be one of.*'huffman'"):
        fio.encode_png(image, strategy="huffman")


def test_png_strategy_is_run_length_for_8_bit_colour_only():
    """The measured choice (benchmarks/bench_codecs.py): the default output is the chosen
    strategy's, and differs from the other one's on an image whose repeats are far apart."""
    tile = np.random.default_rng(4).integers(0, 40, (4, 5, 3))
    palette = fio.default_palette()
    cases = [(np.tile(tile, (8, 8, 1)).astype(np.uint8), None, "rle", "default"),
             (np.tile(tile, (8, 8, 1)).astype(np.uint16), None, "default", "rle"),
             (np.tile(tile[..., :1], (8, 8, 1)).astype(np.uint8), palette, "default", "rle")]
    for image, pal, strategy, other in cases:
        assert png_io.default_strategy(8 * image.itemsize, pal is not None) == strategy
        data = fio.encode_png(image, palette=pal)
        assert data == fio.encode_png(image, palette=pal, strategy=strategy)
        assert data != fio.encode_png(image, palette=pal, strategy=other)
        np.testing.assert_array_equal(fio.decode_png(data)[0], image)


def test_png_decoder_reads_files_of_other_encoders_and_rejects_corrupt_ones(tmp_path):
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(5)
    image16 = rng.integers(0, 65536, (6, 9, 3), dtype=np.uint16)
    image16[2:] = image16[1]  # some structure, so libpng's adaptive filter picks several filters
    ok, buf = cv2.imencode(".png", image16[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 9])
    assert ok
    np.testing.assert_array_equal(fio.decode_png(buf.tobytes())[0], image16)
    grey_alpha = rng.integers(0, 65536, (3, 4, 2), dtype=np.uint16)
    data = io.BytesIO()
    png.Writer(4, 3, greyscale=True, alpha=True, bitdepth=16).write_array(data, grey_alpha.ravel())
    np.testing.assert_array_equal(fio.decode_png(data.getvalue())[0], grey_alpha)
    good = fio.encode_png(image16)
    (tmp_path / "cut.png").write_bytes(good[: len(good) // 2])
    with pytest.raises(ValueError, match=r"cut\.png.*corrupt PNG data"):
        fio.read_png(tmp_path / "cut.png")


def test_pngs_decode_with_tfds_opencv_path(tmp_path):
    """TFDS decodes images without TensorFlow as ``cv2.imdecode(bytes, IMREAD_UNCHANGED)`` and
    then reorders BGR(A) to RGB(A) (tensorflow_datasets/core/features/image_feature.py); every
    non-palette PNG kind a scene directory holds must come back exactly that way."""
    cv2 = pytest.importorskip("cv2")
    scene = _scene(np.random.default_rng(6), 1, 5, 7, max_label=300, flow_scale=5.0)
    fio.write_image_dict(scene, tmp_path)
    for name in ("rgba", "segmentation", "forward_flow", "normal", "object_coordinates"):
        path = tmp_path / f"{name}_00000.png"
        stored = fio.read_png(path)
        decoded = cv2.imdecode(np.frombuffer(path.read_bytes(), np.uint8), cv2.IMREAD_UNCHANGED)
        if decoded.ndim == 3:
            conversion = {3: cv2.COLOR_BGR2RGB, 4: cv2.COLOR_BGRA2RGBA}[decoded.shape[2]]
            decoded = cv2.cvtColor(decoded, conversion)
        assert decoded.dtype == stored.dtype, name
        np.testing.assert_array_equal(decoded.reshape(stored.shape), stored, err_msg=name)
    assert fio.read_png(tmp_path / "forward_flow_00000.png").dtype == np.uint16


# ------------------------------------------------------------------------------------ TIFF
@SETTINGS
@given(data=st.data(), channels=st.integers(1, 4), dims=_dims(), compress=st.booleans())
def test_tiff_round_trip_is_bit_exact(data, channels, dims, compress):
    image = data.draw(hnp.arrays(np.float32, dims + (channels,),
                                 elements=st.floats(width=32, allow_nan=True)))
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "d.tiff"
        fio.write_tiff(image, path, compress=compress)
        back = fio.read_tiff(str(path))
        if channels == 1:  # a second, independent reader agrees
            with Image.open(path) as img:
                assert img.mode == "F"
                pillow = np.asarray(img)
    assert back.dtype == np.float32 and back.shape == image.shape
    np.testing.assert_array_equal(back.view(np.uint32), image.view(np.uint32))
    if channels == 1:
        np.testing.assert_array_equal(pillow.view(np.uint32), image[..., 0].view(np.uint32))


def test_tiff_reads_pillow_written_file_and_casts_float64(tmp_path):
    depth = np.random.default_rng(2).uniform(0, 100, (6, 5)).astype(np.float32)
    Image.fromarray(depth).save(tmp_path / "pil.tiff", format="TIFF")
    np.testing.assert_array_equal(fio.read_tiff(tmp_path / "pil.tiff")[..., 0], depth)
    fio.write_tiff(depth[..., None].astype(np.float64), tmp_path / "f64.tiff")
    back = fio.read_tiff(tmp_path / "f64.tiff")
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back[..., 0], depth)
    with pytest.raises(TypeError, match="got dtype uint8"):
        fio.write_tiff(np.zeros((2, 2, 1), np.uint8), tmp_path / "x.tiff")
    with pytest.raises(ValueError, match="not a TIFF file libtiff can read"):
        fio.decode_tiff(b"GIF89a.....")
    Image.fromarray(depth).save(tmp_path / "deflate.tiff", format="TIFF",
                                compression="tiff_adobe_deflate")
    np.testing.assert_array_equal(fio.read_tiff(tmp_path / "deflate.tiff")[..., 0], depth)


# ------------------------------------------------------------------------- JSON and pickle
_scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-2**53, 2**53), st.text(max_size=8),
    st.floats(allow_nan=False, allow_infinity=False),
    st.integers(-1000, 1000).map(np.int64), st.floats(-1e3, 1e3, width=32).map(np.float32),
    st.booleans().map(np.bool_),
)
_json_trees = st.recursive(
    _scalars,
    lambda children: st.one_of(
        st.lists(children, max_size=4), st.lists(children, max_size=3).map(tuple),
        st.dictionaries(st.one_of(st.text(max_size=6), st.integers(-9, 9)), children,
                        max_size=4),
        hnp.arrays(np.float64, st.tuples(st.integers(0, 3), st.integers(1, 3)),
                   elements=st.floats(-1e6, 1e6)),
    ),
    max_leaves=12,
)


def _plain(value):
    """The expected JSON value, computed independently of kubric's converter."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {(k if isinstance(k, str) else str(k)): _plain(v) for k, v in value.items()}
    return value


@SETTINGS
@given(tree=_json_trees)
def test_json_round_trip_and_byte_identical_output(tree):
    data = {"tree": tree}
    with tempfile.TemporaryDirectory() as tmp:
        a, b = pathlib.Path(tmp) / "a.json", pathlib.Path(tmp) / "sub" / "b.json"
        try:
            expected = _plain(data)
        except TypeError:
            return
        try:
            fio.write_json(data, a)
        except ValueError as err:  # e.g. {1: .., "1": ..} collide: must be reported
            assert "both convert" in str(err)
            return
        fio.write_json(data, str(b))
        assert a.read_bytes() == b.read_bytes()
        assert fio.read_json(a) == expected


def test_json_numpy_path_color_set_quaternion_and_determinism(tmp_path):
    data = {
        "b": np.arange(6, dtype=np.int32).reshape(2, 3), "a": np.float32(0.5),
        "path": pathlib.Path("/x/y.png"), "color": Color(1.0, 0.5, 0.0),
        "tags": {"zeta", "alpha", "mid"}, "mixed": {3, "a"}, "q": Quaternion(1, 0, 0, 0),
        7: np.bool_(True), "nested": {"t": (np.uint8(3), np.float64(2.5))},
    }
    fio.write_json(data, tmp_path / "m.json")
    text = (tmp_path / "m.json").read_text()
    assert text.endswith("}\n") and text.index('"7"') < text.index('"a"')  # sorted keys
    back = fio.read_json(tmp_path / "m.json")
    assert back == {
        "b": [[0, 1, 2], [3, 4, 5]], "a": 0.5, "path": "/x/y.png", "color": [1.0, 0.5, 0.0, 1.0],
        "tags": ["alpha", "mid", "zeta"], "mixed": [3, "a"], "q": [1.0, 0.0, 0.0, 0.0],
        "7": True, "nested": {"t": [3, 2.5]},
    }
    data2 = dict(reversed(list(data.items())))  # insertion order does not matter
    fio.write_json(data2, tmp_path / "m2.json")
    assert (tmp_path / "m2.json").read_bytes() == (tmp_path / "m.json").read_bytes()
    with pytest.raises(TypeError, match=r"data\['obj'\]: value of type object has no JSON"):
        fio.write_json({"obj": object()}, tmp_path / "bad.json")
    assert not (tmp_path / "bad.json").exists()


@SETTINGS
@given(tree=_json_trees)
def test_pickle_round_trip(tree):
    with tempfile.TemporaryDirectory() as tmp:
        fio.write_pkl({"x": tree}, pathlib.Path(tmp) / "d.pkl")
        back = fio.read_pkl(pathlib.Path(tmp) / "d.pkl")
    assert json_io.dumps_json(back) == json_io.dumps_json({"x": tree})


# ---------------------------------------------------------------------------------- atomic
def test_as_path_accepts_str_and_path_and_rejects_others():
    assert fio.as_path("a/b.png") == pathlib.Path("a/b.png")
    p = pathlib.Path("x")
    assert fio.as_path(p) is p
    with pytest.raises(TypeError, match="expected a str or os.PathLike.*int 3"):
        fio.as_path(3)


def test_failed_write_keeps_old_file_and_leaves_no_temporary(tmp_path, monkeypatch):
    target = tmp_path / "meta.json"
    fio.write_json({"v": 1}, target)

    class Boom(RuntimeError):
        pass

    def crash_during_rename(src, dst):
        assert pathlib.Path(src).read_bytes().startswith(b"{")  # fully written temp file
        raise Boom("simulated crash before rename")

    monkeypatch.setattr(paths.os, "replace", crash_during_rename)
    with pytest.raises(Boom):
        fio.write_json({"v": 2, "long": list(range(1000))}, target)
    monkeypatch.undo()
    assert fio.read_json(target) == {"v": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["meta.json"]

    real_fdopen = os.fdopen

    class HalfWriter:  # writes half of the data, then fails (e.g. disk full)
        def __init__(self, fd, mode):
            self.fp = real_fdopen(fd, mode)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fp.close()

        def write(self, data):
            self.fp.write(bytes(data[: len(data) // 2]))
            self.fp.flush()
            raise Boom("disk full")

    monkeypatch.setattr(paths.os, "fdopen", HalfWriter)
    with pytest.raises(Boom, match="disk full"):
        fio.write_json({"v": 3, "long": list(range(1000))}, target)
    monkeypatch.undo()
    assert fio.read_json(target) == {"v": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["meta.json"]


def test_killed_writer_never_truncates_final_file(tmp_path):
    """A process killed half-way through writing leaves the previous complete file."""
    import signal
    import subprocess
    import sys

    old = np.full((4, 4, 4), 9, np.uint8)
    target = tmp_path / "rgba_00000.png"
    fio.write_png(old, target)
    code = (
        "import os, sys, time\n"
        "real = os.fdopen\n"
        "class Slow:\n"
        "    def __init__(self, fd, mode): self.fp = real(fd, mode)\n"
        "    def __enter__(self): return self\n"
        "    def __exit__(self, *e): self.fp.close()\n"
        "    def write(self, data):\n"
        "        data = bytes(data); self.fp.write(data[:len(data) // 2]); self.fp.flush()\n"
        "        print('half', flush=True); time.sleep(60); self.fp.write(data[len(data) // 2:])\n"
        "os.fdopen = Slow\n"
        "import numpy as np; from kubric import file_io as f\n"
        "f.write_png(np.full((64, 64, 4), 7, np.uint8), sys.argv[1])\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code, str(target)], stdout=subprocess.PIPE)
    try:
        assert proc.stdout.readline().strip() == b"half"
        partial = [p for p in tmp_path.iterdir() if p.name != target.name]
        assert len(partial) == 1 and partial[0].name.startswith(".rgba_00000.png.")
        assert 0 < partial[0].stat().st_size
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    np.testing.assert_array_equal(fio.read_png(target), old)  # old file intact
    # the hidden leftover is never taken for a frame
    np.testing.assert_array_equal(fio.read_image_dict(tmp_path)["rgba"], old[None])


# ------------------------------------------------------------------------ scene directories
def _scene(rng, t, h, w, max_label, flow_scale):
    normal = rng.normal(size=(t, h, w, 3))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    return {
        "rgba": rng.integers(0, 256, (t, h, w, 4), dtype=np.uint8),
        "depth": rng.uniform(0.1, 50, (t, h, w, 1)).astype(np.float32),
        "z": rng.uniform(0.1, 50, (t, h, w, 1)).astype(np.float32),
        "segmentation": rng.integers(0, max_label + 1, (t, h, w, 1)).astype(np.uint32),
        "forward_flow": (rng.normal(size=(t, h, w, 2)) * flow_scale).astype(np.float32),
        "backward_flow": (rng.normal(size=(t, h, w, 2)) * flow_scale).astype(np.float32),
        "normal": normal.astype(np.float32),
        "object_coordinates": rng.uniform(0, 1, (t, h, w, 3)).astype(np.float32),
        "uv": np.concatenate([rng.uniform(0, 1, (t, h, w, 2)), np.zeros((t, h, w, 1))],
                             -1).astype(np.float32),
    }


EXPECTED_FILES = ["rgba_{:05d}.png", "depth_{:05d}.tiff", "z_{:05d}.tiff",
                  "segmentation_{:05d}.png", "forward_flow_{:05d}.png",
                  "backward_flow_{:05d}.png", "normal_{:05d}.png",
                  "object_coordinates_{:05d}.png", "uv_{:05d}.png"]


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), t=st.integers(1, 3), h=st.integers(1, 6),
       w=st.integers(1, 6), max_label=st.sampled_from([0, 3, 255, 256, 65535]),
       flow_scale=st.sampled_from([0.0, 1e-3, 5.0, 300.0]))
def test_write_image_dict_round_trip(seed, t, h, w, max_label, flow_scale):
    rng = np.random.default_rng(seed)
    scene = _scene(rng, t, h, w, max_label, flow_scale)
    scene["segmentation"][0, 0, 0, 0] = max_label
    with tempfile.TemporaryDirectory() as tmp:
        ranges = fio.write_image_dict(scene, tmp, max_write_threads=4)
        names = sorted(os.listdir(tmp))
        assert names == sorted([f.format(i) for f in EXPECTED_FILES for i in range(t)]
                               + ["data_ranges.json"])
        stored = fio.read_json(pathlib.Path(tmp) / "data_ranges.json")
        seg_depths = {_png_header(pathlib.Path(tmp) / f"segmentation_{i:05d}.png")["bitdepth"]
                      for i in range(t)}
        back = fio.read_image_dict(tmp)
    assert stored == ranges
    for key in ("forward_flow", "backward_flow", "depth", "z"):  # one range per layer per scene
        assert stored[key] == {"min": float(scene[key].min()), "max": float(scene[key].max())}
    assert seg_depths == {8 if max_label <= 255 else 16}  # one format for the whole scene
    assert set(back) == set(scene)
    for key, value in scene.items():
        assert back[key].shape == value.shape, key
    np.testing.assert_array_equal(back["rgba"], scene["rgba"])
    np.testing.assert_array_equal(back["segmentation"], scene["segmentation"])
    assert back["segmentation"].dtype == np.uint32
    np.testing.assert_array_equal(back["depth"], scene["depth"])
    np.testing.assert_array_equal(back["z"], scene["z"])
    for key in ("forward_flow", "backward_flow"):
        span = stored[key]["max"] - stored[key]["min"]
        np.testing.assert_allclose(back[key], scene[key], rtol=0,
                                   atol=0.5 * span / 65535 + 1e-6 * max(1, flow_scale))
    np.testing.assert_allclose(back["normal"], scene["normal"], rtol=0, atol=STEP16 + 1e-6)
    for key in ("object_coordinates", "uv"):
        np.testing.assert_allclose(back[key], scene[key], rtol=0, atol=0.5 * STEP16 + 1e-6)


def test_scene_directory_bytes_are_deterministic(tmp_path):
    """Same seed ⇒ same scene ⇒ byte-identical files, whatever the number of writer threads."""
    def write(seed, directory, threads):
        scene = _scene(np.random.default_rng(seed), 2, 16, 12, max_label=300, flow_scale=5.0)
        scene["segmentation"][1] %= 200  # frame 1 fits 8 bits, the scene still needs 16
        fio.write_image_dict(scene, directory, max_write_threads=threads)
        return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}

    first = write(7, tmp_path / "a", threads=1)
    assert len(first) == 2 * len(EXPECTED_FILES) + 1
    assert write(7, tmp_path / "b", threads=4) == first
    other = write(8, tmp_path / "c", threads=4)
    assert other.keys() == first.keys()
    assert all(other[name] != first[name] for name in first if name.endswith((".png", ".tiff")))


def test_flow_file_encoding_matches_spec(tmp_path):
    flow = np.zeros((2, 3, 4, 2), np.float32)
    flow[0, 0, 0] = (-2.0, 6.0)
    flow[1, 2, 3] = (1.0, -1.0)
    fio.write_image_dict({"forward_flow": flow}, tmp_path)
    assert fio.read_json(tmp_path / "data_ranges.json") == {
        "forward_flow": {"min": -2.0, "max": 6.0}}
    raw = fio.read_png(tmp_path / "forward_flow_00000.png")
    assert raw.dtype == np.uint16 and raw.shape == (3, 4, 3)
    assert tuple(raw[0, 0]) == (0, 65535, 0)  # Δrow=min, Δcol=max, channel 2 = 0
    assert raw[1, 1, 0] == round(2 / 8 * 65535)  # zero flow → (0 - min) / (max - min)
    raw1 = fio.read_png(tmp_path / "forward_flow_00001.png")  # same scene range in frame 1
    assert tuple(raw1[2, 3]) == (round(3 / 8 * 65535), round(1 / 8 * 65535), 0)


def test_normal_encoding_matches_spec_and_constant_flow(tmp_path):
    normal = np.zeros((1, 1, 3, 3), np.float32)
    normal[0, 0] = [[1, 0, 0], [0, -1, 0], [0, 0, 0]]
    fio.write_image_dict({"normal": normal, "backward_flow": np.zeros((1, 1, 3, 2))}, tmp_path)
    raw = fio.read_png(tmp_path / "normal_00000.png")
    assert raw[0].tolist() == [[65535, 32768, 32768], [32768, 0, 32768], [32768] * 3]
    assert fio.read_json(tmp_path / "data_ranges.json") == {
        "backward_flow": {"min": 0.0, "max": 0.0}}
    back = fio.read_image_dict(tmp_path)
    assert sorted(back) == ["backward_flow", "normal"]
    np.testing.assert_array_equal(back["backward_flow"], np.zeros((1, 1, 3, 2)))


def test_write_image_dict_rejects_bad_layers_before_writing(tmp_path):
    good = np.zeros((2, 3, 3, 4), np.uint8)
    cases = [
        ({"rgba": good.astype(np.float32)}, TypeError, "layer 'rgba'.*dtype uint8.*float32"),
        ({"rgba": good[..., :3]}, ValueError, r"layer 'rgba'.*\(T, H, W, 4\).*\(2, 3, 3, 3\)"),
        ({"rgba": good, "depth": np.zeros((3, 3, 3, 1), np.float32)}, ValueError,
         "disagree on"),
        ({"normal": np.full((1, 2, 2, 3), 1.5, np.float32)}, ValueError,
         r"layer 'normal'.*\[-1.0, 1.0\], got range \[1.5, 1.5\]"),
        ({"forward_flow": np.full((1, 2, 2, 2), np.nan, np.float32)}, ValueError, "NaN or inf"),
        ({"segmentation": np.full((1, 2, 2, 1), 70000, np.uint32)}, ValueError,
         "70000 exceeds 65535"),
        ({"albedo": good}, ValueError, "unknown layer.*'albedo'"),
    ]
    for data, error, message in cases:
        with pytest.raises(error, match=message):
            fio.write_image_dict(data, tmp_path / "scene")
        assert not (tmp_path / "scene").exists()


def test_file_templates_and_read_segmentation(tmp_path):
    seg = np.arange(2 * 2 * 3, dtype=np.uint32).reshape(2, 2, 3, 1)
    fio.write_image_dict({"segmentation": seg}, tmp_path,
                         file_templates={"segmentation": "seg/{i:03d}.png"})
    assert sorted(os.listdir(tmp_path / "seg")) == ["000.png", "001.png"]
    back = fio.read_layer(tmp_path, "segmentation", {"segmentation": "seg/{:03d}.png"})
    np.testing.assert_array_equal(back, seg)
    fio.write_image_dict({"segmentation": seg}, tmp_path)
    np.testing.assert_array_equal(fio.read_segmentation(tmp_path), seg)
    (tmp_path / "segmentation_00001.png").unlink()
    fio.write_palette_png(seg[0], tmp_path / "segmentation_00002.png")
    with pytest.raises(ValueError, match=r"missing indices \[1\]"):
        fio.read_segmentation(tmp_path)


def test_data_ranges_json_is_merged_and_required_for_flow(tmp_path):
    flow = np.ones((1, 2, 2, 2), np.float32)
    fio.write_image_dict({"forward_flow": flow}, tmp_path)
    fio.write_image_dict({"backward_flow": -flow}, tmp_path)
    assert set(fio.read_json(tmp_path / "data_ranges.json")) == {"forward_flow",
                                                                  "backward_flow"}
    (tmp_path / "data_ranges.json").write_text(json.dumps({}))
    with pytest.raises(ValueError, match="no range for layer 'forward_flow'"):
        fio.read_image_dict(tmp_path, layers=["forward_flow"])


def test_kb_exports_resolve_to_file_io():
    for name in ("as_path", "write_pkl", "write_json", "write_png", "write_palette_png",
                 "write_scaled_png", "write_tiff", "write_image_dict", "read_png", "read_tiff",
                 "read_json", "read_pkl", "read_palette_png", "read_scaled_png",
                 "read_image_dict", "read_segmentation"):
        assert getattr(kb, name) is getattr(fio, name), name


def test_upstream_batch_writers_use_the_layer_encodings(tmp_path):
    from kubric import file_io
    rgba = np.random.RandomState(0).randint(0, 256, (2, 4, 5, 4)).astype(np.uint8)
    file_io.write_rgba_batch(rgba, tmp_path)
    depth = np.full((2, 4, 5, 1), 3.5, np.float32)
    file_io.write_depth_batch(depth, tmp_path, file_template="d_{:05d}.tiff")
    seg = np.arange(40, dtype=np.uint32).reshape(2, 4, 5, 1) % 7
    file_io.write_segmentation_batch(seg, tmp_path)
    back = file_io.read_image_dict(tmp_path, layers=["rgba", "segmentation"])
    np.testing.assert_array_equal(back["rgba"], rgba)
    np.testing.assert_array_equal(back["segmentation"], seg)
    np.testing.assert_array_equal(file_io.read_tiff(tmp_path / "d_00001.tiff"), depth[1])
    assert file_io.write_coordinates_batch is file_io.write_object_coordinates_batch
