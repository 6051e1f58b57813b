"""A worker script written the upstream Kubric way (flags, kb.setup, kb.done), used by
tests/test_utils.py to check that such scripts run unchanged."""

import numpy as np

import kubric as kb
from kubric.renderer import Blender
from kubric.simulator import PyBullet

parser = kb.ArgumentParser()
parser.add_argument("--kubasic_assets", type=str, required=True)
parser.set_defaults(frame_end=3, frame_rate=12, resolution=32)
FLAGS = parser.parse_args()

scene, rng, output_dir, scratch_dir = kb.setup(FLAGS)
simulator = PyBullet(scene, scratch_dir)
renderer = Blender(scene, scratch_dir, samples_per_pixel=2, use_denoising=False)
kubasic = kb.AssetSource.from_manifest(FLAGS.kubasic_assets)

floor = kubasic.create("dome", name="floor", static=True, background=True,
                       material=kb.PrincipledBSDFMaterial(color=kb.get_color("gray")))
scene += floor
scene += kb.DirectionalLight(position=(3, -3, 10), look_at=(0, 0, 0), intensity=3.0)
scene.camera = kb.PerspectiveCamera(focal_length=35., sensor_width=32,
                                    position=(7.5, -6.5, 5.3))
scene.camera.look_at((0, 0, 0))
for shape in ("cube", "sphere"):
    obj = kubasic.create(asset_id=shape, scale=0.7,
                         material=kb.PrincipledBSDFMaterial(color=kb.random_hue_color(rng=rng)))
    obj.metadata = {"shape": shape}
    scene += obj
    kb.move_until_no_overlap(obj, simulator, spawn_region=[(-3, -3, 1), (3, 3, 4)], rng=rng)

animation, collisions = simulator.run(frame_start=0, frame_end=scene.frame_end + 1)
data_stack = renderer.render()
kb.compute_visibility(data_stack["segmentation"], scene.assets)
visible = [a for a in scene.foreground_assets
           if isinstance(a, kb.PhysicalObject) and np.max(a.metadata["visibility"]) > 0]
visible = sorted(visible, key=lambda a: np.sum(a.metadata["visibility"]), reverse=True)
data_stack["segmentation"] = kb.adjust_segmentation_idxs(data_stack["segmentation"],
                                                         scene.assets, visible)
scene.metadata["num_instances"] = len(visible)
kb.write_image_dict(data_stack, output_dir)
kb.post_processing.compute_bboxes(data_stack["segmentation"], visible)
kb.write_json(filename=output_dir / "metadata.json", data={
    "flags": vars(FLAGS),
    "metadata": kb.get_scene_metadata(scene),
    "camera": kb.get_camera_info(scene.camera),
    "instances": kb.get_instance_info(scene, visible),
})
kb.write_json(filename=output_dir / "events.json", data={
    "collisions": kb.process_collisions(collisions, scene, assets_subset=visible)})
kb.done()
