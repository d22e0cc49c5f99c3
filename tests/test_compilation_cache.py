"""Traced programs kept on disk (``xla.programs.compile_program``): a second process
loads them instead of tracing, with the same results bit for bit; keys tell programs
of different code, settings or shapes apart."""

import dataclasses
import gc
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.env.batch import MultiEnv
from solar_jax.env.integrator import mjx
from solar_jax.training.trainer import Trainer
from solar_jax.xla import cache, options
from solar_jax.xla import programs as xla_programs
from solar_jax.xla.programs import compile_program, jit_init
from tests.tiny import CONFIG, ROBOT

# A program with the LAPACK custom calls MJX's solver makes (Cholesky, triangular
# solve), which crash a process that loads them unless LAPACK is prepared first.
PROGRAM = textwrap.dedent(
    """
    import sys
    import jax, jax.numpy as jnp, numpy as np
    from solar_jax.xla.cache import enable_compilation_cache
    from solar_jax.xla.programs import compile_program

    enable_compilation_cache()
    traced = []

    def solve(state, scale):
        traced.append(1)
        spd = state["a"] @ state["a"].T + jnp.eye(3)
        lower = jnp.linalg.cholesky(spd)
        x = jax.scipy.linalg.solve_triangular(lower, state["b"], lower=True)
        return {"a": state["a"] + 1, "b": x * scale}  # both can take a donated buffer

    state = {"a": jnp.arange(9.0).reshape(3, 3) / 7, "b": jnp.ones((3, 2))}
    program = compile_program(
        solve, (state, jnp.float32(2)), donate_argnums=(0,), fingerprint="test"
    )
    out = program(state, jnp.float32(2))
    assert state["a"].is_deleted() and state["b"].is_deleted(), "not donated"
    np.save(sys.argv[1], np.asarray(out["b"]))
    print("traced" if traced else "loaded")
    """
)


def test_a_second_process_loads_the_program_and_gets_the_same_bits(tmp_path):
    env = os.environ | {"SOLAR_JAX_CACHE": str(tmp_path / "cache")}
    runs = []
    for i in range(2):
        out = tmp_path / f"x{i}.npy"
        result = subprocess.run(
            [sys.executable, "-c", PROGRAM, str(out)],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert result.returncode == 0, result.stderr[-2000:]
        runs.append((result.stdout.split()[-1], np.load(out)))
    assert [how for how, _ in runs] == ["traced", "loaded"]
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    assert len(list((tmp_path / "cache" / "programs").iterdir())) == 1


def test_keys_part_programs_by_fingerprint_and_shapes_and_a_torn_file_is_traced_again(
    tmp_path, monkeypatch
):
    monkeypatch.setattr(cache, "programs_dir", tmp_path)
    traced = []

    def double(x):
        traced.append(x.shape)
        return 2 * x

    for fingerprint, shape in (("a", 3), ("a", 3), ("b", 3), ("a", 4)):
        program = compile_program(double, (jnp.ones(shape),), fingerprint=fingerprint)
        np.testing.assert_array_equal(program(jnp.ones(shape)), 2 * np.ones(shape))
    assert traced == [(3,), (3,), (4,)]  # the second ("a", 3) was loaded
    with pytest.raises(TypeError, match="another structure"):
        program({"x": jnp.ones(4)})
    files = sorted(tmp_path.iterdir())
    assert len(files) == 3
    for path in files:
        path.write_bytes(b"torn")
    program = compile_program(double, (jnp.ones(3),), fingerprint="a")
    np.testing.assert_array_equal(program(jnp.ones(3)), 2 * np.ones(3))
    assert len(traced) == 4  # traced again, and saved whole
    compile_program(double, (jnp.ones(3),), fingerprint="a")
    assert len(traced) == 4


def test_a_program_of_mjx_data_is_loaded_by_the_next_run(tmp_path, monkeypatch):
    # mjx.Data's static fields are NumPy arrays in wrappers printed at their address: a
    # program taking one must be found again from another Data of the same model (a
    # run's collection carries the worlds' data from round to round).
    monkeypatch.setattr(cache, "programs_dir", tmp_path)
    model = MultiEnv([str(ROBOT)], 1).worlds[0].model
    traced = []

    def height(data):
        traced.append(1)
        return data.qpos[1] + 1.0

    for _ in range(2):
        data = mjx.make_data(mjx.put_model(model))  # new wrappers, new addresses
        compile_program(height, (data,), fingerprint="a")(data)
    assert len(traced) == 1 and len(list(tmp_path.iterdir())) == 1


def test_without_a_fingerprint_or_cache_nothing_is_kept(tmp_path, monkeypatch):
    monkeypatch.setattr(cache, "programs_dir", tmp_path)
    compile_program(lambda x: x + 1, (jnp.ones(2),))
    monkeypatch.setattr(cache, "programs_dir", None)
    compile_program(lambda x: x + 1, (jnp.ones(2),), fingerprint="a")
    assert not any(tmp_path.iterdir())


def test_the_commands_trace_with_fewer_garbage_collections_cache_or_not(monkeypatch):
    monkeypatch.setattr(cache, "programs_dir", cache.programs_dir)
    monkeypatch.setenv("SOLAR_JAX_CACHE", "off")
    before = gc.get_threshold()
    try:
        gc.set_threshold(700, 10, 10)  # Python's defaults
        assert cache.enable_compilation_cache() is None
        assert gc.get_threshold() == cache.GC_THRESHOLDS != (700, 10, 10)
    finally:
        gc.set_threshold(*before)


def test_the_trainer_s_fingerprint_follows_what_its_programs_are_traced_from(tiny_trainer):
    env = tiny_trainer.env

    def fingerprint(config, env=env):
        return Trainer(config, env).fingerprint

    same = fingerprint(dataclasses.replace(CONFIG, seed=7, out="elsewhere", total_steps=9))
    assert same == tiny_trainer.fingerprint  # bookkeeping keys
    td3 = dataclasses.replace(CONFIG.td3, batch_size=CONFIG.td3.batch_size + 1)
    assert fingerprint(dataclasses.replace(CONFIG, td3=td3)) != same
    solver = dataclasses.replace(CONFIG.env, solver_iterations=CONFIG.env.solver_iterations + 1)
    config = dataclasses.replace(CONFIG, env=solver)
    assert fingerprint(config, MultiEnv(env.morphs, env.batch_size, solver)) != same


def _hoisted(program) -> bool:
    """Whether XLA moved the loop's invariant ``sin(c)`` out of the loop (``_invariant``)."""
    entry = program.as_text().split("\nENTRY ")[1]
    return "sine" in entry


def _invariant(c, x):
    return jax.lax.fori_loop(0, 10, lambda i, x: x + jnp.sin(c) * x, x)


@pytest.mark.parametrize("kept", [False, True], ids=["direct", "exported"])
def test_the_physics_options_reach_xla_traced_or_exported(kept, tmp_path, monkeypatch):
    monkeypatch.setattr(cache, "programs_dir", tmp_path if kept else None)
    args = (jnp.ones(8), jnp.ones(8))
    plain = compile_program(_invariant, args, fingerprint="a")
    physics = options.physics_compiler_options()
    skipping = compile_program(_invariant, args, fingerprint="a", compiler_options=physics)
    assert _hoisted(plain) and not _hoisted(skipping)  # loop-invariant code motion skipped
    np.testing.assert_array_equal(plain(*args), skipping(*args))
    assert len(list(tmp_path.iterdir())) == (1 if kept else 0)  # one program, two options


def test_the_physics_options_keep_the_passes_xla_flags_disable(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", "--xla_foo=1 --xla_disable_hlo_passes=a,b")
    passes = options.physics_compiler_options()["xla_disable_hlo_passes"]
    assert passes.split(",") == ["a", "b", *options.PHYSICS_SKIPPED_PASSES]


def test_programs_compiled_together_come_back_in_order():
    jobs = [(lambda x, k=k: x + k, (jnp.zeros(2),), {}) for k in range(3)]
    programs = xla_programs.compile_programs(jobs)
    assert [float(p(jnp.zeros(2))[0]) for p in programs] == [0.0, 1.0, 2.0]


def test_jit_init_runs_alone_with_plain_jit_bits_and_inside_a_trace():
    def draw(key):
        return jax.random.uniform(key, (5, 3), minval=-0.1, maxval=0.1) * 3.0 + 1.0

    key, init = jax.random.key(0), jit_init(draw)
    np.testing.assert_array_equal(init(key), jax.jit(draw)(key))
    # Inside another trace (a run's state by ``jax.eval_shape``): no compiler options.
    assert jax.eval_shape(lambda: init(jax.random.key(1))).shape == (5, 3)
    np.testing.assert_array_equal(jax.jit(init)(key), init(key))


def test_a_start_program_with_a_fingerprint_is_loaded_with_the_same_bits(tmp_path, monkeypatch):
    monkeypatch.setattr(cache, "programs_dir", tmp_path)
    traced = []

    def draw(key):
        traced.append(1)
        return {"w": jax.random.normal(key, (4, 3)), "b": jnp.zeros(3)}

    key = jax.random.PRNGKey(0)
    first = jit_init(draw, "a")(key)
    again = jit_init(draw, "a")  # a new process's: loaded from disk, not traced
    np.testing.assert_array_equal(again(key)["w"], first["w"])
    assert len(traced) == 1 and len(list(tmp_path.iterdir())) == 1
    np.testing.assert_array_equal(first["w"], jax.jit(draw)(key)["w"])  # plain jit's bits
    assert jax.eval_shape(lambda: again(key))["w"].shape == (4, 3)  # inside a trace: plain jit
