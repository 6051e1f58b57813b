"""The :class:`Scene`: global settings, the assets, and the views linked to them."""

from __future__ import annotations

from collections.abc import Iterable

from kubric.core import traits as kt
from kubric.core.assets import Asset, UndefinedAsset
from kubric.core.cameras import Camera, UndefinedCamera
from kubric.core.color import Color, get_color
from kubric.core.materials import Texture
from kubric.core.objects import Object3D, PhysicalObject
from kubric.core.resolution import parse_resolution
from kubric.core.uids import SceneUids


def _as_resolution(value, owner, name):
    return parse_resolution(value, f"Scene.{name}")


def _as_rate(other: str):
    positive = kt.as_int(low=1)

    def convert(value, owner, name):
        v = positive(value, owner, name)
        values = getattr(owner, "_values", {})
        if other in values:
            step, frame = (v, values[other]) if name == "step_rate" else (values[other], v)
            if step % frame:
                raise ValueError(f"Scene.step_rate ({step}) must be a multiple of frame_rate "
                                 f"({frame}); use scene.set_rates(frame_rate, step_rate) to "
                                 "change both")
        return v
    return convert


def _as_frame(other: str):
    integer = kt.as_int()

    def convert(value, owner, name):
        v = integer(value, owner, name)
        values = getattr(owner, "_values", {})
        if other in values:
            start, end = (v, values[other]) if name == "frame_start" else (values[other], v)
            if end < start:
                raise ValueError(f"Scene.frame_end ({end}) must be ≥ frame_start ({start})")
        return v
    return convert


def _as_light_or_texture(value, owner, name):
    if isinstance(value, Texture):
        return value
    return kt.as_color()(value, owner, name)


class Scene(kt.HasProperties):
    """Global settings plus the assets; the interface views (simulator, renderer) read.

    Attributes:
      frame_start, frame_end: inclusive frame range (default 1..48).
      frame_rate: frames per second (24). step_rate: physics steps per second (240), a multiple of
        frame_rate; the physics time step is 1/step_rate.
      resolution: (width, height) in pixels (512, 512); also accepts 256, "320x240", "320,240".
      gravity: (3,) m/s² (0, 0, −10).
      camera: the active camera (adding a camera to the scene makes it active).
      ambient_illumination: Color, or a Texture (HDRI) lighting the scene from all directions.
      background: Color, or a Texture (HDRI) seen behind everything.
    """

    frame_start = kt.Property(1, _as_frame("frame_end"), "first frame (inclusive)")
    frame_end = kt.Property(48, _as_frame("frame_start"), "last frame (inclusive)")
    frame_rate = kt.Property(24, _as_rate("step_rate"), "frames per second")
    step_rate = kt.Property(240, _as_rate("frame_rate"), "physics steps per second")
    resolution = kt.Property((512, 512), _as_resolution, "(width, height) in pixels")
    gravity = kt.Vector3D((0.0, 0.0, -10.0), "m/s², world frame")
    camera = kt.Property(lambda: UndefinedCamera(), kt.as_instance(lambda: Camera),
                         "active camera")
    ambient_illumination = kt.Property(get_color("black"), _as_light_or_texture,
                                       "ambient light: Color or HDRI Texture")
    background = kt.Property(get_color("black"), _as_light_or_texture,
                             "background: Color or HDRI Texture")

    def __init__(self, **kwargs):
        self._assets: list[Asset] = []
        self._uids = SceneUids()  # this scene's uid counters (kubric.core.uids)
        self._views: list = []
        self.linked_objects: dict = {}
        self.metadata: dict = {}
        self._init_properties(kwargs)
        if not isinstance(self.camera, UndefinedCamera):
            self.add(self.camera)

    @classmethod
    def from_flags(cls, flags) -> Scene:
        """A scene from parsed worker flags (``frame_start``, ``frame_end``, ``frame_rate``,
        ``step_rate``, ``resolution``), as upstream scripts call it. ``resolution`` takes every
        spelling of :func:`kubric.core.resolution.parse_resolution` (256, "320x240", (320, 240))."""
        return cls(frame_start=flags.frame_start, frame_end=flags.frame_end,
                   frame_rate=flags.frame_rate, step_rate=flags.step_rate,
                   resolution=flags.resolution)

    # ------------------------------------------------------------------ settings
    def set_rates(self, frame_rate: int, step_rate: int) -> None:
        """Change frame_rate and step_rate together (each alone must keep the multiple rule)."""
        positive = kt.as_int(low=1)
        fr = positive(frame_rate, self, "frame_rate")
        sr = positive(step_rate, self, "step_rate")
        if sr % fr:
            raise ValueError(f"Scene.step_rate ({sr}) must be a multiple of frame_rate ({fr})")
        self._values["frame_rate"], self._values["step_rate"] = fr, sr
        self._on_property_set("frame_rate", fr)
        self._on_property_set("step_rate", sr)

    @property
    def frames(self) -> range:
        """frame_start..frame_end inclusive."""
        return range(self.frame_start, self.frame_end + 1)

    @property
    def steps_per_frame(self) -> int:
        return self.step_rate // self.frame_rate

    def _on_property_set(self, name, value):
        if name == "camera" and not isinstance(value, UndefinedCamera):
            self.add(value)
        for view in self._views:
            view.on_change(self, name, value)

    # ------------------------------------------------------------------ assets
    @property
    def assets(self) -> tuple[Asset, ...]:
        return tuple(self._assets)

    @property
    def foreground_assets(self) -> tuple[Object3D, ...]:
        """Objects that are not part of the background (floor, dome, cameras are background)."""
        return tuple(a for a in self._assets if isinstance(a, Object3D) and not a.background)

    @property
    def background_assets(self) -> tuple[Asset, ...]:
        return tuple(a for a in self._assets if a.background)

    def add(self, asset: Asset | Iterable[Asset]) -> None:
        """Add an asset (or several). Adding one twice is a no-op; its material comes along; a
        camera becomes the active camera. An asset in no scene yet gets its uid here (see
        :mod:`kubric.core.uids`)."""
        if isinstance(asset, (list, tuple, set)):
            for a in asset:
                self.add(a)
            return
        if not isinstance(asset, Asset):
            raise TypeError(f"only assets can be added to a scene, got {asset!r}")
        if isinstance(asset, UndefinedAsset) or asset in self._assets:
            return
        self._uids.claim(asset)
        self._assets.append(asset)
        asset.scenes.append(self)
        if isinstance(asset, PhysicalObject):
            self.add(asset.material)
        for view in self._views:
            view.add(asset)
        if isinstance(asset, Camera) and self.camera is not asset:
            self.camera = asset

    def __iadd__(self, asset):
        self.add(asset)
        return self

    def remove(self, asset: Asset) -> None:
        if asset not in self._assets:
            raise ValueError(f"{getattr(asset, 'uid', asset)!r} is not part of this scene")
        self._assets.remove(asset)
        self._uids.release(asset)
        asset.scenes.remove(self)
        for view in self._views:
            view.remove(asset)
        if asset is self.camera:
            self.camera = UndefinedCamera()

    def __isub__(self, asset):
        self.remove(asset)
        return self

    # ------------------------------------------------------------------ views
    @property
    def views(self) -> tuple:
        return tuple(self._views)

    def link_view(self, view) -> None:
        """Link a view: ``view.add_scene(self)``, then ``view.add(asset)`` for every asset
        already in the scene."""
        if any(v is view for v in self._views):
            raise ValueError(f"{view!r} is already linked to this scene")
        self._views.append(view)
        view.add_scene(self)
        for asset in self._assets:
            view.add(asset)

    def unlink_view(self, view) -> None:
        if not any(v is view for v in self._views):
            raise ValueError(f"{view!r} is not linked to this scene")
        self._views.remove(view)
        for asset in self._assets:
            view.remove(asset)
        self.linked_objects.pop(view, None)

    def __repr__(self) -> str:
        return (f"<Scene {self.resolution[0]}x{self.resolution[1]} frames "
                f"{self.frame_start}..{self.frame_end} with {len(self._assets)} assets>")


__all__ = ["Scene", "Color"]
