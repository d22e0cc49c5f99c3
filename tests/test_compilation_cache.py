"""Traced programs kept on disk (``compilation_cache.compile_program``): a second process
loads them instead of tracing, with the same results bit for bit; keys tell programs
of different code, settings or shapes apart."""

import dataclasses
import os
import subprocess
import sys
import textwrap

import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax import compilation_cache
from solar_jax.compilation_cache import compile_program
from solar_jax.env.batch import MultiEnv
from solar_jax.trainer import Trainer
from tests.tiny import CONFIG

# A program with the LAPACK custom calls MJX's solver makes (Cholesky, triangular
# solve), which crash a process that loads them unless LAPACK is prepared first.
PROGRAM = textwrap.dedent(
    """
    import sys
    import jax, jax.numpy as jnp, numpy as np
    from solar_jax.compilation_cache import compile_program, enable_compilation_cache

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
    monkeypatch.setattr(compilation_cache, "_programs", tmp_path)
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


def test_without_a_fingerprint_or_cache_nothing_is_kept(tmp_path, monkeypatch):
    monkeypatch.setattr(compilation_cache, "_programs", tmp_path)
    compile_program(lambda x: x + 1, (jnp.ones(2),))
    monkeypatch.setattr(compilation_cache, "_programs", None)
    compile_program(lambda x: x + 1, (jnp.ones(2),), fingerprint="a")
    assert not any(tmp_path.iterdir())


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
    assert fingerprint(config, MultiEnv(env.names, env.batch_size, solver)) != same
