"""The Blender Cycles renderer: a view of the scene model on ``bpy==5.0.1``.

``Blender(scene, ...)`` resets Blender to factory settings, sets every render option explicitly
(Cycles, **Standard** view transform, samples, denoising, light tree, bounces, device) and then
links itself to the scene, which replays the scene and its assets through the mapping tables
``builders`` / ``setters`` / ``keyframers`` (one row per model class / property:
:mod:`kubric.renderer.blender_tables`).

Rendering: :meth:`Blender.render` renders every requested frame in two Blender calls (contiguous
frame runs are one ``render(animation=True)`` each): the RGB render at ``samples_per_pixel`` and
the exact annotation render described in :mod:`kubric.renderer.blender_passes`. Blender's state is
kept between frames (``render.use_persistent_data``). The result is a dict of (T, H, W, C) numpy
arrays (see blender_passes and the output contract): rgba uint8, depth/z float32 (metres),
segmentation uint32, forward/backward_flow float32 (Δrow, Δcol in pixels), normal, uv,
object_coordinates float32.
It implements the renderer protocol of :mod:`kubric.renderer.base` (registered as ``blender``;
recipes build it with ``kubric.renderer.create``); :meth:`Blender.settings` is what a scene's
``metadata["renderer"]`` records.

Options (each checked in one line by :mod:`kubric.renderer.blender_options`):
  samples_per_pixel (int ≥ 1; with adaptive sampling the most per pixel), adaptive_sampling
  (bool: Cycles stops sampling a pixel once its noise estimate is below adaptive_threshold,
  a number in (0, 1], default 0.01 = Blender's; recorded in settings() while adaptive sampling is
  on), use_denoising (bool, OIDN),
  denoising_quality ("HIGH", "BALANCED" or "FAST": OIDN's network size; default "HIGH"),
  denoising_prefilter ("ACCURATE", "FAST" or "NONE": how OIDN cleans the albedo / normal
  guide passes; default "ACCURATE"; both are Blender's defaults, measured in docs/render-cost.md),
  background_transparency (bool: transparent film, alpha 0 where the background shows),
  motion_blur (False / 0 = off, True = shutter 0.5 frames, or a shutter length in frames > 0; the
  shutter is centred on the frame time (``motion_blur_position = 'CENTER'``, a box shutter curve),
  so the sharp annotation layers show the shutter's centre; RGB only), device ("CPU" or "GPU";
  default "GPU" when the environment variable KUBRIC_USE_GPU is 1/true, else "CPU"), max_bounces
  (None = Blender's defaults, or an int ≥ 0 limiting every bounce kind), light_tree (bool, default
  False: faster on small lamp-lit scenes), verbose (bool: show Blender's console output),
  scratch_dir (where frames are written; default a new temporary directory), custom_scene
  (upstream's option: the path of a ``.blend`` file that Blender opens instead of an empty scene;
  its objects are rendered with the model's assets — background (label 0) in segmentation, unknown
  to the model and the simulator — while its world is replaced by the scene's background / ambient
  settings), keep_freed_memory (bool, default False: raise glibc's malloc thresholds for the rest
  of the process so that the buffers freed after each frame are reused — about 0.5 CPU-s less per
  24-frame 256² scene for 40–100 MiB more peak RSS, worth it at low sample counts;
  :mod:`kubric.renderer.allocator`), and Cycles' levers path_guiding, clamp_direct,
  clamp_indirect, filter_glossy, adaptive_min_samples, denoising_input_passes, total_bounces,
  diffuse_bounces, glossy_bounces, transmission_bounces, fast_gi, light_threshold, caustics,
  min_light_bounces, scrambling_distance and tile_size (defaults: Blender's;
  :mod:`kubric.renderer.blender_sampling`; RGB only, recorded in settings() when not the default).
Render threads: Blender's automatic count (all cores), or exactly N when the environment variable
KUBRIC_RENDER_THREADS is N ≥ 1 (set by ``kubric generate --threads-per-scene`` on Dask).
Depth of field comes from the perspective camera's ``use_dof`` / ``focus_distance`` /
``aperture_fstop`` (RGB only).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import bpy
import numpy as np

from kubric.core import camera_geometry as geo
from kubric.core import cameras, materials, rolling_shutter
from kubric.core.views import TableView
from kubric.renderer import allocator
from kubric.renderer import blender_lens as bl
from kubric.renderer import blender_materials as bm
from kubric.renderer import blender_passes as bp
from kubric.renderer import blender_rolling as bl_rolling
from kubric.renderer import blender_sampling as bsm
from kubric.renderer import blender_shadows as bs
from kubric.renderer import blender_tables as bt
from kubric.renderer.base import CapabilityError, Renderer
from kubric.renderer.blender_options import (
    as_bool,
    as_int,
    as_threshold,
    choice,
    custom_scene_path,
    live_option,
    render_device,
    render_threads,
    set_cycles,
    shutter,
    silenced,
)
from kubric.renderer.render_progress import frame_bar


class Blender(TableView, Renderer):
    """Cycles renderer view (see module doc for options and output); implements the renderer
    protocol of :mod:`kubric.renderer.base`."""

    samples_per_pixel = live_option("samples_per_pixel", lambda n, v: as_int(n, v, 1),
                                    set_cycles("samples"))
    adaptive_sampling = live_option("adaptive_sampling", as_bool,
                                    set_cycles("use_adaptive_sampling"))
    adaptive_threshold = live_option("adaptive_threshold", as_threshold,
                                     set_cycles("adaptive_threshold"))
    use_denoising = live_option("use_denoising", as_bool, set_cycles("use_denoising"))
    denoising_quality = live_option("denoising_quality", choice(("HIGH", "BALANCED", "FAST")),
                                    set_cycles("denoising_quality"))
    denoising_prefilter = live_option("denoising_prefilter",
                                      choice(("ACCURATE", "FAST", "NONE")),
                                      set_cycles("denoising_prefilter"))
    background_transparency = live_option(
        "background_transparency", as_bool,
        lambda bscene, value: setattr(bscene.render, "film_transparent", value))
    # Cycles' levers (blender_sampling.CONVERTERS: path_guiding, clamps, bounces, ...) are
    # live options too, added after the class body

    builders = bt.BUILDERS
    setters = bt.SETTERS
    keyframers = bt.KEYFRAMERS

    def __init__(self, scene, scratch_dir=None, adaptive_sampling=False, use_denoising=True,
                 samples_per_pixel=128, background_transparency=False, *, motion_blur=False,
                 device=None, max_bounces=None, light_tree=False, verbose=False,
                 denoising_quality="HIGH", denoising_prefilter="ACCURATE", custom_scene=None,
                 adaptive_threshold=0.01, keep_freed_memory=False, **levers):
        custom_scene = custom_scene_path(custom_scene)
        if keep_freed_memory:  # per-frame buffers reused, not faulted in again (allocator.py)
            allocator.keep_freed_memory()
        self.bpy_scene = None
        self._options: dict = {}
        self._given = {name for name, value, default in (
            ("motion_blur", motion_blur, False), ("max_bounces", max_bounces, None),
            ("background_transparency", background_transparency, False),
            ("adaptive_sampling", adaptive_sampling, False), ("light_tree", light_tree, False))
            if value is not default}
        self.samples_per_pixel = samples_per_pixel
        self.adaptive_sampling = adaptive_sampling
        self.adaptive_threshold = adaptive_threshold
        self.use_denoising = use_denoising
        self.denoising_quality = denoising_quality
        self.denoising_prefilter = denoising_prefilter
        self.background_transparency = background_transparency
        unknown = sorted(set(levers) - set(bsm.CONVERTERS))
        if unknown:
            raise TypeError(f"Blender got unknown options {unknown}; the levers are "
                            f"{list(bsm.CONVERTERS)}")
        for name, default in bsm.BLENDER_DEFAULTS.items():
            setattr(self, name, levers.get(name, default))
        self.motion_blur = shutter(motion_blur)
        self.device = render_device(device)
        self.max_bounces = None if max_bounces is None else as_int("max_bounces",
                                                                     max_bounces, 0)
        self.light_tree = as_bool("light_tree", light_tree)
        self.verbose = as_bool("verbose", verbose)
        if scratch_dir is None:
            scratch_dir = tempfile.mkdtemp(prefix="kubric_blender_")
        self.scratch_dir = Path(scratch_dir)
        self.scratch_dir.mkdir(parents=True, exist_ok=True)
        self.imported_materials: dict[str, list] = {}
        with self.quiet():
            bpy.ops.wm.read_factory_settings(use_empty=True)
            if custom_scene is not None:  # a user's scene to render the model's assets into
                bpy.ops.wm.open_mainfile(filepath=custom_scene)
                for obj in bpy.data.objects:  # its objects are background in segmentation
                    obj.pass_index = 0
            bpy.context.preferences.edit.keyframe_new_interpolation_type = "LINEAR"
            self.bpy_scene = bpy.context.scene
            self._setup_render_engine()
            for name, value in self._options.items():
                setattr(self, name, value)  # apply to the fresh Blender scene
        super().__init__(scene)

    @property
    def blender_scene(self):
        """The ``bpy.types.Scene`` this renderer drives (upstream's name for ``bpy_scene``)."""
        return self.bpy_scene

    # ------------------------------------------------------------------ setup
    def quiet(self):
        """Context manager silencing Blender's console output unless ``verbose``."""
        return silenced(not self.verbose)

    def _setup_render_engine(self):
        s = self.bpy_scene
        s.render.engine = "CYCLES"
        s.view_settings.view_transform = "Standard"
        s.view_settings.look = "None"
        s.view_settings.exposure = 0.0
        s.view_settings.gamma = 1.0
        s.display_settings.display_device = "sRGB"
        s.render.use_persistent_data = True
        s.render.use_compositing = False
        s.render.use_sequencer = False
        s.cycles.use_light_tree = self.light_tree
        s.cycles.denoiser = "OPENIMAGEDENOISE"
        threads = render_threads()
        s.render.threads_mode = "FIXED" if threads else "AUTO"
        if threads:
            s.render.threads = threads
        self._setup_device()
        layer = s.view_layers[0]
        aov = layer.aovs.add()
        aov.name, aov.type = bp.AOV_NAME, "COLOR"

    def _setup_device(self):
        s = self.bpy_scene
        if self.device == "CPU":
            s.cycles.device = "CPU"
            return
        prefs = bpy.context.preferences.addons["cycles"].preferences
        for kind in ("OPTIX", "CUDA", "HIP", "ONEAPI", "METAL"):
            try:
                prefs.compute_device_type = kind
            except TypeError:
                continue
            prefs.get_devices()
            gpus = [d for d in prefs.devices if d.type == kind]
            if gpus:
                for d in prefs.devices:
                    d.use = d.type == kind
                s.cycles.device = "GPU"
                return
        raise RuntimeError("Blender option device='GPU' (or KUBRIC_USE_GPU) was requested but "
                           "Cycles finds no OPTIX/CUDA/HIP/oneAPI/Metal device; use device='CPU'")

    # ------------------------------------------------------------------ table helpers
    def on_keyframe_delete(self, asset, name: str, frame: int) -> None:
        """Drop the Blender key that the keyframer row of ``name`` inserted at ``frame``."""
        obj = asset.linked_objects.get(self)
        key = self._keyframers_for(type(asset)).get(name)
        if obj is None or key is None:
            return
        paths = key.blender_paths(obj) if hasattr(key, "blender_paths") else [key.blender_path(obj)]
        for owner, data_path in paths:
            try:
                owner.keyframe_delete(data_path, frame=frame)
            except RuntimeError:  # Blender has no key there (e.g. a Texture colour was keyed)
                pass

    def destroy(self, asset, obj) -> None:
        if isinstance(obj, bpy.types.Object):
            bpy.data.objects.remove(obj, do_unlink=True)
        elif isinstance(obj, bpy.types.Material):
            bpy.data.materials.remove(obj, do_unlink=True)

    def assign_material(self, asset, obj, material) -> None:
        """Give ``obj`` the Blender counterpart of ``material`` (in every slot)."""
        if isinstance(material, materials.UndefinedMaterial):
            imported = self.imported_materials.get(asset.uid)
            mats = imported if imported else [bm.default_material()]
        else:
            if self not in material.linked_objects:
                self.add(material)
            mats = [material.linked_objects[self]]
        mesh = obj.data
        if len(mats) == 1 and len(mesh.materials) > 1:
            for i in range(len(mesh.materials)):
                mesh.materials[i] = mats[0]
        elif len(mats) == len(mesh.materials):  # slot by slot: clear() would reset every
            for i, m in enumerate(mats):        # face's material index to 0
                mesh.materials[i] = m
        else:
            mesh.materials.clear()
            for m in mats:
                mesh.materials.append(m)

    # ------------------------------------------------------------------ per-render state
    def _object_tables(self):
        """Give every rendered object a unique pass_index; return (label lut, bounds lut)."""
        assets = self.scene.assets
        labels = np.zeros(len(assets) + 1, np.uint32)
        bounds = np.zeros((len(assets) + 1, 2, 3), np.float64)
        for i, asset in enumerate(assets, start=1):
            obj = asset.linked_objects.get(self)
            if not isinstance(obj, bpy.types.Object) or obj.type != "MESH":
                continue
            obj.pass_index = i
            seg = getattr(asset, "segmentation_id", None)
            labels[i] = i if seg is None else seg
            bounds[i] = np.asarray(asset.bounds, np.float64)
        return labels, bounds

    def _sync(self):
        s = self.bpy_scene
        cam = self.scene.camera
        obj = cam.linked_objects.get(self)
        if obj is None:
            raise ValueError("the scene has no camera: add a PerspectiveCamera or "
                             "OrthographicCamera before rendering")
        s.camera = obj
        bl.apply(obj, cam, self.scene.resolution)
        linear_interpolation()
        bs.update_shadow_catchers(self)

    def _configure_rgb(self, path_prefix):
        s = self.bpy_scene
        c = s.cycles
        c.samples = self.samples_per_pixel
        c.use_adaptive_sampling = self.adaptive_sampling
        c.adaptive_threshold = self.adaptive_threshold
        c.use_denoising = self.use_denoising
        c.filter_width = 1.5
        levers = {name: getattr(self, name) for name in bsm.CONVERTERS}
        if levers["path_guiding"] != "off" and self.device != "CPU":
            raise ValueError(f"Blender option path_guiding={levers['path_guiding']!r} needs "
                             f"device 'CPU' (Cycles guides paths on the CPU only), got "
                             f"{self.device!r}")
        bsm.apply(c, levers)
        s.render.film_transparent = self.background_transparency
        s.render.use_motion_blur = self.motion_blur > 0
        if self.motion_blur > 0:  # centred: the exact layers mean the shutter's centre
            s.render.motion_blur_shutter = self.motion_blur
            s.render.motion_blur_position = "CENTER"
        bl_rolling.configure_cycles(s, self.scene.camera)
        self._camera_dof(restore=True)
        layer = s.view_layers[0]
        layer.material_override = None
        self._passes(layer, False)
        if self.max_bounces is None:  # total/diffuse/glossy/transmission: the levers (above)
            c.volume_bounces, c.transparent_max_bounces = 0, 8
        else:
            c.max_bounces = c.diffuse_bounces = c.glossy_bounces = self.max_bounces
            c.transmission_bounces = c.volume_bounces = c.transparent_max_bounces = \
                self.max_bounces
        img = s.render.image_settings
        img.media_type = "IMAGE"
        img.file_format = "PNG"
        img.color_mode = "RGBA"
        img.color_depth = "8"
        img.compression = 15
        s.render.filepath = str(path_prefix)

    def _configure_annotations(self, path_prefix):
        s = self.bpy_scene
        c = s.cycles
        c.samples = 1
        c.use_adaptive_sampling = False
        c.use_denoising = False
        c.filter_width = 0.01
        bsm.apply(c, bsm.BLENDER_DEFAULTS)  # the exact layers never see the RGB levers
        c.max_bounces = c.diffuse_bounces = c.glossy_bounces = 0
        c.transmission_bounces = c.volume_bounces = c.transparent_max_bounces = 0
        s.render.film_transparent = True
        s.render.use_motion_blur = False
        self._camera_dof(restore=False)
        layer = s.view_layers[0]
        layer.material_override = bp.override_material()
        self._passes(layer, True)
        img = s.render.image_settings
        img.media_type = "MULTI_LAYER_IMAGE"
        img.file_format = "OPEN_EXR_MULTILAYER"
        img.color_depth = "32"
        img.exr_codec = "ZIP"
        s.render.filepath = str(path_prefix)

    def _passes(self, layer, on):
        layer.use_pass_z = layer.use_pass_object_index = layer.use_pass_normal = on
        layer.use_pass_vector = layer.use_pass_uv = on

    def _camera_dof(self, restore):
        cam = self.scene.camera
        obj = cam.linked_objects.get(self)
        if obj is not None and isinstance(cam, cameras.PerspectiveCamera):
            obj.data.dof.use_dof = bool(cam.use_dof) if restore else False

    def _render_runs(self, frames, prefix, suffix):
        """Render ``frames`` in as few animation calls as possible; return the file per frame."""
        s = self.bpy_scene
        start, end = s.frame_start, s.frame_end
        runs, files = [], {}
        for f in frames:
            _frame_file(prefix, f, suffix).unlink(missing_ok=True)  # never read a stale frame
        for f in frames:
            if runs and f == runs[-1][1] + 1:
                runs[-1][1] = f
            else:
                runs.append([f, f])
        what = "Blender RGB" if suffix == ".png" else "Blender exact layers"
        try:
            with frame_bar(what, len(frames)), self.quiet():
                if suffix == ".png" and rolling_shutter.duration_of(self.scene.camera) > 0:
                    runs = []  # each frame a still at its sub-frame (blender_rolling)
                    bl_rolling.render_stills(s, self.scene, frames,
                                             lambda f: _frame_file(prefix, f, suffix))
                for a, b in runs:
                    s.frame_end = 1048574
                    s.frame_start, s.frame_end = a, b
                    bpy.ops.render.render(animation=True)
        finally:
            s.frame_end = 1048574
            s.frame_start, s.frame_end = start, end
        for f in frames:
            path = _frame_file(prefix, f, suffix)
            if not path.is_file():
                raise RuntimeError(f"Blender did not write frame {f} to {path}")
            files[f] = path
        return files

    # ------------------------------------------------------------------ public API
    def render(self, frames=None, return_layers=bp.ALL_LAYERS, ignore_missing_textures=False):
        """Render ``frames`` (default: the scene's frame range) → {layer: (T, H, W, C) array}.

        ``return_layers`` is any subset of ``("rgba",) + ANNOTATION_LAYERS`` (see module doc).
        An image texture whose file is missing is an error naming it, unless
        ``ignore_missing_textures`` (Blender then renders it magenta).
        """
        if not ignore_missing_textures:
            missing = missing_texture_files()
            if missing:
                raise FileNotFoundError(f"Blender.render: missing texture file(s) {missing}; "
                                        "pass ignore_missing_textures=True to render anyway")
        frames, wanted = self.check_request(frames, return_layers)
        cam = self.scene.camera
        readout = rolling_shutter.duration_of(cam)
        self.require_effects({"rolling_shutter": readout > 0 and
                              f"camera {cam.name!r} rolling_shutter_duration={readout!r}"})
        if readout > 0:  # Cycles' rolling RGB, raycast's exact layers (blender_rolling)
            bl_rolling.check(self.scene, self.motion_blur)
        refusal = bl.check_scene(self.scene)
        if refusal:
            raise CapabilityError(f"Blender.render: {refusal}")
        self._sync()
        out = _FrameStack(len(frames))
        if "rgba" in wanted:
            prefix = self.scratch_dir / "rgba_"
            self._configure_rgb(prefix)
            files = self._render_runs(sorted(set(frames)), str(prefix), ".png")
            for i, f in enumerate(frames):
                out.put("rgba", i, _read_png_rgba(files[f]))
        ann = [k for k in wanted if k != "rgba"]
        if ann and readout > 0:
            out.arrays.update(bl_rolling.exact_layers(self.scene, frames, ann))
        elif ann:
            labels, bounds = self._object_tables()
            prefix = self.scratch_dir / "annotations_"
            self._configure_annotations(prefix)
            try:
                files = self._render_runs(sorted(set(frames)), str(prefix), ".exr")
            finally:
                self._configure_rgb(self.scratch_dir / "rgba_")
            for i, f in enumerate(frames):
                passes = bp.read_multilayer_exr(files[f])
                layers = bp.decode(passes, self.scene.camera, f, labels, bounds, ann)
                if geo.has_distortion(self.scene.camera):
                    layers.update(bl.lens_layers(passes, self.scene.camera, f, self.scene.assets,
                                                 ann))
                del passes
                for k in ann:
                    out.put(k, i, layers.pop(k))
        return {k: out.arrays[k] for k in wanted}

    def settings(self) -> dict:
        """``metadata["renderer"]``: engine, view transform and the RGB quality settings, plus
        every option of motion_blur, max_bounces, background_transparency, adaptive_sampling and
        light_tree that was given to the constructor, and every noise lever (path_guiding, clamps,
        filter_glossy, adaptive_min_samples) that is not Blender's default (device and verbosity
        never change pixels beyond float noise and are not recorded)."""
        out = {"engine": "CYCLES", "view_transform": "Standard",
               "samples_per_pixel": self.samples_per_pixel, "denoising": self.use_denoising,
               "denoising_quality": self.denoising_quality,
               "denoising_prefilter": self.denoising_prefilter}
        out.update({name: getattr(self, name) for name in sorted(self._given)})
        if self.adaptive_sampling:
            out["adaptive_threshold"] = self.adaptive_threshold
        out.update(bsm.recorded({name: getattr(self, name) for name in bsm.CONVERTERS}))
        return out

    def render_still(self, frame=None, return_layers=bp.ALL_LAYERS, ignore_missing_textures=False):
        """Render one frame (default: Blender's current frame) → {layer: (H, W, C) array}."""
        frame = self.bpy_scene.frame_current if frame is None else frame
        rendered = self.render([frame], return_layers, ignore_missing_textures)
        return {k: v[0] for k, v in rendered.items()}

    def save_state(self, path, pack_textures=True):
        """Write the scene as a .blend file (RGB settings, animation included) for the UI.

        An existing file is replaced (no ``.blend1`` backup is left). With ``pack_textures`` the
        image files are packed into the .blend, so it opens elsewhere with its textures (missing
        files stay unpacked references).
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        self._sync()
        self._object_tables()
        self._configure_rgb(self.scratch_dir / "rgba_")
        path.unlink(missing_ok=True)
        with self.quiet():
            if pack_textures:
                missing = set(missing_texture_files())
                for img in bpy.data.images:
                    if (img.source == "FILE" and img.filepath and img.packed_file is None
                            and str(Path(bpy.path.abspath(img.filepath))) not in missing):
                        img.pack()
            bpy.ops.wm.save_as_mainfile(filepath=str(path.resolve()), copy=True)
        return path

    # ------------------------------------------------------------------ upstream shortcuts
    def set_ambient_light_hdri(self, hdri_filepath, hdri_rotation=(0.0, 0.0, 0.0),
                               strength=1.0) -> None:
        """Light the scene with an HDRI: sets ``scene.ambient_illumination`` to an environment
        :class:`~kubric.core.materials.Texture` (Euler XYZ ``hdri_rotation`` in radians)."""
        self.scene.ambient_illumination = materials.Texture(
            filename=str(hdri_filepath), mapping="environment", rotation=hdri_rotation,
            strength=strength)

    def set_background_hdri(self, hdri_filepath, hdri_rotation=(0.0, 0.0, 0.0)) -> None:
        """Show an HDRI behind everything: sets ``scene.background`` to an environment Texture."""
        self.scene.background = materials.Texture(
            filename=str(hdri_filepath), mapping="environment", rotation=hdri_rotation)

    # upstream workers called these private names
    _set_ambient_light_hdri = set_ambient_light_hdri
    _set_background_hdri = set_background_hdri


for _name, _convert in bsm.CONVERTERS.items():
    setattr(Blender, _name, live_option(_name, _convert, lambda bscene, value, name=_name:
                                        bsm.apply_one(bscene.cycles, name, value)))


class _FrameStack:
    """(T, H, W, C) arrays filled frame by frame: the frames are copied into one array per layer
    as they are decoded, instead of being listed and stacked (which held every layer twice)."""

    def __init__(self, num_frames: int):
        self.num_frames = num_frames
        self.arrays: dict[str, np.ndarray] = {}

    def put(self, layer: str, index: int, frame: np.ndarray) -> None:
        if layer not in self.arrays:
            self.arrays[layer] = np.empty((self.num_frames,) + frame.shape, frame.dtype)
        self.arrays[layer][index] = frame


def missing_texture_files() -> list[str]:
    """Paths of file-backed, unpacked Blender images whose file does not exist."""
    missing = []
    for img in bpy.data.images:
        if img.source != "FILE" or img.packed_file is not None or not img.filepath:
            continue
        path = Path(bpy.path.abspath(img.filepath))
        if not path.exists():
            missing.append(str(path))
    return sorted(missing)


def linear_interpolation():
    """Set every keyframe of every action to LINEAR interpolation (bpy 5 layered actions)."""
    for action in bpy.data.actions:
        for fcurve in _action_fcurves(action):
            for kp in fcurve.keyframe_points:
                if kp.interpolation != "LINEAR":
                    kp.interpolation = "LINEAR"


def _action_fcurves(action):
    curves = []
    for layer in getattr(action, "layers", []):
        for strip in layer.strips:
            for bag in getattr(strip, "channelbags", []):
                curves.extend(bag.fcurves)
    if not curves and hasattr(action, "fcurves"):
        curves = list(action.fcurves)
    return curves


def _frame_file(prefix, frame, suffix) -> Path:
    """The file Blender writes for ``frame`` when render.filepath is ``prefix`` (#### padding)."""
    return Path(f"{prefix}{frame:04d}{suffix}")


def _read_png_rgba(path) -> np.ndarray:
    from PIL import Image
    with Image.open(path) as im:
        return np.asarray(im.convert("RGBA"), dtype=np.uint8)
