"""Scene format v1: the `motion` block of an object, camera or light.

    motion: {type: static}                       # default
    motion: {type: keyframes, channels: {...}}   # key poses per channel
    motion: {type: procedural, generators: [...], channels: {...}}
    motion: {type: dynamics, ...}                # simulated (dynamics_schema.py)

Parent frames are not a motion type: any object, camera or light may name a `parent`,
and its world transform is parent(t) * local(t) (docs/scene-format.md).
"""

# No `from __future__ import annotations` in the schema modules: pydantic would then compile
# and evaluate every field's annotation string when each model class is made, in every
# process that loads a scene (docs/ci-sharding.md, "What validation keeps").

from typing import Annotated, Literal, Union

from pydantic import Field, field_validator, model_validator

from .dynamics_schema import DynamicsMotion
from .types import FiniteFloat, Model, NonNegative as NonNegativeFloat, Positive, Transform, Vec3

Interpolation = Literal["hold", "nearest", "linear", "catmull-rom", "bezier", "hermite"]
Extrapolation = Literal["hold", "linear", "cycle"]
Ease = Literal["in", "out", "in-out", "none"]

# A keyed value: a scalar (fov, intensity, uniform scale), a 3-vector (translate, scale),
# or a rotation given as Euler angles, axis-angle or quaternion (rotate channel).
ScalarOrVec = Union[FiniteFloat, tuple[FiniteFloat, FiniteFloat, FiniteFloat]]
# A tangent: like a value, or for `hermite` rotation keys a quaternion derivative (w, x, y, z) per second.
Tangent = Union[ScalarOrVec, tuple[FiniteFloat, FiniteFloat, FiniteFloat, FiniteFloat]]


class Key(Model):
    """One key of a channel. `time` is in frames or seconds (the block's `time_unit`).

    `interpolation` overrides the channel's for the segment that starts at this key.
    Bezier keys may give `tangent_in` / `tangent_out` (value units per second) or `ease`;
    hermite rotation keys give them as quaternion derivatives (w, x, y, z) per second.
    Rotation keys give exactly one of `value` (Euler xyz degrees), `euler` (+ `order`),
    `axis` + `angle`, or `quaternion` (w, x, y, z). The segment arriving at a key takes the
    shortest arc; `turns` adds whole extra turns about that arc's axis (a deliberate
    720-degree spin from 0 back to 0 is `turns: 2` with an axis-angle key; negative turns
    spin the other way). See docs/motion.md.
    """

    time: FiniteFloat
    value: ScalarOrVec | None = None
    euler: tuple[FiniteFloat, FiniteFloat, FiniteFloat] | None = None
    order: Annotated[str, Field(pattern=r"^([xyz]{3}|[XYZ]{3})$")] = "xyz"
    axis: Vec3 | None = None
    angle: FiniteFloat | None = None
    quaternion: tuple[FiniteFloat, FiniteFloat, FiniteFloat, FiniteFloat] | None = None
    turns: int = 0
    interpolation: Interpolation | None = None
    ease: Ease | None = None
    tangent_in: Tangent | None = None
    tangent_out: Tangent | None = None

    @model_validator(mode="after")
    def _one_value(self) -> "Key":
        given = [
            n
            for n, v in (("value", self.value), ("euler", self.euler), ("quaternion", self.quaternion))
            if v is not None
        ]
        if self.axis is not None or self.angle is not None:
            if self.axis is None or self.angle is None:
                raise ValueError("axis and angle go together")
            given.append("axis/angle")
        if len(given) != 1:
            raise ValueError(
                "a key needs exactly one of value, euler, axis/angle, quaternion"
                + (f" (got {', '.join(given)})" if given else "")
            )
        return self


class Channel(Model):
    """One animated channel: its keys (times strictly increasing) and an interpolation and
    extrapolation of its own, overriding the block's."""

    keys: Annotated[list[Key], Field(min_length=1)]
    interpolation: Interpolation | None = None
    extrapolation: Extrapolation | None = None

    @field_validator("keys")
    @classmethod
    def _sorted(cls, keys: list[Key]) -> list[Key]:
        times = [k.time for k in keys]
        for i in range(1, len(times)):
            if times[i] <= times[i - 1]:
                raise ValueError(
                    f"key times must increase strictly: keys[{i}].time {times[i]} <= keys[{i - 1}].time {times[i - 1]}"
                )
        return keys


# Channels every transformable thing has; owners add their animatable scalars
# (camera: fov; lights: intensity, radiance, irradiance, scale).
TRANSFORM_CHANNELS = ("translate", "rotate", "scale")


class StaticMotion(Model):
    """No motion: the thing keeps its `transform:`."""

    type: Literal["static"] = "static"


class KeyframeMotion(Model):
    """Keyframed channels (translate, rotate, scale and the owner's scalar channels); key
    times in frames or seconds."""

    type: Literal["keyframes"]
    time_unit: Literal["frames", "seconds"] = "frames"
    interpolation: Interpolation = "linear"
    extrapolation: Extrapolation = "hold"
    channels: dict[str, Channel]

    @field_validator("channels")
    @classmethod
    def _nonempty(cls, channels: dict[str, Channel]) -> dict[str, Channel]:
        if not channels:
            raise ValueError("a keyframes block needs at least one channel")
        return channels


# --- procedural generators ----------------------------------------------------------------


class Ballistic(Model):
    """x(t) = x0 + v0 (t - t0) + a (t - t0)^2 / 2 (seconds, metres)."""

    type: Literal["ballistic"]
    x0: Vec3 = (0.0, 0.0, 0.0)
    v0: Vec3
    a: Vec3 = (0.0, -9.81, 0.0)
    t0: FiniteFloat = 0.0


class Orbit(Model):
    """Circular motion about `center` in the plane normal to `axis`."""

    type: Literal["orbit"]
    center: Vec3 = (0.0, 0.0, 0.0)
    axis: Vec3 = (0.0, 1.0, 0.0)
    radius: Positive = 1.0
    period: Positive = 1.0  # seconds per revolution
    phase: FiniteFloat = 0.0  # degrees
    face_center: bool = False


class Oscillate(Model):
    """x(t) += amplitude * sin(2 pi frequency t + phase) along `direction` (or rotation)."""

    type: Literal["oscillate"]
    channel: Literal["translate", "rotate", "scale"] = "translate"
    direction: Vec3 = (0.0, 1.0, 0.0)  # for rotate: the axis
    amplitude: FiniteFloat = 1.0  # metres, degrees or scale factor
    frequency: Positive = 1.0  # Hz
    phase: FiniteFloat = 0.0  # degrees


class Turntable(Model):
    """Constant spin about `axis` through the object's origin."""

    type: Literal["turntable"]
    axis: Vec3 = (0.0, 1.0, 0.0)
    rate: Annotated[FiniteFloat, Field(json_schema_extra={"unit": "degrees/s"})] = 360.0
    phase: FiniteFloat = 0.0  # degrees


class Noise(Model):
    """Smooth seeded noise (hand-held camera shake) on translation and rotation."""

    type: Literal["noise"]
    seed: int = 0
    frequency: Positive = 2.0  # Hz
    translate_amplitude: Vec3 = (0.01, 0.01, 0.0)  # metres
    rotate_amplitude: Vec3 = (0.5, 0.5, 0.2)  # degrees


class ExpressionChannels(Model):
    """Channel components as expressions in `t` (seconds); see docs/expressions.md."""

    translate: tuple[str, str, str] | None = None
    rotate: tuple[str, str, str] | None = None  # Euler xyz degrees
    scale: Union[str, tuple[str, str, str], None] = None
    order: Annotated[str, Field(pattern=r"^([xyz]{3}|[XYZ]{3})$")] = "xyz"


Generator = Annotated[Union[Ballistic, Orbit, Oscillate, Turntable, Noise], Field(discriminator="type")]


class ProceduralMotion(Model):
    """Generators compose in order (translations add, rotations multiply), then the
    expression channels apply on top. Scalars (fov, intensity) go in `scalars`."""

    type: Literal["procedural"]
    generators: list[Generator] = []
    channels: ExpressionChannels | None = None
    scalars: dict[str, str] = {}

    @model_validator(mode="after")
    def _something(self) -> "ProceduralMotion":
        if not self.generators and self.channels is None and not self.scalars:
            raise ValueError("a procedural block needs generators, channels or scalars")
        return self


# --- motion planning (pipeline/motion/plan.py; docs/seed-motion.md, "Motion planning") ----


class OccupancyGrid(Model):
    """Where the agent may go, on the floor plane (world X right, Z down the image rows,
    +Y up): from an `image` (pixels darker than `threshold` are walls; one pixel per cell)
    or from the scene's own static objects (`from_scene: true`: every static cube,
    sphere, cylinder or mesh (its bounding box) that reaches into the height band `band`
    is a wall). Cell (0, 0) has its corner at `origin` (x, z); `size` (x, z metres) is the
    extent of a scene-projected grid. Outside the grid is wall."""

    image: str | None = None
    threshold: Annotated[float, Field(gt=0, lt=1)] = 0.5
    from_scene: bool = False
    cell: Positive = 0.1  # metres per cell
    origin: tuple[FiniteFloat, FiniteFloat] = (0.0, 0.0)
    size: tuple[Positive, Positive] | None = None
    band: tuple[FiniteFloat, FiniteFloat] = (0.05, 3.0)  # heights (y) that block the agent

    @model_validator(mode="after")
    def _one_source(self) -> "OccupancyGrid":
        if (self.image is None) == (not self.from_scene):
            raise ValueError("a grid needs exactly one of image, from_scene: true")
        if self.from_scene and self.size is None:
            raise ValueError("a grid from the scene needs its size (x, z metres)")
        if self.band[0] >= self.band[1]:
            raise ValueError(f"band {self.band}: the low height must be below the high one")
        return self


class Follower(Model):
    """A simulated vehicle that tracks the planned path (the dynamics stage): gravity, a
    hover force that carries its weight, Rayleigh drag, and a steering force towards where
    the path will be in `look_ahead` seconds, at most `max_accel`. It must stay within
    `tolerance` metres of the path (checked; the path keeps that much extra clearance)."""

    mass: Positive = 1.5  # kg
    cd: NonNegativeFloat = 1.0
    area: Positive = 0.05  # m^2
    look_ahead: Annotated[float, Field(gt=0, le=5)] = 0.3  # s
    max_accel: Positive = 20.0  # m/s^2
    tolerance: Positive = 0.1  # m


class PlanMotion(Model):
    """A planned path: A* (8-connected, octile heuristic) on the occupancy `grid` from
    `start` through `waypoints` to `goal` for an agent of `radius`, shortened by line of
    sight, turned into a centripetal Catmull-Rom root-motion spline travelled with a
    trapezoidal speed profile (accelerate at `accel` to `speed`, cruise, brake at
    `decel`), from `start_time` seconds. `facing`: along the tangent, also `bank` into
    turns, or `none`. With `follower`, a simulated vehicle tracks the path (dynamics)."""

    type: Literal["plan"]
    grid: OccupancyGrid
    start: Annotated[Vec3, Field(json_schema_extra={"unit": "m"}, description="where the path starts")]
    goal: Vec3
    waypoints: list[Vec3] = []
    radius: Positive = 0.3  # m, the agent's own radius
    margin: NonNegativeFloat | None = None  # m of extra clearance for smoothing (default: one cell)
    speed: Positive = 1.0  # m/s, cruise
    accel: Positive = 1.0  # m/s^2
    decel: Positive | None = None  # m/s^2 (default: accel)
    start_time: FiniteFloat = 0.0  # s
    facing: Literal["tangent", "bank", "none"] = "tangent"
    follower: Follower | None = None


# --- inverse kinematics (pipeline/motion/ik.py; docs/seed-motion.md, "Inverse kinematics") -


class JointLimit(Model):
    """Limits of one joint of an `ccd` chain, relative to its keyed local rotation: a hinge
    (`axis` in the joint's keyed local frame, angle in [min, max] degrees about it, no other
    rotation) or a ball joint (`cone`: at most that many degrees away, any axis)."""

    joint: str
    axis: Vec3 | None = None
    min: Annotated[float, Field(ge=-180, le=180)] = -180.0
    max: Annotated[float, Field(ge=-180, le=180)] = 180.0
    cone: Annotated[float, Field(gt=0, le=180)] | None = None

    @model_validator(mode="after")
    def _kind(self) -> "JointLimit":
        if (self.axis is None) == (self.cone is None):
            raise ValueError("a joint limit needs exactly one of axis (a hinge, with min/max) or cone (a ball joint)")
        if self.axis is not None and sum(c * c for c in self.axis) < 1e-24:
            raise ValueError("axis must not be the zero vector")
        if self.min > self.max:
            raise ValueError(f"min ({self.min}) exceeds max ({self.max})")
        return self


class WeightKey(Model):
    """A key of an IK constraint's weight: its time and the weight in [0, 1]."""

    time: FiniteFloat
    value: Annotated[float, Field(ge=0, le=1)]


class IKConstraint(Model):
    """Inverse kinematics on a chain of parented objects `chain` (root joint first, each
    the parent of the next, the last is the end effector): after the chain's keyed pose,
    the joints turn so the effector reaches the world position of `target` (an object).
    `two-bone` (three names: e.g. hip, knee, ankle) is the analytic solver, the middle
    joint bending towards `pole`; `ccd` (cyclic coordinate descent) takes any length and
    joint `limits`. `weight` (a number or keys over time, 0 = keyed pose, 1 = solved)
    blends the solved rotations with the keyed ones; `keep_effector_rotation` keeps the
    effector's keyed world orientation (a foot stays flat)."""

    chain: Annotated[list[str], Field(min_length=2, max_length=32)]
    target: str
    solver: Literal["two-bone", "ccd"] = "two-bone"
    pole: str | None = None
    weight: Union[Annotated[float, Field(ge=0, le=1)], Annotated[list[WeightKey], Field(min_length=1)]] = 1.0
    time_unit: Literal["frames", "seconds"] = "frames"
    keep_effector_rotation: bool = False
    iterations: Annotated[int, Field(ge=1, le=1000)] = 64
    tolerance: Positive = 1e-5  # m, ccd stops when every time's effector is this close
    limits: list[JointLimit] = []

    @model_validator(mode="after")
    def _shape(self) -> "IKConstraint":
        if self.solver == "two-bone" and len(self.chain) != 3:
            raise ValueError(f"a two-bone chain has 3 names (root, middle, effector), got {len(self.chain)}")
        if self.solver == "two-bone" and self.limits:
            raise ValueError("joint limits apply to the ccd solver (two-bone is exact: limit it with its pole)")
        if len(set(self.chain)) != len(self.chain):
            raise ValueError("a chain names each joint once")
        if isinstance(self.weight, list):
            for i in range(1, len(self.weight)):
                if self.weight[i].time <= self.weight[i - 1].time:
                    raise ValueError(f"weight key times must increase strictly: weight[{i}].time {self.weight[i].time}")
        for lim in self.limits:
            if lim.joint not in self.chain[:-1]:
                raise ValueError(f"limit on '{lim.joint}', which is not a joint of the chain {self.chain[:-1]}")
        return self


MotionBlock = Annotated[
    Union[StaticMotion, KeyframeMotion, ProceduralMotion, DynamicsMotion, PlanMotion],
    Field(discriminator="type"),
]


# --- deformation (pipeline/motion/deform.py; docs/motion.md, "Deformation") ---------------


class MeshKey(Model):
    """One key mesh of a blend-shape animation: a file (.obj, same topology) or inline
    vertices (object space, metres). Counts are checked against the first key."""

    time: FiniteFloat
    file: str | None = None
    vertices: list[Vec3] | None = None

    @model_validator(mode="after")
    def _one_source(self) -> "MeshKey":
        if (self.file is None) == (self.vertices is None):
            raise ValueError("a mesh key needs exactly one of file, vertices")
        return self


class BlendShapes(Model):
    """Vertex animation between key meshes of identical topology, per vertex."""

    type: Literal["blend-shapes"]
    time_unit: Literal["frames", "seconds"] = "frames"
    interpolation: Literal["hold", "linear", "catmull-rom"] = "linear"
    extrapolation: Extrapolation = "hold"
    keys: Annotated[list[MeshKey], Field(min_length=1)]

    @field_validator("keys")
    @classmethod
    def _sorted(cls, keys: list[MeshKey]) -> list[MeshKey]:
        for i in range(1, len(keys)):
            if keys[i].time <= keys[i - 1].time:
                raise ValueError(f"key times must increase strictly: keys[{i}].time {keys[i].time} <= keys[{i - 1}].time {keys[i - 1].time}")
        return keys


class Bone(Model):
    """A bone frame in the mesh's object space: bind pose `transform` (relative to its
    parent bone), `length` along its local +Y (for auto weights), animated by `motion`."""

    name: Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_.\-]*$")]
    parent: str | None = None
    transform: Transform = Transform.default()
    length: Positive = 1.0
    motion: Annotated[Union[StaticMotion, KeyframeMotion, ProceduralMotion], Field(discriminator="type")] = StaticMotion.default()


class Skinning(Model):
    """Linear blend skinning: vertex = sum_b w_b (pose_b(t) bind_b^-1) vertex_bind, at most
    4 influences per vertex, weights normalised to sum 1. `weights` (one mapping bone ->
    weight per vertex of the bind mesh) or `auto: true` (by distance to each bone)."""

    type: Literal["skinning"]
    bones: Annotated[list[Bone], Field(min_length=1)]
    weights: list[dict[str, NonNegativeFloat]] | None = None
    auto: bool = False
    detail: Annotated[int, Field(ge=1, le=256)] = 16  # tessellation of primitive bind meshes

    @model_validator(mode="after")
    def _weights(self) -> "Skinning":
        if (self.weights is None) == (not self.auto):
            raise ValueError("skinning needs exactly one of weights, auto: true")
        return self


class MorphTarget(Model):
    """One morph target (a blend shape in the artist's sense): a mesh file of the same
    topology as the object's; `weight` is its weight when not animated."""

    name: Annotated[str, Field(min_length=1, max_length=128)]
    file: str
    weight: FiniteFloat = 0.0


class MorphTargets(Model):
    """vertex(t) = base + sum_i w_i(t) (target_i - base), per vertex; the weights are keyed
    by target name in `animation` (scalar channels), as glTF morph targets are."""

    type: Literal["morph-targets"]
    targets: Annotated[list[MorphTarget], Field(min_length=1, max_length=1024)]
    animation: KeyframeMotion | None = None


class JointSkin(Model):
    """Linear blend skinning driven by scene objects (joints), as glTF skins are:
    object-space vertex(t) = world_from_object(t)^-1 sum_k w_k world_from_joint_k(t)
    inverse_bind_k vertex_bind. `file` (.npz) holds `inverse_bind` [J, 4, 4],
    `joint_indices` [V, 4] and `joint_weights` [V, 4]; `morph` deforms the bind mesh first."""

    type: Literal["joint-skin"]
    joints: Annotated[list[Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_.\-]*$")]], Field(min_length=1)]
    file: str
    morph: MorphTargets | None = None



class FlockWeights(Model):
    """Weights of Reynolds's steering rules (dimensionless; docs/seed-motion.md, "Flocks")."""

    separation: NonNegativeFloat = 1.5
    alignment: NonNegativeFloat = 1.0
    cohesion: NonNegativeFloat = 1.0
    goal: NonNegativeFloat = 0.5
    avoid: NonNegativeFloat = 3.0


class FlockBounds(Model):
    """An axis-aligned box (world metres) the agents steer back into and never leave."""

    min: Vec3
    max: Vec3

    @model_validator(mode="after")
    def _ordered(self) -> "FlockBounds":
        if any(lo >= hi for lo, hi in zip(self.min, self.max)):
            raise ValueError(f"bounds min {self.min} must be below max {self.max} on every axis")
        return self


class Flock(Model):
    """A flock or crowd of `count` agents (boids: separation, alignment, cohesion, goal
    seeking, obstacle avoidance) simulated by the dynamics stage. Each agent is a copy of
    the object's own shape (a mesh file, a cube, cylinder or rectangle) turned so its
    local +Z faces along its velocity, local +Y towards `up`. Agents live in world space;
    they start in the box `spawn_center` +- `spawn_size` / 2 with speed `speed` in seeded
    random directions (horizontal ones when `planar`: a crowd on its ground plane)."""

    type: Literal["flock"]
    count: Annotated[int, Field(ge=1, le=1_000_000)]
    seed: int = 0
    spawn_center: Vec3 = (0.0, 0.0, 0.0)
    spawn_size: tuple[NonNegativeFloat, NonNegativeFloat, NonNegativeFloat] = (1.0, 1.0, 1.0)
    speed: NonNegativeFloat = 1.0  # m/s, initial
    min_speed: NonNegativeFloat = 0.2  # m/s
    max_speed: Positive = 2.0  # m/s
    max_accel: Positive = 8.0  # m/s^2, bound on the summed steering
    responsiveness: Positive = 2.0  # 1/s: steering acceleration = responsiveness * weighted sum
    neighbour_radius: Positive = 1.0  # m: alignment and cohesion see neighbours this close
    neighbours: Annotated[int, Field(ge=1, le=64)] = 8  # the nearest k within the radius
    separation: Positive = 0.2  # m: no two agents come closer (hard constraint)
    separation_range: Positive | None = None  # m: the separation rule acts inside it (default 2 x separation)
    weights: FlockWeights = FlockWeights.default()
    goal: Vec3 | None = None
    avoid_distance: Positive = 1.0  # m: obstacle avoidance starts this far from a collider
    look_ahead: NonNegativeFloat = 0.5  # s: obstacles are also tested where the agent will be
    bounds: FlockBounds | None = None
    planar: bool = False  # crowds: velocities stay in the plane normal to `up`
    up: Vec3 = (0.0, 1.0, 0.0)
    step: Annotated[float, Field(gt=0, le=0.1)] = 1.0 / 120.0  # s, the flock's own fixed step
    start: Annotated[FiniteFloat, Field(json_schema_extra={"unit": "s"}, description="when the flock starts moving, in seconds after the first frame (the dynamics clock: 0 at the timeline's first frame, whatever its number)")] = 0.0

    @model_validator(mode="after")
    def _consistent(self) -> "Flock":
        if self.min_speed > self.max_speed:
            raise ValueError(f"min_speed ({self.min_speed}) exceeds max_speed ({self.max_speed})")
        if self.separation_range is not None and self.separation_range < self.separation:
            raise ValueError(f"separation_range ({self.separation_range}) must be at least separation ({self.separation})")
        if sum(c * c for c in self.up) < 1e-24:
            raise ValueError("up must not be the zero vector")
        return self


Deformation = Annotated[Union[BlendShapes, Skinning, MorphTargets, JointSkin, Flock], Field(discriminator="type")]
