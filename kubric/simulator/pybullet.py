"""The PyBullet view: rigid-body simulation of a :class:`~kubric.core.scene.Scene`.

``PyBullet(scene)`` opens its own PyBullet client (``pybullet.DIRECT``, one per instance, so
several simulators in one process never share state), creates a body for every Cube, Sphere and
URDF FileBasedObject of the scene, and from then on mirrors the model through the view tables
(mass, friction, restitution, static, scale, pose, velocities; scene gravity and step_rate).
Cameras, lights and materials have no physics counterpart. Characters become kinematic per-bone
convex colliders that follow their animation every step (:mod:`kubric.simulator.characters`).

Time: the physics time step is ``1 / scene.step_rate`` seconds, with
``scene.step_rate // scene.frame_rate`` steps per frame.

Engine settings (chosen for reproducible, non-sticky contacts; facts from upstream Kubric and
bullet3 issue 3094): rigid bodies in maximal coordinates, ``contactProcessingThreshold = 0``,
``restitutionVelocityThreshold = 0``, ``warmStartingFactor = 0``, split impulse on,
``contactSlop = 0``, no cone friction, ``deterministicOverlappingPairs = 1`` and a fixed number of
solver iterations. Linear and angular damping are 0 by default (PyBullet's default is 0.04), so a
body in free fall follows ``x(t) = x0 + v0 t + g t² / 2``. Bullet combines the restitution of two
touching bodies by multiplication and their friction likewise.

Determinism: the same scene (same seed) gives bit-identical trajectories, in one process or in
separate processes, as long as assets are added in the same order.
"""

from __future__ import annotations

import logging
import pathlib
import weakref

import numpy as np
import pybullet as pb

from kubric.core.assets import Asset
from kubric.core.characters import Character
from kubric.core.deformables import Deformable
from kubric.core.objects import FileBasedObject, PhysicalObject
from kubric.core.scene import Scene
from kubric.core.views import TableView
from kubric.simulator import bodies as kb_bodies
from kubric.simulator import characters as kb_characters
from kubric.simulator import contacts as kb_contacts
from kubric.simulator import deformables as kb_deformables
from kubric.simulator.bodies import Body

logger = logging.getLogger(__name__)

__all__ = ["PyBullet"]

#: Model properties written back (and keyframed) by :meth:`PyBullet.run`.
SIMULATED_PROPERTIES = ("position", "quaternion", "velocity", "angular_velocity")


def _disconnect(client: int) -> None:
    try:
        if pb.isConnected(physicsClientId=client):
            pb.disconnect(physicsClientId=client)
    except pb.error:  # already gone
        pass


# ----------------------------------------------------------------------------- table rows
def _build_scene(view, scene):
    return view.client


def _set_gravity(view, scene, client, value):
    pb.setGravity(*(float(v) for v in value), physicsClientId=client)


def _set_time_step(view, scene, client, value):
    pb.setPhysicsEngineParameter(fixedTimeStep=1.0 / scene.step_rate, numSubSteps=0,
                                 physicsClientId=client)


def _build_object(view, obj) -> Body:
    return view._make_body(obj)


def _set_state(view, obj, body, value):
    view._apply_state(obj, body)


def _set_shape(view, obj, body, value):
    view._rebuild_if_needed(obj, body)


def _set_mass(view, obj, body, value):
    if not view._rebuild_if_needed(obj, body) and body.uid is not None and not body.key[-1]:
        kb_bodies.set_mass(body, obj, view.client)


def _set_dynamics(view, obj, body, value):
    view._apply_dynamics(obj, body)


def _build_character(view, character):
    bodies = kb_characters.build_character_bodies(character, view.client)
    for uid in bodies.uids:
        view._assets_by_body[uid] = character
    return bodies


def _repose_character(view, character, bodies, value):
    kb_characters.pose_character(character, bodies, view.client, None)


def _rescale_character(view, character, bodies, value):
    """A new scale needs new hulls (the add replays every setter: unchanged scale, no work)."""
    if kb_characters.uniform_scale(character) == bodies.scale:
        return
    for uid in bodies.uids:
        view._assets_by_body.pop(uid, None)
    kb_characters.remove_character_bodies(bodies, view.client)
    new = _build_character(view, character)
    bodies.bones, bodies.uids, bodies.scale = new.bones, new.uids, new.scale


def _character_dynamics(view, character, bodies, value):
    kb_characters.set_dynamics(character, bodies, view.client)


def _ignore(view, obj, body, value):
    """A property the kinematic character colliders do not use (they never move by physics)."""


def _build_deformable(view, deformable):
    if not view.deformable_world:
        view._open_deformable_world()
    return kb_deformables.SoftBody()


def _soft_key(deformable) -> tuple:
    """What a soft body is built from: the current mesh and the physics properties."""
    return (deformable.deformed_vertices().tobytes(), float(deformable.mass),
            float(deformable.stiffness), float(deformable.damping),
            float(deformable.collision_margin), float(deformable.friction),
            tuple(float(x) for x in deformable.neo_hookean))


def _rebuild_deformable(view, deformable, body, value):
    """A soft body at the model's current mesh and physics (rebuilt only when they changed;
    not while :meth:`PyBullet.run` writes the simulated vertices back)."""
    if view._writing:
        return
    key = _soft_key(deformable)
    if key != view._soft_keys.get(deformable):
        kb_deformables.remove(body, view.client)
        body.uid = kb_deformables.build(deformable, view.client).uid
        view._soft_keys[deformable] = key


class PyBullet(TableView):
    """Rigid-body simulator view of ``scene`` (see the module docstring for conventions).

    Args:
      scene: the scene to simulate; linked on construction (existing assets are created).
      scratch_dir: directory for temporary files (upstream's signature; stored as
        ``self.scratch_dir``, None = none; this view writes only where it is told to).
      solver_iterations: constraint-solver iterations per step (fixed for determinism).
      linear_damping, angular_damping: PyBullet damping factors applied to every body (0 = none).
    """

    builders = {
        Scene: _build_scene,
        PhysicalObject: _build_object,
        Character: _build_character,
        Deformable: _build_deformable,
        Asset: None,  # cameras, lights, materials, plain Object3D: no physics counterpart
    }
    setters = {
        Scene: {"gravity": _set_gravity, "step_rate": _set_time_step,
                "frame_rate": _set_time_step},
        PhysicalObject: {
            "position": _set_state, "quaternion": _set_state, "velocity": _set_state,
            "angular_velocity": _set_state, "scale": _set_shape, "static": _set_shape,
            "mass": _set_mass, "friction": _set_dynamics, "restitution": _set_dynamics,
        },
        FileBasedObject: {"simulation_filename": _set_shape},
        Character: {"position": _repose_character, "quaternion": _repose_character,
                    "bone_rotations": _repose_character, "root_offset": _repose_character,
                    "scale": _rescale_character, "friction": _character_dynamics,
                    "restitution": _character_dynamics, "velocity": _ignore,
                    "angular_velocity": _ignore, "static": _ignore, "mass": _ignore},
        Deformable: {**{name: _rebuild_deformable for name in (
            "position", "quaternion", "scale", "mass", "friction", "stiffness", "damping",
            "collision_margin", "neo_hookean", "simulated_vertices")},
            "velocity": _ignore, "angular_velocity": _ignore, "static": _ignore,
            "restitution": _ignore},
    }
    keyframers = {}

    def __init__(self, scene: Scene, scratch_dir=None, *, solver_iterations: int = 50,
                 linear_damping: float = 0.0, angular_damping: float = 0.0):
        self.scratch_dir = None if scratch_dir is None else pathlib.Path(scratch_dir)
        self.linear_damping = float(linear_damping)
        self.angular_damping = float(angular_damping)
        self.client = pb.connect(pb.DIRECT)
        if self.client < 0:
            raise RuntimeError("PyBullet: could not open a physics client (pybullet.connect)")
        self._finalizer = weakref.finalize(self, _disconnect, self.client)
        self._engine_parameters(solver_iterations)
        self._shapes = kb_bodies.ShapeCache(self.client)
        self._assets_by_body: dict[int, PhysicalObject] = {}
        self._keyed_frames: dict[PhysicalObject, set[int]] = {}
        self._links: dict[PhysicalObject, dict[int, PhysicalObject]] = {}  # attach_links
        self._solver_iterations = int(solver_iterations)
        self.deformable_world = False  # opened by the first deformable (_open_deformable_world)
        self._soft_keys: dict = {}
        self._writing = False
        super().__init__(scene)

    def _engine_parameters(self, solver_iterations: int) -> None:
        pb.setPhysicsEngineParameter(
            numSolverIterations=int(solver_iterations), deterministicOverlappingPairs=1,
            restitutionVelocityThreshold=0.0, warmStartingFactor=0.0, useSplitImpulse=1,
            contactSlop=0.0, enableConeFriction=0, physicsClientId=self.client)

    def _open_deformable_world(self) -> None:
        """Switch the engine to PyBullet's deformable world (soft bodies exist only there;
        :mod:`kubric.simulator.deformables`): reset the engine, then rebuild the scene's settings
        and every body from the model, which is the truth (same model ⇒ same engine state)."""
        pb.resetSimulation(pb.RESET_USE_DEFORMABLE_WORLD, physicsClientId=self.client)
        self.deformable_world = True
        self._engine_parameters(self._solver_iterations)
        self._shapes = kb_bodies.ShapeCache(self.client)
        self._assets_by_body.clear()
        self._soft_keys.clear()
        for name, setter in self._setters_for(Scene).items():
            setter(self, self.scene, self.client, getattr(self.scene, name))
        for asset in self.scene.assets:
            if asset.linked_objects.pop(self, None) is not None:
                self.add(asset)

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        """Unlink from the scene and disconnect the PyBullet client (idempotent)."""
        if any(v is self for v in self.scene.views):
            self.scene.unlink_view(self)
        self._finalizer()

    def __repr__(self) -> str:
        return f"<PyBullet client {self.client}>"

    # ------------------------------------------------------------------ bodies
    def _make_body(self, obj) -> Body:
        key = kb_bodies.shape_key(obj)
        if key is None:
            logger.info("%s has no simulation_filename: not simulated", obj.uid)
            return Body()
        body = kb_bodies.create_body(obj, key, self._shapes)
        self._assets_by_body[body.uid] = obj
        return body

    def _rebuild_if_needed(self, obj, body: Body) -> bool:
        """Recreate the engine body when its shape, scale, file or fixedness changed."""
        key = kb_bodies.shape_key(obj)
        if key == body.key:
            return False
        self._remove_body(body)
        if key is not None:
            new = kb_bodies.create_body(obj, key, self._shapes)
            body.uid, body.key, body.links = new.uid, new.key, new.links
            body.set_inertial(new.inertial_pos, new.inertial_orn)
            self._assets_by_body[body.uid] = obj
            self._apply_dynamics(obj, body)
            self._apply_state(obj, body)
        return True

    def _remove_body(self, body: Body) -> None:
        if body.uid is not None:
            self._assets_by_body.pop(body.uid, None)
            pb.removeBody(body.uid, physicsClientId=self.client)
        body.uid, body.key = None, None

    def destroy(self, asset, obj) -> None:
        if isinstance(obj, Body):
            self._remove_body(obj)
        elif isinstance(obj, kb_deformables.SoftBody):
            self._soft_keys.pop(asset, None)
            kb_deformables.remove(obj, self.client)
        elif isinstance(obj, kb_characters.CharacterBodies):
            for uid in obj.uids:
                self._assets_by_body.pop(uid, None)
            kb_characters.remove_character_bodies(obj, self.client)

    def _characters(self) -> list:
        """[(character, its colliders)] of the scene."""
        return [(a, a.linked_objects[self]) for a in self.scene.assets
                if isinstance(a.linked_objects.get(self), kb_characters.CharacterBodies)]

    def _character_schedule(self, times) -> list:
        """[(colliders, (N, B, 4, 4) poses at ``times``)] for every character."""
        return [(bodies, kb_characters.schedule(c, bodies, times))
                for c, bodies in self._characters()]

    def _apply_state(self, obj, body: Body) -> None:
        """Set the engine pose and velocities from the model (the model is the truth)."""
        if body.uid is None:
            return
        pos, orn = body.engine_pose(obj.position, obj.quaternion)
        lin, ang = body.engine_velocity(obj.position, obj.quaternion, obj.velocity,
                                        obj.angular_velocity)
        pb.resetBasePositionAndOrientation(body.uid, pos, orn, physicsClientId=self.client)
        pb.resetBaseVelocity(body.uid, lin, ang, physicsClientId=self.client)

    def _apply_dynamics(self, obj, body: Body) -> None:
        if body.uid is None:
            return
        for link in body.links:
            pb.changeDynamics(body.uid, link, lateralFriction=float(obj.friction),
                              restitution=float(obj.restitution), contactProcessingThreshold=0.0,
                              linearDamping=self.linear_damping,
                              angularDamping=self.angular_damping, physicsClientId=self.client)

    def _body_of(self, obj) -> Body:
        body = obj.linked_objects.get(self) if isinstance(obj, Asset) else None
        if not isinstance(body, Body) or body.uid is None:
            raise ValueError(f"{getattr(obj, 'uid', obj)!r} has no body in this simulator "
                             "(is it a simulated PhysicalObject added to the simulated scene?)")
        return body

    def attach_links(self, base, links: dict) -> None:
        """Pose ``links`` (``{URDF link name: unsimulated object}``) from the links of ``base``'s
        multi-link URDF body at every frame that :meth:`run` records (the link's URDF frame:
        position, quaternion, and that point's velocity and angular velocity)."""
        body = self._body_of(base)
        names = {pb.getJointInfo(body.uid, j, physicsClientId=self.client)[12].decode(): j
                 for j in range(pb.getNumJoints(body.uid, physicsClientId=self.client))}
        unknown = sorted(set(links) - set(names))
        if unknown:
            raise ValueError(f"{base.uid}: its URDF has no links {unknown}; links: "
                             f"{sorted(names)}")
        self._links[base] = {names[k]: obj for k, obj in links.items()}

    def _read_link(self, body: Body, index: int):
        st = pb.getLinkState(body.uid, index, computeLinkVelocity=1,
                             computeForwardKinematics=1, physicsClientId=self.client)
        com, pos, orn, vel, ang = st[0], st[4], st[5], st[6], st[7]
        vel = np.asarray(vel) + np.cross(ang, np.asarray(pos) - np.asarray(com))
        return (tuple(float(v) for v in pos), kb_bodies.xyzw_to_wxyz(orn),
                tuple(float(v) for v in vel), tuple(float(v) for v in ang))

    def _read_all(self, simulated, states) -> None:
        for obj, body in simulated:
            states.setdefault(obj, []).append(self._read_state(obj, body))
            for index, link_obj in self._links.get(obj, {}).items():
                states.setdefault(link_obj, []).append(self._read_link(body, index))

    def _read_state(self, obj, body: Body):
        pos, orn = pb.getBasePositionAndOrientation(body.uid, physicsClientId=self.client)
        vel, ang = pb.getBaseVelocity(body.uid, physicsClientId=self.client)
        return body.model_state(pos, orn, vel, ang)

    def _simulated(self) -> list[tuple[PhysicalObject, Body]]:
        out = []
        for asset in self.scene.assets:
            body = asset.linked_objects.get(self)
            if isinstance(body, Body) and body.uid is not None:
                out.append((asset, body))
        return out

    # ------------------------------------------------------------------ queries
    def check_overlap(self, obj, tolerance: float = 0.0) -> bool:
        """Whether ``obj`` penetrates any other body by more than ``tolerance`` metres.

        Uses the engine's exact closest-point query at the current model poses (touching without
        penetration is not an overlap).
        """
        body = self._body_of(obj)
        for other in sorted(self._assets_by_body):
            if other == body.uid:
                continue
            points = pb.getClosestPoints(body.uid, other, distance=0.0,
                                         physicsClientId=self.client)
            if any(p[8] < -tolerance for p in points):
                return True
        return False

    def save_state(self, path="scene.bullet") -> pathlib.Path:
        """Write the engine state (bodies, shapes, poses) to a ``.bullet`` file; returns its path.

        The file can be read back with ``pybullet.loadBullet``. Parent folders are created.
        """
        path = pathlib.Path(path)
        if path.suffix != ".bullet":
            raise ValueError(f"save_state path must end in '.bullet', got {str(path)!r}")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.unlink(missing_ok=True)
        pb.saveBullet(str(path), physicsClientId=self.client)
        if not path.is_file():
            raise RuntimeError(f"PyBullet did not write {str(path)!r}")
        return path

    # ------------------------------------------------------------------ simulation
    def run(self, frame_start: int = 0, frame_end: int | None = None, *,
            merge_contacts: bool = True,
            min_contact_force: float = kb_contacts.DEFAULT_MIN_FORCE):
        """Simulate from the current model state and keyframe the result.

        The state at ``frame_start`` is the current state (recorded as the first keyframe); the
        engine then takes ``steps_per_frame`` steps of ``1/step_rate`` s per frame up to
        ``frame_end`` (inclusive; default ``scene.frame_end``). For every simulated object and
        every frame, position, quaternion (WXYZ), velocity and angular_velocity are assigned to
        the model and keyframed (``asset.keyframe_insert``), so other views receive the motion;
        afterwards the model (and the engine) hold the state at ``frame_end``.

        Repeated runs continue from the current state (e.g. a settling run, then a reset of
        velocities, then the real run). Each run replaces the animation of the previous ones:
        keyframes of the four properties that an earlier ``run`` of this simulator wrote at
        frames outside the new range are deleted from the model, so the model holds exactly the
        latest run's trajectory (``asset.keyframe_delete`` tells the other views, e.g. the
        renderer, to drop those keys too).

        Args:
          frame_start, frame_end: inclusive frame range (``frame_end ≥ frame_start``).
          merge_contacts: merge the contacts of one body pair within one frame interval into one
            event (see :mod:`kubric.simulator.contacts`); False returns every contact point of
            every step.
          min_contact_force: contacts with a smaller normal force (N) are dropped.

        Returns:
          ``(animation, collisions)``: animation ``{asset: {"position": [(x, y, z), ...],
          "quaternion": [(w, x, y, z), ...], "velocity": [...], "angular_velocity": [...]}}``
          with one float64 tuple per frame ``frame_start..frame_end``; collisions a list of
          event dicts whose ``frame`` is ``frame_start + step / steps_per_frame``.
        """
        frame_end = self.scene.frame_end if frame_end is None else frame_end
        for name, value in (("frame_start", frame_start), ("frame_end", frame_end)):
            if isinstance(value, bool) or not isinstance(value, int):
                raise TypeError(f"PyBullet.run: {name} must be an integer, got {value!r}")
        if frame_end < frame_start:
            raise ValueError(f"PyBullet.run: frame_end ({frame_end}) must be ≥ frame_start "
                             f"({frame_start})")
        steps_per_frame = self.scene.steps_per_frame
        _set_time_step(self, self.scene, self.client, None)
        simulated = self._simulated()
        for obj, body in simulated:  # the model is the truth at the start of a run
            self._apply_state(obj, body)
        n_steps = (frame_end - frame_start) * steps_per_frame
        # kinematic colliders: every step's pose, computed at once (step 0 = frame_start)
        poses = self._character_schedule(frame_start + np.arange(n_steps + 1) / steps_per_frame)
        for bodies, schedule in poses:
            kb_characters.place(bodies, self.client, schedule[0])

        states: dict = {}
        self._read_all(simulated, states)
        soft = self._soft_bodies()
        meshes = {a: [kb_deformables.read(b.uid, self.client)] for a, b in soft}
        events: list[dict] = []
        for step in range(1, n_steps + 1):
            for bodies, schedule in poses:  # kinematic colliders at this step's time
                kb_characters.place(bodies, self.client, schedule[step])
            pb.stepSimulation(physicsClientId=self.client)
            points = pb.getContactPoints(physicsClientId=self.client)
            if points:
                events.extend(kb_contacts.raw_events(
                    points, self._assets_by_body, frame_start + step / steps_per_frame, step,
                    min_contact_force))
            if step % steps_per_frame == 0:
                self._read_all(simulated, states)
                for a, b in soft:
                    meshes[a].append(kb_deformables.read(b.uid, self.client))

        if merge_contacts:
            events = kb_contacts.merge_events(events, steps_per_frame)
        collisions = kb_contacts.finalize(events)
        animation = {obj: {name: [s[i] for s in seq] for i, name in enumerate(SIMULATED_PROPERTIES)}
                     for obj, seq in states.items()}
        self._write_keyframes(animation, frame_start, frame_end)
        self._write_meshes(meshes, frame_start, frame_end)
        animation.update({a: {"simulated_vertices": seq} for a, seq in meshes.items()})
        return animation, collisions

    def _soft_bodies(self) -> list:
        """[(deformable, its soft body)] of the scene."""
        return [(a, a.linked_objects[self]) for a in self.scene.assets
                if isinstance(a.linked_objects.get(self), kb_deformables.SoftBody)
                and a.linked_objects[self].uid is not None]

    def _write_meshes(self, meshes, frame_start: int, frame_end: int) -> None:
        """Key every deformable's vertices at every frame of the run (replacing an earlier run's
        keys outside it); the engine keeps its state (no rebuild from the written values)."""
        frames = range(frame_start, frame_end + 1)
        self._writing = True
        try:
            for obj, seq in meshes.items():
                kb_deformables.check_stable(obj, frames, seq)
                for frame in sorted(set(obj.keyframes.get("simulated_vertices", {})) -
                                    set(frames)):
                    obj.keyframe_delete("simulated_vertices", frame)
                for frame, verts in zip(frames, seq, strict=True):
                    obj.record(frame, verts)
                self._soft_keys[obj] = _soft_key(obj)
        finally:
            self._writing = False

    def _write_keyframes(self, animation, frame_start: int, frame_end: int) -> None:
        frames = range(frame_start, frame_end + 1)
        for obj, old_frames in self._keyed_frames.items():
            for frame in old_frames.difference(frames):
                for name in SIMULATED_PROPERTIES:
                    if frame in obj.keyframes.get(name, {}):
                        obj.keyframe_delete(name, frame)
        self._keyed_frames = {}
        for obj, track in animation.items():
            for i, frame in enumerate(frames):
                for name in SIMULATED_PROPERTIES:
                    setattr(obj, name, track[name][i])
                for name in SIMULATED_PROPERTIES:
                    obj.keyframe_insert(name, frame)
            self._keyed_frames[obj] = set(frames)
