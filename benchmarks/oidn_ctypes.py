"""Intel Open Image Denoise on numpy images, through the library the ``bpy`` wheel ships
(``bpy/lib/libOpenImageDenoise.so.2``, the same OIDN 2.x Cycles denoises with): for benchmarks that
denoise buffers Cycles did not (``bench_temporal_accumulation.py``).

:func:`denoise` does what Cycles' OIDN denoiser does with ``denoising_input_passes =
RGB_ALBEDO_NORMAL`` and the ACCURATE prefilter: the albedo and normal guides are each denoised
first (an ``RT`` filter with only that guide), then the colour with both guides and ``cleanAux``.
Checked against Cycles by ``bench_temporal_accumulation.py``'s row "64 spp + OIDN (denoised
outside Cycles)": 64 spp's noisy frame and guides denoised here give Cycles' own result within
the noise (worst error ratio 0.99 / 1.04 on MOVi-A / MOVi-C, docs/render-cost.md).

Images are (H, W, 3+) float arrays, linear; only the first three channels are read.
"""

from __future__ import annotations

import ctypes
import importlib.util
import pathlib

import numpy as np

_QUALITY = {"HIGH": 6, "BALANCED": 5, "FAST": 4}  # OIDNQuality
_FLOAT3 = 3  # OIDN_FORMAT_FLOAT3
_CPU = 1  # OIDN_DEVICE_TYPE_CPU
_state: dict = {}


def library_path() -> pathlib.Path:
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        raise SystemExit("oidn_ctypes: the bpy wheel is not installed (it ships the OIDN library)")
    path = pathlib.Path(spec.origin).parent / "lib" / "libOpenImageDenoise.so.2"
    if not path.is_file():
        raise SystemExit(f"oidn_ctypes: {path} is missing from the bpy wheel")
    return path


def _device():
    if "device" not in _state:
        lib = ctypes.CDLL(str(library_path()))
        vp, size = ctypes.c_void_p, ctypes.c_size_t
        lib.oidnNewDevice.restype, lib.oidnNewDevice.argtypes = vp, [ctypes.c_int]
        lib.oidnNewFilter.restype, lib.oidnNewFilter.argtypes = vp, [vp, ctypes.c_char_p]
        lib.oidnGetDeviceError.argtypes = [vp, ctypes.POINTER(ctypes.c_char_p)]
        lib.oidnSetSharedFilterImage.argtypes = [vp, ctypes.c_char_p, vp, ctypes.c_int] + [size] * 5
        lib.oidnSetFilterBool.argtypes = [vp, ctypes.c_char_p, ctypes.c_bool]
        lib.oidnSetFilterInt.argtypes = [vp, ctypes.c_char_p, ctypes.c_int]
        for name in ("oidnCommitDevice", "oidnCommitFilter", "oidnExecuteFilter",
                     "oidnReleaseFilter"):
            getattr(lib, name).argtypes = [vp]
        device = lib.oidnNewDevice(_CPU)
        lib.oidnCommitDevice(device)
        _state.update(lib=lib, device=device)
        _check()
    return _state["lib"], _state["device"]


def _check() -> None:
    message = ctypes.c_char_p()
    code = _state["lib"].oidnGetDeviceError(_state["device"], ctypes.byref(message))
    if code:
        raise RuntimeError(f"OIDN error {code}: {(message.value or b'').decode()}")


def _filter(images: dict[str, np.ndarray], hdr: bool, quality: str,
            clean_aux: bool) -> np.ndarray:
    lib, device = _device()
    h, w = next(iter(images.values())).shape[:2]
    f = lib.oidnNewFilter(device, b"RT")
    kept = {}  # OIDN reads the buffers at execution: keep them alive until then
    for name, image in images.items():
        kept[name] = a = np.ascontiguousarray(image[..., :3], np.float32)
        lib.oidnSetSharedFilterImage(f, name.encode(), a.ctypes.data, _FLOAT3, w, h, 0, 0, 0)
    out = np.zeros((h, w, 3), np.float32)
    lib.oidnSetSharedFilterImage(f, b"output", out.ctypes.data, _FLOAT3, w, h, 0, 0, 0)
    lib.oidnSetFilterBool(f, b"hdr", hdr)
    lib.oidnSetFilterBool(f, b"cleanAux", clean_aux)
    lib.oidnSetFilterInt(f, b"quality", _QUALITY[quality])
    lib.oidnCommitFilter(f)
    lib.oidnExecuteFilter(f)
    lib.oidnReleaseFilter(f)
    _check()
    return out


def denoise(color: np.ndarray, albedo: np.ndarray, normal: np.ndarray,
            quality: str = "HIGH") -> np.ndarray:
    """``color`` (linear radiance) denoised with the prefiltered ``albedo`` and ``normal``
    guides → (H, W, 3) float32."""
    if quality not in _QUALITY:
        raise ValueError(f"oidn_ctypes.denoise: quality {quality!r} is not one of "
                         f"{sorted(_QUALITY)}")
    albedo = _filter({"albedo": albedo}, False, quality, False)
    normal = _filter({"normal": normal}, False, quality, False)
    return _filter({"color": color, "albedo": albedo, "normal": normal}, True, quality, True)
