"""Traced programs kept on disk, and programs compiled side by side.

A program is traced and lowered once, exported (``jax.export``: StableHLO bytes, its
output structure as JSON, so reading one runs no code from the file) and saved under the
cache's ``programs/``, keyed by a fingerprint of what it is traced from
(``cache.program_fingerprint``) and its arguments' shapes; a later process loads it
instead of tracing, which is most of a warm start once XLA's part is cached.
"""

import functools
import hashlib
import json
import re
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import jax
import jax.numpy as jnp
from jax import export

from solar_jax.files import write_atomic
from solar_jax.xla import cache
from solar_jax.xla.options import INIT_COMPILER_OPTIONS


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
        if cache.programs_dir is None or not fingerprint:
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
    if cache.programs_dir is None or not fingerprint or sharded:
        return jax.jit(fn, donate_argnums=donate_argnums).lower(*args), lambda compiled: compiled
    leaves = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in arg_leaves]
    # Static leaves print as objects at an address (MJX's wrapped NumPy fields of
    # ``mjx.Data``): their values are the models', which the fingerprint holds.
    structure = re.sub(r" at 0x[0-9a-f]+", "", str(in_tree))
    shapes = repr((structure, [(x.shape, str(x.dtype)) for x in leaves]))
    name = hashlib.sha256(f"{fingerprint}|{shapes}".encode()).hexdigest()[:32]
    label = getattr(fn, "__name__", "program").strip("_")
    path = cache.programs_dir / f"{label}-{name}{PROGRAM_SUFFIX}"
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
