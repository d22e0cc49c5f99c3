"""Compiled work kept on disk for the command-line entry points.

MJX steps take 20-40 s to compile per world on a CPU host (benchmarks/README.md); with
the cache, a second run of the same suite and settings loads them from disk.
``SOLAR_JAX_CACHE`` sets the folder; ``SOLAR_JAX_CACHE=off`` disables it. It holds:

- JAX's persistent compilation cache (XLA executables, keyed by the lowered program);
- ``programs/``: the traced and lowered programs themselves (``jax.export``'s StableHLO
  bytes, their output structure as JSON: reading one runs no code from the file),
  keyed by what they are traced from (``program_fingerprint``), so that a warm start
  skips tracing and lowering, which is most of it once XLA's part is cached;
- ``compile_times.json``: how long each program took to compile here, so a run's
  progress line can say what to expect.

``enable_compilation_cache``, which every command calls first, also sets the garbage
collector's thresholds for tracing (``GC_THRESHOLDS``): the one process-wide setting
of a command that compiles, beside the cache's.
"""

import functools
import gc
import hashlib
import json
import os
import re
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from importlib import metadata
from pathlib import Path

import jax
import jax.numpy as jnp
from jax import export

from solar_jax.files import write_atomic

DEFAULT_DIR = Path.home() / ".cache" / "solar_jax" / "xla"
PROGRAMS_DIR = "programs"
PROGRAM_FORMAT = 2  # raise when what a program file holds changes
_programs: Path | None = None  # the programs folder, once the cache is enabled


# Python's cyclic garbage collector while JAX traces: at its default thresholds (700, 10,
# 10) it runs a young collection every 700 new objects, and tracing makes millions (every
# tracer, equation and avals tuple). At these, humanoid++'s episodes program (paper sizes)
# traced and lowered in 21.9-23.4 s against 26.4-29.2, its update in 6.3-6.7 against
# 7.9-8.0 (two processes each, in turn); the tiny test run's in 3.7 against 4.6 and 2.4
# against 3.0 (the test suite, whose workers hold large heaps, gained nothing measurable).
# Unreachable cycles are still collected, in larger batches.
GC_THRESHOLDS = (50_000, 20, 100)


def enable_compilation_cache() -> Path | None:
    """Points JAX's persistent cache at ``$SOLAR_JAX_CACHE`` (default ``DEFAULT_DIR``) and
    keeps traced programs in its ``programs/`` (``compile_program``). The commands call it
    first, so it also sets the garbage collector's thresholds for tracing
    (``GC_THRESHOLDS``), cache or not."""
    global _programs
    gc.set_threshold(*GC_THRESHOLDS)
    setting = os.environ.get("SOLAR_JAX_CACHE", str(DEFAULT_DIR))
    if setting.lower() in ("off", "0", "none", ""):
        _programs = None
        return None
    path = Path(setting).expanduser()
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".write-test-{os.getpid()}"
        probe.touch()
        probe.unlink()
    except OSError as err:  # read-only, or a file in the way: run without it
        print(
            f"warning: SOLAR_JAX_CACHE={path}: cannot write there ({err.strerror or err}); "
            "running without the compilation cache",
            file=sys.stderr,
        )
        _programs = None
        return None
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    _programs = path / PROGRAMS_DIR
    return path


_VERSIONED = ("jax", "jaxlib", "mujoco", "mujoco-mjx", "flax", "optax", "numpy")


def _source_digest() -> str:
    """Every Python file of the ``solar_jax`` package, hashed (what traced code reads)."""
    package = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        digest.update(str(path.relative_to(package)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def program_fingerprint(*parts: bytes | str) -> str:
    """A key for programs traced from ``parts`` (e.g. the config less its bookkeeping keys,
    the MuJoCo models) by this package's source, under these library versions and this
    backend. Anything a traced function reads must be in one of these."""
    digest = hashlib.sha256()
    versions = [(name, metadata.version(name)) for name in _VERSIONED]
    device = jax.devices()[0]
    tracing = [jax.config.jax_enable_x64, jax.config.jax_default_matmul_precision]
    header = [PROGRAM_FORMAT, sys.version, versions, device.platform, device.device_kind, tracing]
    for part in (json.dumps(header), _source_digest(), *parts):
        digest.update(part if isinstance(part, bytes) else part.encode())
        digest.update(b"\0")
    return digest.hexdigest()


# XLA passes the physics program compiles without (``physics_compiler_options``): on a CPU,
# loop-invariant code motion and constant sinking over MJX's nested while loops take about
# a third of its compile time, and its steps run no slower without them (docs/design.md).
# Not measured on accelerators, where they stay on. XLA's older CPU fusion emitters compile
# one world faster but a suite's joint program slower, so the package keeps the new ones;
# the tests, whose programs are small, use the old (``tests/unoptimised.py``).
PHYSICS_SKIPPED_PASSES = ("while-loop-invariant-code-motion", "while-loop-constant-sinking")


def physics_compiler_options() -> dict[str, str]:
    """XLA options for programs with the physics: on a CPU, the passes ``XLA_FLAGS``
    disables (the option replaces that list) plus ``PHYSICS_SKIPPED_PASSES``."""
    if jax.default_backend() != "cpu":
        return {}
    flags = re.findall(r"--xla_disable_hlo_passes=(\S+)", os.environ.get("XLA_FLAGS", ""))
    disabled = [p for flag in flags for p in flag.split(",") if p]
    passes = dict.fromkeys([*disabled, *PHYSICS_SKIPPED_PASSES])  # ordered, no repeats
    return {"xla_disable_hlo_passes": ",".join(passes)}


def jit_physics(fn: Callable, **jit_options) -> Callable:
    """``jax.jit(fn, **jit_options)`` for a function that steps the physics, compiled with
    ``physics_compiler_options`` (also through ``.lower(...).compile()``)."""
    return jax.jit(fn, compiler_options=physics_compiler_options(), **jit_options)


# The networks' initialisation (threefry draws for every parameter, run once per run)
# compiled at LLVM's -O1 on a CPU: 1.1-2.5 s against 3.2-4.6 s at the default level,
# with the same bits (measured for SOLAR tiny, small and default, Amorpheus and the
# monolithic MLP); -O0 would change the bits.
INIT_COMPILER_OPTIONS = {"xla_backend_optimization_level": 1}


def jit_start(
    fn: Callable, fingerprint: str = "", compiler_options: dict[str, str] | None = None
) -> Callable:
    """``jax.jit(fn)`` for a program a run calls once at its start (an initialisation, the
    first clustering). Called as a program of its own, it is compiled with
    ``compiler_options`` and, given a ``fingerprint`` of what ``fn`` reads and the cache
    enabled, through ``compile_program``: a warm start loads it instead of tracing it
    (the tests' tiny trainer's ``init``, both programs in XLA's cache: 1.0-1.1 s against
    1.8-2.0 s traced, three processes each). Traced inside another function
    (``jax.eval_shape`` of a run's state: its tracer arguments say so), it is a plain
    ``jax.jit``: JAX takes compiler options at the top level only."""
    top_level, nested = jax.jit(fn, compiler_options=compiler_options), jax.jit(fn)
    compiled = {}  # the arguments' structure and shapes -> program (``compile_program``)

    def start(*args):
        leaves, tree = jax.tree.flatten(args)
        if any(isinstance(leaf, jax.core.Tracer) for leaf in leaves):
            return nested(*args)
        if _programs is None or not fingerprint:
            return top_level(*args)
        shapes = (tree, tuple((jnp.shape(x), jnp.result_type(x)) for x in leaves))
        if shapes not in compiled:
            compiled[shapes] = compile_program(
                fn, args, fingerprint=fingerprint, compiler_options=compiler_options
            )
        return compiled[shapes](*args)

    return start


def jit_init(fn: Callable, fingerprint: str = "") -> Callable:
    """``jit_start`` for a parameter initialisation: ``INIT_COMPILER_OPTIONS`` on a CPU."""
    options = INIT_COMPILER_OPTIONS if jax.default_backend() == "cpu" else None
    return jit_start(fn, fingerprint, options)


def compile_programs(
    jobs: Sequence[tuple[Callable, tuple, dict]], timings: list[dict] | None = None
) -> list[Callable]:
    """``compile_program(fn, args, **options)`` for each job; results in the order of
    ``jobs``. Each is traced (or loaded) and lowered here, in that order, and XLA compiles
    it in a thread of its own beside the next one's tracing and the other compiles: XLA
    compiles a module on about one core and releases Python's lock, whereas two programs
    traced in two threads at once take turns on it (the first job, the physics, would
    wait for the update's tracing). ``timings``, if given, gets one record per job: its
    name, the seconds it took to trace (or load) and lower, and its XLA compile's
    seconds and when that ended (from this call's start)."""
    start = time.perf_counter()

    def compiled_timed(lowered, options, record):
        began = time.perf_counter()
        compiled = lowered.compile(options)
        record |= dict(compile_s=time.perf_counter() - began, done_s=time.perf_counter() - start)
        return compiled

    with ThreadPoolExecutor(max_workers=max(len(jobs), 1)) as pool:
        pending = []
        for fn, args, options in jobs:
            options = dict(options)
            compiler_options = options.pop("compiler_options", None)
            began = time.perf_counter()
            lowered, wrap = _lower_program(fn, args, **options)
            record = dict(
                name=getattr(fn, "__name__", "program"), lower_s=time.perf_counter() - began
            )
            if timings is not None:
                timings.append(record)
            pending.append((pool.submit(compiled_timed, lowered, compiler_options, record), wrap))
        return [wrap(future.result()) for future, wrap in pending]


def compile_program(
    fn: Callable,
    args: tuple,
    *,
    donate_argnums: tuple[int, ...] = (),
    fingerprint: str = "",
    compiler_options: dict[str, str] | None = None,
) -> Callable:
    """``jax.jit(fn, donate_argnums=...).lower(*args).compile(compiler_options)`` (``args``:
    arrays or ``jax.ShapeDtypeStruct``), through the ``programs/`` cache when the cache is enabled
    and a ``fingerprint`` of what ``fn`` reads is given: the program is traced and
    lowered once, exported (``jax.export``) and saved; a later process with the same
    fingerprint and argument shapes loads it instead of tracing (``fn`` does not run, so
    a trace counter in it stays put). Traced or loaded, the program is compiled from
    the same exported module, so a run and its resumption in a new process compute the
    same bits. Programs over several devices are not cached (an export fixes its device
    count)."""
    lowered, wrap = _lower_program(fn, args, donate_argnums, fingerprint)
    return wrap(lowered.compile(compiler_options))


def _lower_program(
    fn: Callable, args: tuple, donate_argnums: tuple[int, ...] = (), fingerprint: str = ""
) -> tuple[jax.stages.Lowered, Callable]:
    """``compile_program`` up to XLA: the program traced (or loaded) and lowered, and the
    function that makes its compiled executable the callable to return."""
    arg_leaves, in_tree = jax.tree.flatten(args)
    shardings = [getattr(x, "sharding", None) for x in arg_leaves]
    sharded = any(s is not None and len(s.device_set) > 1 for s in shardings)
    if _programs is None or not fingerprint or sharded:
        return jax.jit(fn, donate_argnums=donate_argnums).lower(*args), lambda compiled: compiled
    leaves = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in arg_leaves]
    # Static leaves print as objects at an address (MJX's wrapped NumPy fields of
    # ``mjx.Data``): their values are the models', which the fingerprint holds.
    structure = re.sub(r" at 0x[0-9a-f]+", "", str(in_tree))
    shapes = repr((structure, [(x.shape, str(x.dtype)) for x in leaves]))
    name = hashlib.sha256(f"{fingerprint}|{shapes}".encode()).hexdigest()[:32]
    path = _programs / f"{getattr(fn, '__name__', 'program').strip('_')}-{name}{PROGRAM_SUFFIX}"
    donated = _donated_leaves(args, donate_argnums)
    saved = _load(path, in_tree)
    if saved is None:
        out_trees = []

        def flat(*leaves):  # export serialises flat arguments only (no custom pytrees)
            out_leaves, out_tree = jax.tree.flatten(fn(*jax.tree.unflatten(in_tree, leaves)))
            out_trees.append(out_tree)
            return out_leaves

        exported = export.export(jax.jit(flat, donate_argnums=donated))(*leaves)
        saved = exported, out_trees[0]
        _save(path, exported.serialize(), out_trees[0], in_tree)
    exported, out_tree = saved
    _prepare_linear_algebra()
    lowered = jax.jit(exported.call, donate_argnums=donated).lower(*leaves)

    def wrap(compiled):
        def call(*call_args):
            call_leaves, tree = jax.tree.flatten(call_args)
            if tree != in_tree:  # the leaves alone could line up by accident
                raise TypeError(f"{path.name}: called with another structure than compiled for")
            return jax.tree.unflatten(out_tree, compiled(*call_leaves))

        call.as_text = compiled.as_text  # the optimised HLO, as a ``Compiled``'s
        return call

    return lowered, wrap


@functools.cache
def _prepare_linear_algebra() -> None:
    """Lowers a Cholesky factorisation and a triangular solve once. MJX's constraint
    solver calls LAPACK through custom calls, and JAX loads LAPACK's functions when it
    first lowers one; a program loaded from disk is never lowered from JAX operations,
    and without this it crashes the process (segmentation fault) on its first run."""
    matrix = jax.ShapeDtypeStruct((2, 2), jnp.float32)

    def factor_and_solve(a):
        lower = jnp.linalg.cholesky(a)
        return jax.scipy.linalg.solve_triangular(lower, a, lower=True)

    jax.jit(factor_and_solve).lower(matrix)


def _donated_leaves(args: tuple, donate_argnums: tuple[int, ...]) -> tuple[int, ...]:
    """The flat leaf positions of the donated arguments."""
    positions, start = [], 0
    for i, arg in enumerate(args):
        count = len(jax.tree.leaves(arg))
        if i in donate_argnums:
            positions.extend(range(start, start + count))
        start += count
    return tuple(positions)


PROGRAM_SUFFIX = ".program"
_MAGIC = b"solar_jax program\n"


def _load(path: Path, in_tree) -> tuple | None:
    """(exported program, output pytree structure) saved at ``path`` for arguments of
    structure ``in_tree``, or None (none yet, or unreadable: then it is traced again and
    overwritten). Reading runs no code from the file: the program is ``jax.export``'s
    serialised module, its output structure JSON (``tree_from_json``)."""
    try:
        data = path.read_bytes()
        if not data.startswith(_MAGIC):
            return None
        size = int.from_bytes(data[len(_MAGIC) : len(_MAGIC) + 8], "little")
        start = len(_MAGIC) + 8
        out_tree = tree_from_json(json.loads(data[start : start + size]), in_tree)
        return export.deserialize(bytearray(data[start + size :])), out_tree
    except Exception:  # missing, torn or from an incompatible version: trace again
        return None


def _save(path: Path, blob: bytearray, out_tree, in_tree) -> None:
    """Writes a program for ``_load``; one whose output structure JSON cannot hold
    (``tree_to_json``) or a cache that cannot be written keeps nothing (it is traced
    again next time)."""
    try:
        header = json.dumps(tree_to_json(out_tree, in_tree)).encode()
    except ValueError:
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, _MAGIC + len(header).to_bytes(8, "little") + header + bytes(blob))
    except OSError:
        return


def _subtrees(tree, path: tuple = ()):
    """(path of child indices, subtree) of every node of a ``PyTreeDef``, root first."""
    yield path, tree
    for i, child in enumerate(tree.children()):
        yield from _subtrees(child, (*path, i))


def _type_name(kind: type) -> str:
    return f"{kind.__module__}:{kind.__qualname__}"


_BUILTIN_NODES = {_type_name(k): k for k in (tuple, list, dict, type(None))}


def tree_to_json(tree, in_tree) -> object:
    """A program's output structure as JSON, relative to its arguments' ``in_tree``: a
    subtree found in ``in_tree`` as its path there (``{"in": [...]}``: MJX's data, whose
    node data holds arrays), a leaf as ``"*"``, any other node as its type's name, its
    node data (None, or a list of strings and numbers) and its children. ``ValueError``
    when a node is none of these."""
    known = {}
    for path, subtree in _subtrees(in_tree):
        known.setdefault(subtree, path)

    def encode(node):
        if node in known and node.num_nodes > 1:
            return {"in": list(known[node])}
        data = node.node_data()
        if data is None:
            return "*"
        kind, aux = data
        if aux is not None and not (
            isinstance(aux, list | tuple)
            and all(isinstance(a, str | int | float | bool) for a in aux)
        ):
            raise ValueError(f"node data of {kind.__name__} is not JSON")
        return {
            "type": _type_name(kind),
            "aux": aux if aux is None else {type(aux).__name__: list(aux)},
            "children": [encode(child) for child in node.children()],
        }

    return encode(tree)


def tree_from_json(data, in_tree):
    """The ``PyTreeDef`` of ``tree_to_json``'s ``data``: its node types are builtins or
    types of ``in_tree`` (looked up there, nothing imported)."""
    leaf = jax.tree.structure(0)
    subtrees = dict(_subtrees(in_tree))
    types = dict(_BUILTIN_NODES)
    for subtree in subtrees.values():
        if subtree.node_data() is not None:
            types.setdefault(_type_name(subtree.node_data()[0]), subtree.node_data()[0])
    wrappers = {"list": list, "tuple": tuple}

    def decode(item):
        if item == "*":
            return leaf
        if "in" in item:
            return subtrees[tuple(item["in"])]
        ((wrapper, values),) = item["aux"].items() if item["aux"] is not None else ((None, None),)
        aux = None if wrapper is None else wrappers[wrapper](values)
        children = [decode(child) for child in item["children"]]
        registry = jax.tree_util.default_registry
        return jax.tree_util.PyTreeDef.from_node_data_and_children(
            registry, (types[item["type"]], aux), children
        )

    return decode(data)


TIMES_FILE = "compile_times.json"  # beside the cache's entries: {program key: seconds}


def _times_path() -> Path | None:
    setting = os.environ.get("SOLAR_JAX_CACHE", str(DEFAULT_DIR))
    if setting.lower() in ("off", "0", "none", ""):
        return None
    return Path(setting).expanduser() / TIMES_FILE


def _read_times(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):  # none yet, or a torn write: no history
        return {}


def last_compile_time(key: str) -> float | None:
    """Seconds the last compilation of ``key`` took on this machine (None: never seen, or
    the cache is off)."""
    path = _times_path()
    return None if path is None else _read_times(path).get(key)


def save_compile_time(key: str, seconds: float) -> None:
    """Remembers how long compiling ``key`` took, for the next run's progress line."""
    path = _times_path()
    if path is None:
        return
    times = _read_times(path) | {key: round(seconds, 1)}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, json.dumps(times, indent=1, sort_keys=True).encode())
    except OSError:  # a read-only or full cache: the next run just does not know
        pass
