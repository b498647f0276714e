"""The render core's stage table: which stages a render runs, in order, and the one parallel loop that runs them.

Every scene goes through the same stages (``stages/``), each a plain function over a claimed range of a pass::

    camera -> setup -> light samples -> BSDF rays -> (environment radiance) -> finish -> shadow rays -> accumulation

A :class:`Plan` says what a scene needs and :meth:`Plan.stages` picks each stage's variant: where the environment map
is the only light, the light-sample stage samples it without a selector (8 samples at a time in vector IR where its
density allows), BSDF rays need only their lat-long coordinates and the radiance lookups get a stage of their own;
with emissive surfaces a BSDF ray finds its nearest hit (analytic shapes, then Embree) to see what it meets.  The
camera, BSDF and shadow rays meet the analytic shapes 8 at a time (vector IR) wherever the scene has no shape
hierarchy (with one, the BSDF and shadow rays walk it in the scalar stages); the setup stage carries texture code
only for scenes with textured materials.  :data:`STAGES` is the one registry: each stage's body, what it counts
(camera samples, slots, blocks of 8), and the scalar twin of a vector stage.  A body's parameters are the pass
records it reads and writes (:data:`RECORDS`, ``pass_state.py``), so its signature says what data it touches.

:func:`run_stage` is the loop over a stage's items, written once (pbrt-v4's ``ForAllQueued``): a worker claims chunks
of the items from a shared counter (``_worksharing.py``) and calls the stage's body on each; :class:`Launcher` runs
one worker per thread.  The loop is compiled per group of stages (:data:`GROUPS`: each plan's, and each stage
alone), so a render compiles its plan's stages and no others; a body compiles once for every plan that runs it
(decisions.md 77, 104).
"""

from __future__ import annotations

import functools
import inspect
import itertools
import os
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass, fields

from numba import literally, njit, typeof, types
from numba.core.errors import TypingError
from numba.extending import overload

from .._numba import FASTMATH
from .._worksharing import claim_range, new_counter
from ..errors import ParameterError
from .accumulation import accumulate, pass_pixels_count
from .stages.bsdf_rays import (
    environment_coords,
    environment_coords_lanes,
    infinite_lights,
    nearest_analytic,
    nearest_analytic_lanes,
    nearest_mesh,
    non_light_blocks,
    what_bsdf_rays_see,
)
from .stages.camera import camera_blocks, camera_lanes, camera_lanes_tree, camera_samples, camera_scalar
from .stages.finish import finish
from .stages.light_samples import (
    environment_blocks,
    environment_lanes,
    environment_resampled,
    environment_scalar,
    light_samples,
    slots_of_pass,
)
from .stages.radiance import environment_radiance, environment_radiance_lanes, slot_blocks
from .stages.setup import shading_setup, shading_setup_textured
from .stages.shadows import (
    analytic_shadows,
    analytic_shadows_lanes,
    mesh_shadows,
    mesh_shadows_single,
)

__all__ = [
    "CLAIM",
    "GROUPS",
    "LOOPS_ENVIRONMENT",
    "RECORDS",
    "STAGES",
    "Launcher",
    "Plan",
    "Stage",
    "body_parameters",
    "group_id",
    "group_loop_source",
    "loop_groups",
    "loop_per_stage",
    "run_stage",
    "stage_id",
]

# "plan" (the default): a render runs its plan's stages in one compiled loop; "stage": each stage in a loop of its own
LOOPS_ENVIRONMENT = "LIGHTPROBE_STAGE_LOOPS"


def loop_per_stage() -> bool:
    """Whether renders run each stage in a loop of its own (``LIGHTPROBE_STAGE_LOOPS=stage``) rather than their
    plan's stages in one loop (``plan``, the default).  The same bodies run in the same order on the same items, so
    the image is the same bits (a test); what differs is the compiling.  A plan's loop is the cheaper to compile for
    one kind of scene (10 s against 37 s for the demo's nine stages: each loop's wrapper unboxes the pass records),
    the loops per stage are shared by every plan, so a process that renders many kinds of scene (the test suite,
    about 34 plans) compiles each stage's loop once instead of every plan's (decisions.md 104)."""
    given = os.environ.get(LOOPS_ENVIRONMENT, "plan").strip().lower()
    if given not in ("plan", "stage"):
        raise ParameterError(f"{LOOPS_ENVIRONMENT}={given!r}: expected 'plan' or 'stage'")
    return given == "stage"


def loop_groups(stages: tuple[int, ...]) -> tuple[tuple[int, ...], ...]:
    """The groups whose compiled loops run a plan's ``stages`` (ids): the plan's one group, or with
    ``LIGHTPROBE_STAGE_LOOPS=stage`` each stage alone."""
    return tuple((i,) for i in stages) if loop_per_stage() else (tuple(stages),)


# The records of a pass (pass_state.py) in the order the stage loop receives them, then the loop's own facts: the
# worker (its scratch rows) and the claimed items [lo, hi).  A stage body's parameters are the ones it reads or
# writes, in this order: its signature is the declaration of its data (pbrt-v4's wavefront/workitems.soa).
RECORDS = ("s", "env", "lights", "sel", "c", "cams", "slots", "acc")
CLAIM = ("worker", "lo", "hi")


def body_parameters(body) -> tuple[str, ...]:
    """The names of a stage body's parameters: some of :data:`RECORDS`, then ``worker`` if it uses its scratch rows,
    then ``lo, hi``, in that order (a TypeError naming the body otherwise)."""
    names = tuple(inspect.signature(getattr(body, "py_func", body)).parameters)
    order = RECORDS + CLAIM
    if (
        names[-2:] != ("lo", "hi")
        or any(n not in order for n in names)
        or list(names) != sorted(names, key=order.index)
    ):
        raise TypeError(f"stage body {body.__name__}{names}: expected some of {order[:-2]} in that order, then lo, hi")
    return names


@dataclass(frozen=True)
class Stage:
    """One stage: its body over items [lo, hi), whose parameters (:func:`body_parameters`) name the records it uses,
    the number of items of a pass ``items(c, cams, slots)``, and for a vector stage the name of its scalar twin."""

    name: str
    body: object
    items: object
    twin: str | None = None

    @property
    def parameters(self) -> tuple[str, ...]:
        return body_parameters(self.body)


STAGES: tuple[Stage, ...] = (
    Stage("camera", camera_lanes, camera_blocks, twin="camera_scalar"),
    Stage("camera_tree", camera_lanes_tree, camera_blocks, twin="camera_scalar"),
    Stage("camera_scalar", camera_scalar, camera_samples),
    Stage("setup", shading_setup, camera_samples),
    Stage("setup_textured", shading_setup_textured, camera_samples),
    Stage("light_samples", light_samples, slots_of_pass),
    Stage("environment_samples_lanes", environment_lanes, environment_blocks, twin="environment_samples"),
    Stage("environment_samples", environment_scalar, slots_of_pass),
    Stage("environment_samples_resampled", environment_resampled, slots_of_pass),
    Stage("environment_coords_lanes", environment_coords_lanes, non_light_blocks, twin="environment_coords"),
    Stage("environment_coords", environment_coords, slots_of_pass),
    Stage("infinite_lights", infinite_lights, slots_of_pass),
    Stage("nearest_analytic_lanes", nearest_analytic_lanes, slot_blocks, twin="nearest_analytic"),
    Stage("nearest_analytic", nearest_analytic, slots_of_pass),
    Stage("nearest_mesh", nearest_mesh, slots_of_pass),
    Stage("what_bsdf_rays_see", what_bsdf_rays_see, slots_of_pass),
    Stage("environment_radiance_lanes", environment_radiance_lanes, slot_blocks, twin="environment_radiance"),
    Stage("environment_radiance", environment_radiance, slots_of_pass),
    Stage("finish", finish, camera_samples),
    Stage("analytic_shadows_lanes", analytic_shadows_lanes, slot_blocks, twin="analytic_shadows"),
    Stage("analytic_shadows", analytic_shadows, slots_of_pass),
    Stage("mesh_shadows", mesh_shadows, slots_of_pass, twin="mesh_shadows_single"),
    Stage("mesh_shadows_single", mesh_shadows_single, slots_of_pass),
    Stage("accumulate", accumulate, pass_pixels_count),
)
_IDS = {stage.name: i for i, stage in enumerate(STAGES)}


def jit_stage_loop(func):
    """Compile the stage loop: no reference counting (as the bodies, ``_numba.jit_body``), the GIL released."""
    return njit(cache=True, nogil=True, error_model="numpy", fastmath=FASTMATH, _nrt=False)(func)


def stage_id(name: str) -> int:
    return _IDS[name]


def _run_group(group, position, s, env, lights, sel, c, cams, slots, acc, counter, worker):
    """The claim loop of :func:`run_stage` for one stage group (the overload below)."""


@overload(_run_group, prefer_literal=True)
def _run_group_overload(group, position, s, env, lights, sel, c, cams, slots, acc, counter, worker):
    """The loop for the group whose index ``group`` is a compile-time constant: its own stages only, each called with
    the records it declares (:func:`group_loop_source`), so only they are typed and compiled (indexing a global
    table of every group made Numba lower all of it, 4.8 s).  Called, not inlined: Numba compiles an overload's
    implementation whole to type it, so an inlined loop was compiled twice, the second time inside
    :func:`run_stage` (a plan's loop 7.3 -> 5.7 s; the call is one per stage and worker, decisions.md 113)."""
    if not isinstance(group, types.IntegerLiteral):
        raise TypingError("run_stage's group must be a compile-time constant")
    return _group_loop(group.literal_value)


def group_loop_source(group: int) -> str:
    """The Python source of group ``group``'s loop: for the stage at ``position``, claim chunks of its items from the
    shared counter and call its body on each, with the records its signature names.  Written out per group (as
    pbrt-v4's wavefront integrator instantiates a kernel per work queue) so that each body's call lists what it
    reads: a reader finds a stage's data in its signature, not in 11 arguments every stage received."""
    lines = ["def loop(group, position, s, env, lights, sel, c, cams, slots, acc, counter, worker):"]
    for position, stage in enumerate(GROUPS[group]):
        lines += [
            f"    {'if' if position == 0 else 'elif'} position == {position}:  # {STAGES[stage].name}",
            f"        n = items_{position}(c, cams, slots)",
            "        lo, hi = claim_range(counter, n)",
            "        while lo < hi:",
            f"            body_{position}({', '.join(STAGES[stage].parameters)})",
            "            lo, hi = claim_range(counter, n)",
        ]
    return "\n".join(lines) + "\n"


@functools.cache
def _group_loop(group: int):
    """Group ``group``'s loop, compiled from :func:`group_loop_source` (one function object per group, so that
    Numba types it once)."""
    namespace = {"claim_range": claim_range}
    for position, stage in enumerate(GROUPS[group]):
        namespace[f"items_{position}"] = STAGES[stage].items
        namespace[f"body_{position}"] = STAGES[stage].body
    exec(compile(group_loop_source(group), f"<stage loop of group {group}>", "exec"), namespace)
    return namespace["loop"]


@jit_stage_loop
def run_stage(group, position, s, env, lights, sel, c, cams, slots, acc, counter, worker):
    """Worker ``worker``'s share of the stage at ``position`` of stage group ``group`` (an index into
    :data:`GROUPS`): chunks of the stage's items claimed from ``counter`` until none is left.  ``group`` is a
    compile-time constant (``literally``): each group, a plan's stages, compiles one loop written for its own stages
    (:func:`group_loop_source`: each body called with the records it names), so a render compiles the stages its
    plan runs and no others (decisions.md 104)."""
    literally(group)
    _run_group(group, position, s, env, lights, sel, c, cams, slots, acc, counter, worker)


class Launcher:
    """Runs the stages ``stages`` (ids: one compiled loop for them all, :func:`run_stage`; None, or
    ``LIGHTPROBE_STAGE_LOOPS=stage``: each stage in its own, as :func:`loop_groups` says) with ``threads`` workers:
    the calling thread is worker 0, a shared pool's threads the others.  Each worker runs
    :func:`run_stage`, which releases the GIL, so the workers run in parallel; which worker takes which chunk changes
    nothing in the image (every item of a stage is independent, and a worker's scratch rows are its own).  Measured
    against Numba's parallel loops, decisions.md 77."""

    _pool: ThreadPoolExecutor | None = None
    _pool_size = 0

    def __init__(self, threads: int, stages: tuple[int, ...] | None = None):
        self.threads = threads
        self.stages = None if stages is None or loop_per_stage() else tuple(stages)
        if threads > 1 and Launcher._pool_size < threads - 1:
            Launcher._pool = ThreadPoolExecutor(max_workers=threads - 1, thread_name_prefix="lightprobe-stage")
            Launcher._pool_size = threads - 1
        self.counter = new_counter()  # the chunk claims' shared counter (_worksharing.py)
        self._entries: dict[int, object] = {}

    def _place(self, stage: int) -> tuple[int, int]:
        """(group, position) of ``stage`` in :data:`GROUPS`."""
        if self.stages is None:
            return group_id((stage,)), 0
        return group_id(self.stages), self.stages.index(stage)

    def run(self, stage: int, records: tuple) -> None:
        """Stage ``stage`` (an id) over the pass whose ``records`` are (s, env, lights, sel, c, cams, slots, acc)."""
        group, position = self._place(stage)
        self.counter[0] = 0
        call = self._entries.get(group)
        if call is None:  # later calls skip the dispatcher's typing of ~150 arrays (a millisecond)
            call = self._entries[group] = _loop_for(group, (position, *records, self.counter, 0))
        futures = [
            Launcher._pool.submit(call, group, position, *records, self.counter, w) for w in range(1, self.threads)
        ]
        try:
            call(group, position, *records, self.counter, 0)
        finally:
            wait(futures)  # never leave a worker writing into the pass after a Ctrl-C or an error
        for f in futures:
            f.result()


def _loop_for(group: int, args: tuple):
    """The compiled :func:`run_stage` of ``group`` for arguments like ``args`` (after the group): compiled, or loaded
    from the cache, for the group as a literal type.  Called with a plain int, the dispatcher would first raise and
    catch Numba's ForceLiteralArg, whose traceback holds the calling frames, the pass's records among them, in a
    reference cycle: every render's pass buffers (GBs) then stayed in memory until Python's cyclic collector next
    ran, and a test process grew past 20 GB."""
    signature = (types.literal(group), *(typeof(x) for x in args))
    compiled = run_stage.overloads.get(signature)
    if compiled is None:
        run_stage.compile(signature)
        compiled = run_stage.overloads[signature]
    return compiled.entry_point


@dataclass(frozen=True)
class Plan:
    """What a render needs, from its scene and settings, and so which stages it runs."""

    environment_alone: bool  # the environment map is the only light (one light sample per pick)
    bounded_lights: bool  # area, point or spot lights: shadow rays that end at a light
    emissive_surfaces: bool  # BSDF rays must find their nearest hit to see what they meet
    meshes: bool
    resampled: bool  # env_candidates > 1
    lanes: bool  # this Numba's LLVM builds the vector intrinsics
    environment_samples_in_lanes: bool
    environment_coords_in_lanes: bool
    environment_radiance_in_lanes: bool
    packets: bool  # Embree's 8-ray packets are native
    textured: bool = False  # some material has textures (the setup stage's texture lookups compile only then)
    shape_tree: bool = False  # a hierarchy over many spheres and rectangles, which rays walk one at a time

    def stages(self) -> tuple[str, ...]:
        """The names of this render's stages, in order."""
        camera = ("camera_tree" if self.shape_tree else "camera") if self.lanes else "camera_scalar"
        names = [camera, "setup_textured" if self.textured else "setup"]
        if self.environment_alone:
            if self.resampled:
                names.append("environment_samples_resampled")
            elif self.environment_samples_in_lanes:
                names.append("environment_samples_lanes")
            else:
                names.append("environment_samples")
            names.append("environment_coords_lanes" if self.environment_coords_in_lanes else "environment_coords")
            names.append("environment_radiance_lanes" if self.environment_radiance_in_lanes else "environment_radiance")
        else:
            names.append("light_samples")
            if self.emissive_surfaces:
                names.append("nearest_analytic_lanes" if self.lanes and not self.shape_tree else "nearest_analytic")
                if self.meshes:
                    names.append("nearest_mesh")
                names.append("what_bsdf_rays_see")
            else:  # the infinite lights are all a BSDF ray can see (none: it is dropped)
                names.append("infinite_lights")
        names.append("finish")
        names.append("analytic_shadows_lanes" if self.lanes and not self.shape_tree else "analytic_shadows")
        if self.meshes:
            names.append("mesh_shadows" if self.packets else "mesh_shadows_single")
        names.append("accumulate")
        return tuple(names)


def _groups() -> tuple[tuple[int, ...], ...]:
    """Every plan's stages (:meth:`Plan.stages` over all values of its fields), then each stage alone (the tests run
    stages one at a time): the stage groups :func:`run_stage` compiles a loop for, one group at a time."""
    plans = {
        tuple(_IDS[name] for name in Plan(*values).stages())
        for values in itertools.product((False, True), repeat=len(fields(Plan)))
    }
    return tuple(sorted(plans)) + tuple((i,) for i in range(len(STAGES)))


GROUPS = _groups()
_GROUP_IDS = {group: i for i, group in enumerate(GROUPS)}


def group_id(stages: tuple[int, ...]) -> int:
    """The index in :data:`GROUPS` of the stage ids ``stages`` (a plan's, or one stage)."""
    try:
        return _GROUP_IDS[tuple(stages)]
    except KeyError:
        raise ValueError(f"no stage group runs the stages {stages}: a plan's stages or one stage") from None
