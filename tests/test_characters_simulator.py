"""Characters in PyBullet: kinematic colliders that follow the animation and report contacts."""

import numpy as np
import pytest

import kubric as kb
from kubric.assets.procedural_character import tube_person, walk_clip


def _scene(**person_kw):
    scene = kb.Scene(frame_start=0, frame_end=24, frame_rate=24, step_rate=240)
    person = tube_person(**person_kw)
    scene += person
    scene += kb.Cube(name="floor", position=(0, 0, -0.5), scale=(5, 5, 0.5), static=True)
    person.play(walk_clip(seconds=1.0))
    return scene, person


def test_ball_dropped_onto_a_walking_person_hits_them():
    from kubric.simulator.pybullet import PyBullet
    scene, person = _scene()
    # the walk moves the person along −y at 0.8 m/s: after the 0.4 s fall onto the head
    # (z 1.72) the head is at y ≈ −0.3
    ball = kb.Sphere(name="ball", position=(0.0, -0.3, 2.5), scale=0.08, mass=0.5,
                     restitution=0.6)
    scene += ball
    sim = PyBullet(scene)
    _, collisions = sim.run()
    hits = [c for c in collisions if set(c["instances"]) == {ball, person}]
    assert hits, [tuple(getattr(a, "name", None) for a in c["instances"]) for c in collisions]
    first = min(c["frame"] for c in hits)
    assert 7 < first < 12                                  # about 0.4 s into the fall
    z = ball.get_values_over_time("position", range(0, 25))[:, 2]
    k = int(np.ceil(first))
    assert z[k + 2] > z[k] + 0.03                         # it bounced up off the head
    assert z[k] > 1.6                                      # ... not through it
    # the person moved by its own keys only: the simulator wrote no keys of it
    assert "velocity" not in person.keyframes and "position" not in person.keyframes
    # the contact lies on the skinned head at that moment
    head = person.aabb(first)
    pos = np.asarray(hits[0]["position"])
    assert head[1, 2] - 0.05 < pos[2] < head[1, 2] + 0.05
    sim.close()


def test_the_same_ball_falls_freely_when_the_person_stands_elsewhere():
    from kubric.simulator.pybullet import PyBullet
    scene, person = _scene(position=(3.0, 0.0, 0.0))
    ball = kb.Sphere(name="ball", position=(0.0, -0.3, 2.5), scale=0.08, mass=0.5)
    scene += ball
    _, collisions = PyBullet(scene).run()
    assert not [c for c in collisions if person in c["instances"]]


def test_non_uniform_scale_is_refused():
    from kubric.simulator.pybullet import PyBullet
    scene = kb.Scene()
    scene += tube_person(name="wide", scale=(1.0, 2.0, 1.0))
    with pytest.raises(ValueError, match="wide: PyBullet simulates characters with a uniform"):
        PyBullet(scene)


def test_colliders_follow_scale_and_dynamics_changes():
    import pybullet as pb

    from kubric.simulator.pybullet import PyBullet
    scene, person = _scene()
    sim = PyBullet(scene)
    bodies = person.linked_objects[sim]
    first = list(bodies.uids)
    assert len(first) >= 10                     # one hull per bone that dominates vertices
    person.friction = 0.8                        # no rebuild: the same bodies, new friction
    assert bodies.uids == first
    assert pb.getDynamicsInfo(first[0], -1, physicsClientId=sim.client)[1] == pytest.approx(0.8)
    person.scale = 1.5                           # new hulls at the new size
    assert bodies.uids != first and bodies.scale == 1.5
    top = max(pb.getAABB(u, physicsClientId=sim.client)[1][2] for u in bodies.uids)
    assert top == pytest.approx(1.5 * person.rest_bounds[1, 2], abs=0.05)
    sim.close()
