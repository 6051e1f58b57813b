"""``complex_brdf``: the paper's complex-BRDF challenge (few-shot novel view synthesis of
specular objects).

One object (a KuBasic shape, or an asset of ``objects_source``) at the origin, a random colour,
and either a specular **metal** (metallic 1, roughness 0.2, IOR 2.5, as MOVi) or a **rubber**
that is purely Lambertian (metallic 0, specular 0, roughness 1); three point lights at random
places on the upper hemisphere (recorded in ``metadata.lights``: positions, m); no floor and a
black background; 24 views on a fixed orbit (the same camera positions in every scene); Cycles
limited to 12 bounces. The views are written as the multi-view recipes write them
(:mod:`kubric.recipes.multiview_base`), with NeRF ``transforms_*.json``.

Random draws per seed, in order: material (with ``material=random``), colour hue, object, the
three lights (elevation, azimuth).
"""

from __future__ import annotations

import math

import numpy as np

import kubric as kb
from kubric.assets import clevr
from kubric.pipeline import Option, OptionError
from kubric.recipes import multiview_schema
from kubric.recipes.common import source_location
from kubric.recipes.multiview_base import MultiviewBase, open_source, orbit_positions

#: metal as MOVi's (CLEVR's, :data:`kubric.assets.clevr.MATERIALS`); rubber purely Lambertian
MATERIALS = {
    "metal": dict(clevr.MATERIALS["metal"].bsdf),
    "rubber": {"metallic": 0.0, "roughness": 1.0, "specular": 0.0},
}
#: the KuBasic shapes (:data:`kubric.assets.clevr.KUBASIC_SHAPES`) in this recipe's draw order
SHAPES = ("cube", "cylinder", "sphere", "cone", "torus", "suzanne", "teapot", "torus_knot",
          "gear", "spot", "sponge")


class ComplexBrdf(MultiviewBase, name="complex_brdf"):
    """Complex BRDFs: one object, random colour, metal (specular) or rubber (Lambertian),
    3 point lights on the upper hemisphere, 24 fixed views, 12 bounces."""

    schema = multiview_schema.COMPLEX_BRDF
    #: the point is specular vs Lambertian appearance: a preview RGB would not show it
    renderer_needs = ("photoreal",)

    num_views = Option(24, "number of camera views on the fixed orbit", low=1, high=10000)
    material = Option("random", "metal (specular), rubber (Lambertian) or random per seed",
                      choices=("random", "metal", "rubber"))
    shape = Option("random", "KuBasic shape, or random per seed (ignored with objects_source)",
                   choices=("random", *SHAPES))
    objects_source = Option(None, "mesh asset source to draw the object from (default: the "
                            "KuBasic shapes)", type=source_location)
    object_size = Option(2.0, "largest extent of the object (m)", low=0.01)
    orbit_distance = Option(6.0, "camera distance from the object (m)", low=0.1)
    orbit_elevation = Option(30.0, "camera elevation above the horizon (degrees)", low=-89.0,
                             high=89.0)
    light_distance = Option(8.0, "distance of the three point lights (m)", low=0.1)
    light_intensity = Option(300.0, "intensity of each point light (W)", low=0.0)
    max_bounces = Option(12, "Cycles light bounces (every kind)", low=0, high=1024)

    def check(self) -> None:
        super().check()
        # the object's bounding sphere (radius ≤ √3/2 · its largest extent) must leave the
        # camera orbit and the lights outside it, or no view shows it
        radius = math.sqrt(3.0) / 2.0 * self.object_size
        for name in ("orbit_distance", "light_distance"):
            if radius >= getattr(self, name):
                raise OptionError(f"{self.name}: object_size={self.object_size:g} (bounding radius "
                                  f"up to {radius:g} m) does not fit inside {name}="
                                  f"{getattr(self, name):g} m; choose object_size < "
                                  f"{2.0 * getattr(self, name) / math.sqrt(3.0):.4g}")

    def open_sources(self) -> dict:
        sources = super().open_sources()
        if self.objects_source is not None:
            sources["objects"] = open_source(self.objects_source, "objects_source")
        return sources

    def renderer_options(self) -> dict:
        return {"max_bounces": self.max_bounces}

    def build_background(self, scene, rng, sources) -> str:
        choice = ("metal", "rubber")[rng.randint(2)]
        self.chosen_material = choice if self.material == "random" else self.material
        scene.metadata["lights"] = []
        for k in range(3):
            elevation = rng.uniform(math.radians(15.0), math.radians(75.0))
            azimuth = rng.uniform(0.0, 2.0 * math.pi)
            d = self.light_distance * np.array([math.cos(elevation) * math.cos(azimuth),
                                                math.cos(elevation) * math.sin(azimuth),
                                                math.sin(elevation)])
            scene.add(kb.PointLight(name=f"light_{k}", position=d,
                                    intensity=self.light_intensity))
            scene.metadata["lights"].append(d.tolist())
        return "black"

    def add_objects(self, scene, rng, sources) -> None:
        color = kb.random_hue_color(rng=rng)
        if "objects" in sources:
            ids = sources["objects"].all_asset_ids
            obj = sources["objects"].create(ids[rng.randint(len(ids))])
        else:
            shape = SHAPES[rng.randint(len(SHAPES))]
            obj = sources["kubasic"].create(shape if self.shape == "random" else self.shape)
        bounds = np.asarray(obj.bounds, np.float64)
        obj.scale = self.object_size / max(float(np.max(bounds[1] - bounds[0])), 1e-9)
        obj.position = -obj.scale * (bounds[0] + bounds[1]) / 2.0  # bounding-box centre at 0
        obj.material = kb.PrincipledBSDFMaterial(color=color,
                                                 **MATERIALS[self.chosen_material])
        obj.metadata = {**obj.metadata, "material": self.chosen_material,
                        "color": np.asarray(color.rgb, np.float32),
                        "size": float(self.object_size)}
        scene.add(obj)

    def camera_positions(self, rng) -> np.ndarray:
        return orbit_positions(self.num_views, self.orbit_distance, self.orbit_elevation,
                               self.look_at())
