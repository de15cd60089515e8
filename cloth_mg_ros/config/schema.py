"""The one parameter schema: every parameter of a scene file, `cloth-mg run` and cloth_node.

`PARAMETERS` holds one `Parameter` per name, in the order `cloth_node --help` lists them: its
kind, its default (when no scene file sets one), unit, range or choices, whether it may be set
while the node runs, who reads it (`SHARED`: scene files, `cloth-mg run` and the node; `NODE`:
the node alone, a scene file may set it and the headless runner ignores it; `ROS`: ROS 2's own,
declared by rclpy, listed and accepted but not declared) and a one-line meaning.

Everything else is generated from it: the scene loader's checks (`check`, `scene_params`,
config.scenes), the node's parameter table, descriptors, run-time checks and `--help`
(ros.parameters), `cloth-mg run --help` for the shared parameters it has an option for
(`option_help`), and the docs' parameter table (`rows`, `markdown_table`). Adding a parameter
means adding it here and using it (test/test_schema.py checks that they all agree).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.garments import GARMENTS
from cloth_mg_ros.mesh.generators import MAX_PARTICLES, MIN_PARTICLES
from cloth_mg_ros.motion.input_frame import BODY_INPUTS, IDENTITY_TRANSFORM
from cloth_mg_ros.motion.skeletons import SKELETONS
from cloth_mg_ros.physics.materials import MATERIALS
from cloth_mg_ros.sim.garment_sim import MAX_FRAME_GAP, MAX_STEPS_PER_TICK, BodySimOptions
from cloth_mg_ros.sim.grippers import GRASP_RADIUS
from cloth_mg_ros.sim.model import COMPRESSION_MODELS, CONTACT_FRICTIONS
from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS, LINEARISE_AT, SCHEMES
from cloth_mg_ros.sim.sheets import SCENES as SHEET_SCENES
from cloth_mg_ros.sim.solve_tolerance import AUTO
from cloth_mg_ros.solvers import SOLVERS

__all__ = [
    "AUTO",
    "BODY_SCENES",
    "INPUT_RELIABILITY",
    "KINDS",
    "Numbers",
    "MAX_PARTICLES",
    "NODE",
    "PARAMETERS",
    "ROS",
    "SHARED",
    "TICK_MODES",
    "WRENCH_FRAMES",
    "Parameter",
    "SceneParams",
    "check",
    "defaults",
    "markdown_table",
    "option_help",
    "rows",
    "scene_params",
]

SHARED = "shared"  # scene files, `cloth-mg run` and the node
NODE = "node"  # the node alone (a scene file may set it; the headless runner ignores it)
ROS = "ros"  # ROS 2's own, declared by rclpy: listed and accepted, not declared by the node
SCOPES = {SHARED: "scene, run, node", NODE: "node", ROS: "ROS 2"}


class Numbers(tuple):
    """The value of a 'double array' parameter: a tuple of floats (a type of its own, so that
    it is told from a string array's plain tuple)."""

    __slots__ = ()


# kind: the Python type of its values (a number or AUTO for the two 'or auto' kinds)
KINDS = {"string": str, "integer": int, "double": float, "bool": bool,
         "integer or auto": int, "double or auto": float, "string array": tuple,
         "double array": Numbers}

BODY_SCENES = ("walking", "brisk_walking", "running", "jumping")
TICK_MODES = ("message", "timer")
INPUT_RELIABILITY = ("best_effort", "reliable")
WRENCH_FRAMES = ("world", "local")  # ros.wrenches: the frames a wrench may name
#: `avatar`'s two names (any other value is a YAML file's path).
AVATAR_PACKAGED, AVATAR_FROM_JOINTS = "packaged", "from_joints"
SKELETON_NAMES = tuple(SKELETONS)  # the joint layouts `skeleton` names


@dataclass(frozen=True)
class Parameter:
    """One parameter. range: (lowest, highest) accepted, both included (numbers); choices:
    the values a string takes (compared after strip().lower() with fold_case); what: the noun
    of its values in messages ('a relative residual'; default 'an integer', 'a number');
    sheet_default: the node's default for sheet scenes where it differs."""

    name: str
    kind: str
    default: object
    meaning: str
    unit: str = ""
    range: tuple[float, float] | None = None
    choices: tuple[str, ...] = ()
    runtime: bool = False
    scope: str = SHARED
    what: str = ""
    fold_case: bool = False
    sheet_default: object = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS or self.scope not in SCOPES:
            raise ValueError(f"parameter {self.name}: kind {self.kind!r} or scope "
                             f"{self.scope!r} unknown")

    @property
    def type(self) -> type:
        """The Python type of its values (int or float for the 'or auto' kinds)."""
        return KINDS[self.kind]

    @property
    def auto(self) -> bool:
        """Whether it also takes the string AUTO."""
        return self.kind.endswith(" or auto")

    def default_for(self, body: bool = True) -> object:
        """The default of a body scene, or the node's for a sheet scene."""
        return self.sheet_default if not body and self.sheet_default is not None \
            else self.default

    def values(self) -> str:
        """The values it takes, for messages and tables: 'an integer in 16..200000 or
        'auto'', 'one of pcg, mpcg', 'true or false', 'a non-empty string'."""
        if self.type is bool:
            return "true or false"
        if self.type is tuple:
            return "a list of distinct names (no '/')"
        if self.type is Numbers:
            return self.what or "a list of numbers"
        if self.type is str:
            return (f"one of {', '.join(self.choices)}" if self.choices
                    else "a non-empty string")
        text = self.what or ("an integer" if self.type is int else "a number")
        if self.range is not None:
            text += f" in {_num(self.range[0])}..{_num(self.range[1])}"
        return text + (f" or '{AUTO}'" if self.auto else "")

    def description(self) -> str:
        """The meaning with its unit: the node's descriptor text."""
        return f"{self.meaning} [{self.unit}]" if self.unit else self.meaning

    def chosen(self, value: str) -> bool:
        """Whether a string is one of the choices."""
        return (value.strip().lower() if self.fold_case else value) in self.choices

    def check(self, value: object, where: str = "") -> object:
        """`value` converted to the kind (an integer given for a double becomes a float), or
        ClothInputError '<where> must be <values>, got <value>' ('<where>: unknown <name>
        <value>; choose one of ...' for a string not among the choices); where: the file and
        key, the flag...; the name by default."""
        if self.auto and isinstance(value, str) and value == AUTO:
            return AUTO
        kind = self.type
        if self.choices and isinstance(value, str) and value.strip() and not self.chosen(value):
            raise ClothInputError(f"{where + ': ' if where else ''}unknown {self.name} "
                                  f"{value!r}; choose one of {', '.join(self.choices)}")
        if kind is bool:
            ok = isinstance(value, bool)
        elif kind is tuple:
            ok = (isinstance(value, (list, tuple))
                  and all(isinstance(v, str) and v.strip() and "/" not in v for v in value)
                  and len(set(value)) == len(value))
            if ok:
                value = tuple(value)
        elif kind is Numbers:
            ok = (not isinstance(value, (str, bytes)) and hasattr(value, "__len__")
                  and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                          and math.isfinite(v) for v in value))
            if ok:
                value = Numbers(float(v) for v in value)
        elif kind is str:
            ok = isinstance(value, str) and bool(value.strip())
        else:
            number = (int,) if kind is int else (int, float)
            ok = (isinstance(value, number) and not isinstance(value, bool)
                  and math.isfinite(value)
                  and (self.range is None or self.range[0] <= value <= self.range[1]))
            if ok:
                value = kind(value)
        if not ok:
            raise ClothInputError(f"{where or self.name} must be {self.values()}, got "
                                  f"{value!r}")
        return value


def _num(x: float) -> str:
    return str(x) if isinstance(x, int) else f"{x:g}"


def _table(*parameters: Parameter) -> dict[str, Parameter]:
    return {p.name: p for p in parameters}


PARAMETERS: dict[str, Parameter] = _table(
    Parameter("scene", "string", "walking",
              f"scene: a sheet ({', '.join(SHEET_SCENES)}) or a body scene "
              f"({', '.join(BODY_SCENES)}, config/<scene>.yaml or a params .yaml path); a "
              f"scene file that does not name itself takes its file's name"),
    Parameter("bag", "string", "walk",
              "the scene's bag of body poses, a bundled bag's name or a rosbag2 path (the "
              "headless runner reads it; the node listens on `topic`: play the bag with "
              "`cloth-mg replay`)"),
    Parameter("topic", "string", "avatar/body_poses",
              "geometry_msgs/PoseArray input topic: the avatar's body poses (body scenes)"),
    Parameter("input_reliability", "string", "best_effort",
              "QoS reliability of the pose subscription: best_effort matches reliable and "
              "best-effort (sensor data) publishers alike; reliable matches reliable ones only",
              choices=INPUT_RELIABILITY, scope=NODE),
    Parameter("body_input", "string", "segments",
              "what each pose message holds: segments (one pose per avatar segment, the "
              "avatar's convention: doc/node.md), joints (a body tracker's joint positions "
              "in the order of `skeleton`; orientations ignored) or kinect_markers (the Azure "
              "Kinect ROS driver's visualization_msgs/MarkerArray on `topic`, kinect32's "
              "joints of body `body_id`)",
              choices=BODY_INPUTS, scope=NODE),
    Parameter("body_id", "integer", -1,
              "body_input kinect_markers: the body to follow (marker id // 100); -1: the body "
              "whose pelvis is nearest the camera, in each message",
              range=(-1, 1_000_000), scope=NODE),
    Parameter("skeleton", "string", "kinect32",
              "body_input joints: the joints' layout, in the PoseArray's order: kinect32 "
              "(Azure Kinect Body Tracking, 32 joints), mediapipe33 (MediaPipe Pose, 33 "
              "landmarks), cmu31 (the CMU BVH skeleton, 31 joints)",
              choices=SKELETON_NAMES, scope=NODE),
    Parameter("joint_hold", "double", 0.15,
              "body_input joints: how long a missing joint (NaN: occluded) is held, carried by "
              "its parent joint; its segments then leave the collider until it is back (a "
              "longer hold places them further from the truth: a walker's hidden ankle 0.45 m "
              "off after 0.25 s)",
              unit="s", range=(0.0, 10.0), scope=NODE),
    Parameter("joint_filter_hz", "double", 5.0,
              "body_input joints: the 1 Euro filter's cut-off at rest (jitter; Casiez et al. "
              "2012), its cut-off rising by joint_filter_beta per m/s; 0: no filter",
              unit="Hz", range=(0.0, 1000.0), scope=NODE),
    Parameter("joint_filter_beta", "double", 1000.0,
              "body_input joints: how fast the filter's cut-off rises with a joint's speed",
              unit="Hz per m/s", range=(0.0, 1e6), scope=NODE),
    Parameter("input_transform", "double array", Numbers(IDENTITY_TRANSFORM),
              "the body poses' frame (a tracker's) in the simulation's z-up world: "
              "[x, y, z, qx, qy, qz, qw], translation and unit quaternion, as a tf2 static "
              "transform states it; poses are moved by it on arrival, and the outputs are "
              "then published in `frame_id`",
              unit="m", what="[x, y, z, qx, qy, qz, qw]", scope=NODE),
    Parameter("floor_height", "double or auto", 0.0,
              "the floor's height in the transformed poses' frame (it is brought to z = 0), "
              "or 'auto': measured over each stream's first second (the lowest capsule point "
              "less the avatar's ground clearance)",
              unit="m", range=(-100.0, 100.0), scope=NODE),
    Parameter("avatar", "string", AVATAR_PACKAGED,
              "the body's capsules: packaged (config/avatar.yaml), a YAML file like it, or "
              "from_joints (body_input joints or kinect_markers: the packaged avatar sized to "
              "the segment lengths measured over each stream's first second; for a subject "
              "not the packaged avatar's size: mediapipe33's pelvis is set by the avatar's "
              "spine length)",
              scope=NODE),
    Parameter("garment", "string", "dress", "garment of a body scene", choices=GARMENTS),
    Parameter("particles", "integer or auto", 2400,
              "approximate number of cloth particles, or 'auto' (body scenes): the most whose "
              "predicted tick fits tick_budget x the pose period (cost model, calibrated once "
              "per machine)", range=(MIN_PARTICLES, MAX_PARTICLES)),
    Parameter("tick_budget", "double", 0.7,
              "body scenes: fraction of the pose period a tick may take (particles auto, lod)",
              range=(1e-3, 1.0), what="a fraction of the pose period"),
    Parameter("max_particles", "integer", 20000,
              "body scenes: particles auto takes at most this many (what the scene needs)",
              range=(MIN_PARTICLES, MAX_PARTICLES)),
    Parameter("lod", "bool", False,
              "body scenes: live level of detail: step down the garment's hierarchy when ticks "
              "overrun the budget, back up when they stay well under it"),
    Parameter("material", "string", "white-dots-on-blk",
              "cloth material: a measured fabric or one of the paper's Table 2 set (cloth-mg "
              "materials)", choices=tuple(MATERIALS), fold_case=True),
    Parameter("solver", "string", "mpcg",
              "linear solver of each implicit step (a change while running rebuilds the "
              "solver)", choices=SOLVERS, runtime=True),
    Parameter("tolerance", "double or auto", 1e-4,
              "relative residual the linear solve must reach (against the step's right-hand "
              "side, or its weight's impulse where that is larger: a cloth at rest), or "
              "'auto' (body scenes): each "
              "level solves to the tolerance its time step allows, measured with the cost "
              "model (the node takes 'auto' at run time only if it started with it)",
              range=(1e-10, 0.5), runtime=True, what="a relative residual"),
    Parameter("levels", "integer", 0,
              "multigrid hierarchy levels (0: as many as the mesh size calls for)",
              range=(0, 7)),
    Parameter("substeps", "integer", 1, "body scenes: at least this many steps per tick",
              range=(1, MAX_STEPS_PER_TICK)),
    Parameter("max_substep_motion", "double", 0.05,
              "body scenes: more steps while a capsule end that can reach the cloth moves "
              "further than this per step", unit="m", range=(1e-3, 1.0)),
    Parameter("max_step", "double", 0.1,
              "body scenes: no step longer than this (a tick that coalesces several pose "
              "messages takes longer steps up to this)", unit="s", range=(1e-3, MAX_FRAME_GAP)),
    Parameter("scheme", "string", "bdf2",
              "implicit integrator: euler (first order, damps motion the most), bdf2 (second "
              "order) or genalpha (generalised-alpha, second order, its numerical damping set "
              "by spectral_radius)", choices=SCHEMES),
    Parameter("newton_iterations", "integer", 1,
              "Newton iterations per step (euler and bdf2): 1 linearises each step once "
              "where the cloth starts; more re-solve it where the last iterate ends, each an "
              "assembly and a solve more, so a turning membrane keeps its turn (bdf2's own "
              "damping of a swinging strip at 1/60 s: 0.0012 with 1, 0.0002 with 3)",
              range=(1, 8)),
    Parameter("linearise_at", "string", "start",
              "euler and bdf2: where a step linearises the forces: start (where the cloth "
              "starts, the paper's step) or prediction (where it goes at its velocities): the "
              "same cost, and a turning membrane keeps more of its turn (bdf2's own damping "
              "of a swinging strip at 1/60 s: 0.0012 from the start, 0.0002 at the "
              "prediction), but a stiff sheet landing on a body can bounce (the drape in "
              "cotton: doc/benchmarks/dynamics.md)", choices=LINEARISE_AT),
    Parameter("spectral_radius", "double", DEFAULT_SPECTRAL_RADIUS,
              "genalpha: how much of the fastest modes a step keeps, rho_inf (1: no numerical "
              "damping, the trapezoidal rule; 0: the fastest modes damped out in one step, "
              "landings as implicit Euler has them; up to 0.8 the stability maps hold, with "
              "faster particles on a jumping body; at 1 the cloth can gain energy)",
              range=(0.0, 1.0), what="a ratio"),
    Parameter("friction", "double", 0.5,
              "Coulomb friction coefficient of the cloth against the body, the floor and the "
              "scene's obstacles (the hang has none: unused there)", range=(0.0, 10.0),
              what="a coefficient"),
    Parameter("compression", "string", "elastic",
              "the membrane under compression: elastic (resisted as in tension, the paper's) "
              "or buckle (a triangle wrinkles along the fabric's threads where its stress is "
              "compressive past the buckling stress its bending allows, pi^2 B / h^2)",
              choices=COMPRESSION_MODELS),
    Parameter("contact_friction", "string", "projection",
              "where friction against the body, the floor and obstacles acts: projection "
              "(after each step's solve, on each particle alone: the paper's) or solve (inside "
              "it, with the contacts that pressed at the last step kept and a stiffer "
              "penalty: the walking dress at 10K particles holds 0.13 J of stretch instead "
              "of 5.4 J, a cotton sheet draped on a sphere 0.25 J instead of 15 J; not yet "
              "measured on every figure: doc/benchmarks/folds.md)",
              choices=CONTACT_FRICTIONS),
    Parameter("threads", "integer", 0,
              "simulation threads (0: every core); the cloth follows this number bit for bit, "
              "not the machine's timing", range=(0, 1024)),
    Parameter("floor", "bool", True, "body scenes: a ground plane at z = 0"),
    Parameter("self_contact", "bool", False, "body scenes: cloth-cloth repulsion"),
    Parameter("grippers", "string array", (),
              "grippers by name, each with topics gripper/<name>/pose, grasp and wrench (the "
              "hang scene's are left and right)"),
    Parameter("grasp_radius", "double", GRASP_RADIUS,
              "a grasp takes the free particles this near the grasp point", unit="m",
              range=(0.001, 0.5)),
    Parameter("release_force", "double", 0.0,
              "a gripper pulled harder than this lets go by itself (0: never)", unit="N",
              range=(0.0, 1e4), runtime=True),
    Parameter("wrench_frame", "string", "world",
              "the frame each gripper/<name>/wrench and cloth/contact/<segment> names, its "
              "torque taken about that frame's origin (tf2 re-expresses it right): world (the "
              "poses' frame, torque about its origin) or local (each gripper's frame, "
              "gripper_frame, at its grasp point; each segment's, segment_frame, at its "
              "origin; force and torque in its axes)", choices=WRENCH_FRAMES, scope=NODE),
    Parameter("gripper_frame", "string", "gripper/{name}",
              "wrench_frame local: the name of a gripper's frame ({name}: the gripper's)",
              scope=NODE),
    Parameter("segment_frame", "string", "{name}",
              "wrench_frame local: the name of a body segment's frame ({name}: the "
              "segment's, as in the avatar's names)", scope=NODE),
    Parameter("tick_mode", "string", "message",
              "message: each tick advances the cloth to the newest pose message, through every "
              "one received since the last tick (body scenes); timer: one tick every 1/rate_hz "
              "s (sheet scenes' default)", choices=TICK_MODES, scope=NODE,
              sheet_default="timer"),
    Parameter("rate_hz", "double", 30.0,
              "timer rate: ticks per second of wall time (of /clock's time under use_sim_time)",
              unit="Hz", range=(0.1, 1000.0), runtime=True, scope=NODE),
    Parameter("dt", "double", 1.0 / 60.0, "sheet scenes: simulation time step", unit="s",
              range=(1e-5, 0.1), scope=NODE),
    Parameter("frame_id", "string", "world",
              "frame of everything published (z up, metres) when the body poses' "
              "header.frame_id is empty (body scenes publish in the poses' frame), and of "
              "sheet scenes", scope=NODE),
    Parameter("marker_topic", "string", "cloth/marker",
              "visualization_msgs/Marker output: the cloth (relative names move with the "
              "node's namespace)", scope=NODE),
    Parameter("markers_topic", "string", "cloth/markers",
              "visualization_msgs/MarkerArray output: the avatar's capsules, the scene's "
              "colliders and a caption with the node's figures (the cloth is on marker_topic "
              "alone, so it is drawn once)", scope=NODE),
    Parameter("stats_topic", "string", "cloth/stats",
              "diagnostic_msgs/DiagnosticArray output, per tick", scope=NODE),
    Parameter("points_topic", "string", "cloth/points",
              "sensor_msgs/PointCloud2 output: the particles (x, y, z float32, m; with "
              "points_velocity also vx, vy, vz, m/s)", scope=NODE),
    Parameter("points_velocity", "bool", False,
              "add the particles' velocities to the point cloud", scope=NODE),
    Parameter("mesh_topic", "string", "cloth/mesh",
              "shape_msgs/Mesh output: the garment's triangles and vertices (in the markers' "
              "frame)", scope=NODE),
    Parameter("diagnostics_period", "double", 1.0,
              "time between statuses on /diagnostics (the aggregator's topic; per-tick figures "
              "stay on stats_topic)", unit="s", range=(0.1, 60.0), scope=NODE),
    Parameter("marker_lifetime", "double", 0.0,
              "how long a display keeps each marker after its stamp (0: until replaced or "
              "deleted; the node deletes its markers at shutdown, and a lifetime clears them "
              "also when the node is killed)", unit="s", range=(0.0, 3600.0), scope=NODE),
    Parameter("strain_colours", "bool", False,
              "colour the cloth by stretch (per-vertex colours)", scope=NODE),
    Parameter("max_steps", "integer", 0, "exit after this many ticks (0: run until shut down)",
              range=(0, 2**31 - 1), scope=NODE),
    Parameter("managed", "bool", False,
              "start as a ROS 2 managed (lifecycle) node: unconfigured until a configure "
              "transition, ticking only while active (`cloth_node_managed` is the same)",
              scope=NODE),
    Parameter("use_sim_time", "bool", False,
              "ROS 2's own: take time from /clock (`cloth-mg replay --clock` publishes it)",
              scope=ROS),
)


def check(name: str, value: object, where: str = "") -> object:
    """Parameter `name`'s `value` checked and converted (Parameter.check); ClothInputError
    for an unknown name."""
    if name not in PARAMETERS:
        raise ClothInputError(f"{where or 'parameters'}: unknown parameter {name!r}; known: "
                              f"{', '.join(PARAMETERS)}")
    return PARAMETERS[name].check(value, where)


class SceneParams(Mapping):
    """A scene's parameters, every one of the schema's, checked and typed: a frozen dataclass
    with one field per parameter, typed by its kind (`config_class`), so that a value is read
    as an attribute (``params.garment``) with no lookup by name; a read-only Mapping too
    (``params["garment"]``, ``dict(params)``) for code that handles them as a dict. A change
    is a checked copy (`replace`)."""

    __slots__ = ()

    def __getitem__(self, name: str) -> object:
        if name not in self.__dataclass_fields__:
            raise KeyError(name)
        return getattr(self, name)

    def __iter__(self) -> Iterator[str]:
        return iter(self.__dataclass_fields__)

    def __len__(self) -> int:
        return len(self.__dataclass_fields__)

    def __reduce__(self):
        return _from_values, (self.as_dict(),)

    def replace(self, **changes: object) -> SceneParams:
        """A copy with `changes`, each checked (ClothInputError names the key and value)."""
        where = f"scene {self.scene}"
        checked = {k: check(k, v, f"{where}: {k}") for k, v in changes.items()}
        return dataclasses.replace(self, **checked)

    def as_dict(self) -> dict[str, object]:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}


def _field_type(p: Parameter) -> object:
    """The annotation of parameter p's field: its type, or that or a str for 'or auto'."""
    return p.type | str if p.auto else p.type


@functools.cache
def config_class(names: tuple[str, ...]) -> type[SceneParams]:
    """The typed configuration class of the parameters ``names`` (the schema's, in order): a
    frozen, slotted dataclass, one field per parameter typed by its kind, made from the table
    (a parameter added to the table alone gets its field)."""
    cls = dataclasses.make_dataclass(
        "SceneConfig", [(n, _field_type(PARAMETERS[n])) for n in names], bases=(SceneParams,),
        frozen=True, eq=False, slots=True)
    cls.__module__ = __name__
    return cls


def _from_values(values: Mapping[str, object]) -> SceneParams:
    """A SceneParams of checked ``values`` (every parameter's, in the schema's order)."""
    return config_class(tuple(values))(**values)


def defaults(body: bool = True) -> SceneParams:
    """Every parameter's default (a body scene's, or the node's for a sheet scene)."""
    return _from_values({p.name: p.default_for(body) for p in PARAMETERS.values()})


def body_options(**overrides: object):
    """A body scene's simulation options (sim.garment_sim.BodySimOptions) with the schema's
    defaults, ``overrides`` (garment, particles, ... or the simulation's own fields) on top."""
    return BodySimOptions.from_scene(defaults(), **overrides)


def scene_params(values: Mapping[str, object], where: str = "", body: bool = True
                 ) -> SceneParams:
    """The defaults with `values` (a scene file's, the node's...) checked on top; where:
    what to name in an error ('scene file config/x.yaml'), before the key."""
    prefix = f"{where}: " if where else ""
    checked = {k: check(k, v, f"{prefix}{k}") for k, v in values.items()}
    return _from_values({**defaults(body), **checked})


def option_help(name: str) -> str:
    """`cloth-mg run --help`'s text of the option that sets shared parameter `name`: its
    meaning, unit, values and default (a scene file sets its own)."""
    p = PARAMETERS[name]
    default = _show(p.default)
    if p.sheet_default is not None:
        default += f" (sheets {_show(p.sheet_default)})"
    unit = f"{p.unit}; " if p.unit else ""
    return (f"{p.meaning} ({unit}{p.values()}; default {default}, or the scene "
            f"file's)").replace("%", "%%")


def rows(scene_defaults: Mapping[str, object] | None = None) -> list[dict]:
    """One dict per parameter for tables (the docs): name, kind, default (the value of
    `scene_defaults`, e.g. config.scenes.load_scene('walking'), where it has one), unit,
    range (the values it takes; '' for a bool), runtime, scope and meaning."""
    given = scene_defaults or {}
    return [{"name": p.name, "kind": p.kind,
             "default": given.get(p.name, p.default),
             "unit": p.unit, "range": "" if p.type is bool else p.values(),
             "runtime": p.runtime, "scope": p.scope, "meaning": p.meaning}
            for p in PARAMETERS.values()]


def markdown_table(table: list[dict] | None = None) -> str:
    """The docs' parameter table (MyST markdown) of `rows()` (or the rows given)."""
    out = ["| parameter | type | default | unit | values | set | read by | meaning |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows() if table is None else table:
        out.append(f"| `{r['name']}` | {r['kind']} | `{_cell(_show(r['default']))}` | "
                   f"{r['unit']} | {_cell(r['range'])} | "
                   f"{'run time' if r['runtime'] else 'start'} | {SCOPES[r['scope']]} | "
                   f"{_cell(r['meaning'])} |")
    return "\n".join(out) + "\n"


def _show(value: object) -> str:
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


_CLASH = set(PARAMETERS) & {n for n in dir(SceneParams) if not n.startswith("_")}
if _CLASH:  # params.<name> must read the parameter, not a method
    raise ValueError(f"parameter names {sorted(_CLASH)} clash with SceneParams' methods")
