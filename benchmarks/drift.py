"""How far MJX trajectories drift from MuJoCo C's, per robot and world layout.

    python -m benchmarks.drift robots=walker_7_main,hopper_5,humanoid_2d_9_full \
        robots_per_world=1,3 solver=4/8,20/20 [steps=100] [out=PATH.json]

Every robot starts from the same state (qpos0 + U(+-0.005), qvel U(+-0.005)) and gets
the same uniform random actions in MJX (float32, the given world layout and solver
settings) and in MuJoCo C (float64, the same solver settings), termination off. Prints
the max |qpos_MJX - qpos_C| within the first 10, 25, 50 and 100 env steps, and writes
JSON.
"""

import dataclasses
import json
import sys
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import solar_jax  # noqa: F401  (before jax: its settings for jaxlib's logs, XLA, MuJoCo)

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from benchmarks.options import parse_options
from solar_jax.config import EnvConfig
from solar_jax.env.physics import make_world_fns
from solar_jax.env.world import build_world
from solar_jax.morphology import load
from solar_jax.xla.options import jit_physics

RESULTS = Path(__file__).resolve().parent / "results"
HORIZONS = (10, 25, 50, 100)


def _mjx_states(morphs, per_world, config, init, actions):
    """``{robot: ([T, nq], [T, nv])}`` MJX trajectories, ``per_world`` robots per world."""
    n_max = max(m.num_agents for m in morphs)
    out = {}
    for start in range(0, len(morphs), per_world):
        idx = list(range(start, min(start + per_world, len(morphs))))
        world = build_world(tuple(morphs[i] for i in idx), n_max)
        fns = make_world_fns(world, config)
        step = jit_physics(fns.step)
        state = fns.reset(jax.random.key(0))
        qpos = np.concatenate([init[i][0] for i in idx])
        qvel = np.concatenate([init[i][1] for i in idx])
        data = state.data.replace(qpos=jnp.asarray(qpos, jnp.float32), qvel=jnp.asarray(qvel))
        state = state.replace(data=data)
        qpos_t, qvel_t = [], []
        for t in range(actions.shape[0]):
            state, _ = step(state, jnp.asarray(actions[t][idx]))
            qpos_t.append(np.asarray(state.data.qpos))
            qvel_t.append(np.asarray(state.data.qvel))
        qpos_t, qvel_t = np.stack(qpos_t), np.stack(qvel_t)
        for r, i in enumerate(idx):
            out[i] = (qpos_t[:, world.qpos_robot == r], qvel_t[:, world.dof_robot == r])
    return out


def _c_model(morph, config):
    model = mujoco.MjModel.from_xml_string(morph.xml)
    model.opt.iterations = config.solver_iterations
    model.opt.ls_iterations = config.ls_iterations
    return model


def _c_step(morph, model, data, action):
    data.ctrl[morph.actuators[1:]] = action[1 : morph.num_agents]
    for _ in range(morph.task.frame_skip):
        mujoco.mj_step(model, data)


def _c_qpos(morph, config, init, actions):
    """Open loop in C from the common start, ``[T, nq]``."""
    model = _c_model(morph, config)
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = init
    trajectory = []
    for action in actions:
        _c_step(morph, model, data, action)
        trajectory.append(data.qpos.copy())
    return np.stack(trajectory)


def _one_step_errors(morph, config, init, actions, qpos, qvel):
    """``[T]`` |qpos_MJX(t) - one C step from MJX's state at t - 1|: no accumulated chaos."""
    model = _c_model(morph, config)
    data = mujoco.MjData(model)
    errors = []
    for t, action in enumerate(actions):
        mujoco.mj_resetData(model, data)
        data.qpos[:], data.qvel[:] = init if t == 0 else (qpos[t - 1], qvel[t - 1])
        _c_step(morph, model, data, action)
        errors.append(np.abs(data.qpos - qpos[t]).max())
    return np.array(errors)


DEFAULTS = dict(
    robots="walker_7_main,hopper_5",
    robots_per_world="1",
    solver="4/8",  # iterations/line search, comma-separated settings
    steps="100",
    out=str(RESULTS / "drift_cpu.json"),
)


def main(argv: list[str] | None = None) -> list[dict]:
    o = parse_options(sys.argv[1:] if argv is None else argv, DEFAULTS, __doc__)
    robots, solvers = o["robots"].split(","), o["solver"].split(",")
    per_worlds = [int(k) for k in o["robots_per_world"].split(",")]
    steps, out = int(o["steps"]), Path(o["out"])

    morphs = []
    for name in robots:
        morph = load(name)
        morphs.append(
            dataclasses.replace(morph, task=dataclasses.replace(morph.task, terminates=False))
        )
    rng = np.random.default_rng(0)
    init = [
        (
            m.model.qpos0 + rng.uniform(-0.005, 0.005, m.model.nq),
            rng.uniform(-0.005, 0.005, m.model.nv),
        )
        for m in morphs
    ]
    n_max = max(m.num_agents for m in morphs)
    actions = rng.uniform(-1, 1, (steps, len(morphs), n_max)).astype(np.float32)
    horizons = [h for h in HORIZONS if h <= steps]
    rows = []
    print(
        f"{'robot':<22} {'per world':>9} {'solver':>7} {'one step':>9} "
        + " ".join(f"{'@' + str(h):>9}" for h in horizons)
    )
    for solver in solvers:
        iterations, line_search = (int(x) for x in solver.split("/"))
        config = EnvConfig(
            solver_iterations=iterations, ls_iterations=line_search, max_episode_steps=10**9
        )
        reference = [_c_qpos(m, config, init[i], actions[:, i]) for i, m in enumerate(morphs)]
        for per_world in per_worlds:
            ours = _mjx_states(morphs, per_world, config, init, actions)
            for i, m in enumerate(morphs):
                qpos, qvel = ours[i]
                error = np.abs(qpos - reference[i]).max(axis=1)
                one = _one_step_errors(m, config, init[i], actions[:, i], qpos, qvel).max()
                row = {"robot": m.name, "robots_per_world": per_world, "solver": solver}
                row["max_one_step_error"] = float(one)
                row.update({f"max_error_{h}": float(error[:h].max()) for h in horizons})
                rows.append(row)
                cells = " ".join(f"{row[f'max_error_{h}']:>9.1e}" for h in horizons)
                print(f"{m.name:<22} {per_world:>9} {solver:>7} {one:>9.1e} {cells}", flush=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"device": jax.devices()[0].device_kind, "rows": rows}, indent=2))
    print(f"wrote {out}")
    return rows


if __name__ == "__main__":
    main()
