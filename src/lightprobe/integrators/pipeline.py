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
one worker per thread.  The loop reaches each body through the address of its compiled entry, so it is compiled
once for every stage and every plan (the records' types are the same for every scene), and a render compiles the
bodies its plan runs and no others; a body compiles once for every plan that runs it (decisions.md 77, 104, 129).
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass

from llvmlite import ir
from numba import njit, typeof, types
from numba.extending import intrinsic

from .._numba import FASTMATH
from .._worksharing import COUNTER_TYPE, claim_range, new_counter, on_workers
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
    "PATTERNS",
    "RECORDS",
    "STAGES",
    "Launcher",
    "Plan",
    "Stage",
    "body_address",
    "body_parameters",
    "body_signature",
    "call_body",
    "compiled",
    "entry_address",
    "loop_signature",
    "record_types",
    "run_stage",
    "stage_id",
    "stage_loop_source",
]

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


#: the stage bodies' distinct parameter lists (:func:`body_parameters`), in the order of :data:`STAGES`: the stage
#: loop has one call site per list, each calling a body through its address with those records
PATTERNS: tuple[tuple[str, ...], ...] = tuple(dict.fromkeys(stage.parameters for stage in STAGES))
_PATTERN_OF = tuple(PATTERNS.index(stage.parameters) for stage in STAGES)


@intrinsic
def call_body(typingctx, address, arguments):
    """Call the compiled stage body whose C entry (Numba's cfunc wrapper, :func:`body_address`) is at ``address``
    with the values of the tuple ``arguments``, which are the body's arguments, in its order and of its types.  A
    call through an address: the loop is compiled without the bodies and links none of their code (a body called
    directly was compiled into the loop again, machine code and all: decisions.md 129)."""
    if not isinstance(address, types.Integer) or not isinstance(arguments, types.BaseTuple):
        return None

    def codegen(context, builder, signature, args):
        argument_types = signature.args[1].types
        entry_type = ir.FunctionType(
            context.get_value_type(types.none), [context.get_value_type(t) for t in argument_types]
        )
        entry = builder.inttoptr(args[0], entry_type.as_pointer())
        builder.call(entry, [builder.extract_value(args[1], i) for i in range(len(argument_types))])
        return context.get_dummy_value()

    return types.none(address, arguments), codegen


def stage_loop_source() -> str:
    """The Python source of :func:`run_stage`: claim chunks of the ``n`` items from the shared counter and call the
    body at ``body`` on each, with the records its parameter list (``PATTERNS[pattern]``) names.  One call site per
    parameter list, so that each call lists what the body reads: a reader finds a stage's data in its signature."""
    lines = [
        "def run_stage(pattern, body, n, s, env, lights, sel, c, cams, slots, acc, counter, worker):",
        "    lo, hi = claim_range(counter, n)",
        "    while lo < hi:",
    ]
    for i, parameters in enumerate(PATTERNS):
        users = ", ".join(stage.name for stage in STAGES if stage.parameters == parameters)
        lines += [
            f"        {'if' if i == 0 else 'elif'} pattern == {i}:  # {users}",
            f"            call_body(body, ({', '.join(parameters)}))",
        ]
    lines.append("        lo, hi = claim_range(counter, n)")
    return "\n".join(lines) + "\n"


def _compile_stage_loop():
    """:func:`run_stage`, from :func:`stage_loop_source`, compiled and cached as a function of this module (its
    code carries this file's name, so that Numba's cache finds the source it stamps)."""
    namespace = {"__name__": __name__, "claim_range": claim_range, "call_body": call_body}
    exec(compile(stage_loop_source(), __file__, "exec"), namespace)
    loop = namespace["run_stage"]
    loop.__doc__ = """Worker ``worker``'s share of a stage: chunks of its ``n`` items claimed from ``counter`` until
    none is left, each given to the stage's body at address ``body`` (:func:`body_address`), whose parameter list is
    ``PATTERNS[pattern]``.  One compiled loop for every stage and every plan: the pass records have the same types
    whatever the scene (``pass_state.py``), and the bodies are reached through their addresses, so the loop is
    compiled once per machine and a render compiles only the bodies its plan runs (decisions.md 104, 129)."""
    return jit_stage_loop(loop)


run_stage = _compile_stage_loop()
ADDRESS = types.int64  # a body's address, as the loop receives it


def loop_signature(record_types: tuple) -> tuple:
    """The argument types of :func:`run_stage` for pass records of types ``record_types``."""
    return (types.int64, ADDRESS, types.int64, *record_types, COUNTER_TYPE, types.int64)


def compiled(function, signature: tuple):
    """``function``'s compiled version for ``signature``: loaded from the kernel cache, or compiled."""
    result = function.overloads.get(signature)
    if result is None:
        function.compile(signature)
        result = function.overloads[signature]
    return result


def body_signature(record_types: tuple, parameters: tuple[str, ...]) -> tuple:
    """The argument types of a stage body whose parameters are ``parameters`` (:func:`body_parameters`: some of the
    pass records, then worker, lo, hi), from the types of the pass's records (s, env, lights, sel, c, cams, slots,
    acc)."""
    by_name = dict(zip(RECORDS, record_types, strict=True)) | dict.fromkeys(CLAIM, types.int64)
    return tuple(by_name[name] for name in parameters)


def body_address(stage: int, record_types: tuple) -> int:
    """The address of stage ``stage``'s body's C entry, compiled (or loaded from the cache) for pass records of
    types ``record_types``; the body's compiled code stays alive with its dispatcher."""
    body = STAGES[stage]
    return entry_address(compiled(body.body, body_signature(record_types, body.parameters)))


def entry_address(result) -> int:
    """The address of a compiled function's C entry (``result``: one of its dispatcher's ``overloads``); a
    RuntimeError naming it where it was compiled without one, rather than a call through address 0."""
    address = result.library.get_pointer_to_function(result.fndesc.llvm_cfunc_wrapper_name)
    if not address:
        raise RuntimeError(f"{result.fndesc.qualname} was compiled without a C entry (Numba's no_cfunc_wrapper)")
    return address


def record_types(records: tuple) -> tuple:
    """The Numba types of a pass's records (the same for every scene and pass: ``pass_state.py``)."""
    return tuple(typeof(x) for x in records)


class Launcher:
    """Runs the stages of a pass with ``threads`` workers: the calling thread is worker 0, a shared pool's threads
    the others (``_worksharing.on_workers``, which waits for every worker after an error or a Ctrl-C).  Each worker
    runs :func:`run_stage`, which releases the GIL, so the workers run in parallel; which worker takes which chunk
    changes nothing in the image (every item of a stage is independent, and a worker's scratch rows are its own).
    Measured against Numba's parallel loops, decisions.md 77."""

    def __init__(self, threads: int):
        self.threads = threads
        self.counter = new_counter()  # the chunk claims' shared counter (_worksharing.py)
        self._loop = None  # run_stage's compiled entry (later calls skip the dispatcher's typing of ~150 arrays)
        self._bodies: dict[int, int] = {}  # stage id -> its body's address

    def prepare(self, stages: tuple[int, ...], records: tuple, helpers=None) -> None:
        """Compile (or load) the loop and the bodies of ``stages`` (ids) for pass records like ``records`` before
        the first pass runs them.  With ``helpers`` (``precompile.Helpers``: processes compiling bodies into the
        cache beside this one), this process compiles, in the plan's order, the bodies it claims first, then loads
        the others once their helper has saved them."""
        types_of = record_types(records)
        if self._loop is None:
            self._loop = compiled(run_stage, loop_signature(types_of)).entry_point
        theirs = []
        for stage in stages:
            if stage in self._bodies:
                continue
            if helpers is None or helpers.claim(STAGES[stage].name):
                self._bodies[stage] = body_address(stage, types_of)
            else:
                theirs.append(stage)
        for stage in theirs:
            helpers.wait_for(STAGES[stage].name)
            self._bodies[stage] = body_address(stage, types_of)

    def run(self, stage: int, records: tuple) -> None:
        """Stage ``stage`` (an id) over the pass whose ``records`` are (s, env, lights, sel, c, cams, slots, acc)."""
        if stage not in self._bodies:
            self.prepare((stage,), records)
        n = STAGES[stage].items(*records[4:7])
        self.counter[0] = 0
        call, pattern, body, counter = self._loop, _PATTERN_OF[stage], self._bodies[stage], self.counter
        on_workers(lambda w: call(pattern, body, n, *records, counter, w), self.threads)


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
