"""The scene model: plain Python + numpy, no rendering or physics engine imported here."""

from kubric.core import camera_geometry
from kubric.core.assets import Asset, UndefinedAsset
from kubric.core.cameras import Camera, OrthographicCamera, PerspectiveCamera, UndefinedCamera
from kubric.core.characters import Character, MotionClip
from kubric.core.color import Color, get_color
from kubric.core.deformables import Deformable
from kubric.core.lights import (
    DirectionalLight,
    Light,
    PointLight,
    RectAreaLight,
    SpotLight,
    UndefinedLight,
)
from kubric.core.materials import (
    FlatMaterial,
    Material,
    PrincipledBSDFMaterial,
    Texture,
    UndefinedMaterial,
)
from kubric.core.objects import Cube, FileBasedObject, Object3D, PhysicalObject, Sphere
from kubric.core.pbr_materials import ImageMaterial, ProceduralMaterial
from kubric.core.quaternion import Quaternion
from kubric.core.scene import Scene
from kubric.core.views import TableView, View

__all__ = [
    "Asset", "UndefinedAsset", "Camera", "OrthographicCamera",
    "PerspectiveCamera", "UndefinedCamera", "Color", "get_color", "DirectionalLight", "Light",
    "PointLight", "RectAreaLight", "SpotLight", "UndefinedLight", "FlatMaterial", "Material",
    "PrincipledBSDFMaterial", "Texture", "UndefinedMaterial", "Cube", "FileBasedObject",
    "Object3D", "PhysicalObject", "Sphere", "Quaternion", "Scene", "TableView", "View",
    "camera_geometry", "Character", "MotionClip", "ProceduralMaterial", "ImageMaterial",
    "Deformable",
]
