"""One morphology's locomotion task, unpadded: ``reset(key)`` and ``step(state, action)``.

A thin view of a one-robot world (``solar_jax.env.physics``): observations are
``[N, 19]``, actions ``[N - 1]`` (one per actuator, in actuator = body pre-order).
The interface mirrors brax's ``Env``/``State`` (pure functions, the state carries
obs, reward and done) without depending on brax: its training agents do not run on
the pinned jax, and the padded multi-morphology batch is ours anyway.
"""

import dataclasses

import jax
import jax.numpy as jnp
from flax import struct

from solar_jax.config import EnvConfig
from solar_jax.env.physics import WorldState, make_world_fns
from solar_jax.env.world import build_world
from solar_jax.morphology import Morphology, load


@struct.dataclass
class EnvState:
    world: WorldState
    obs: jnp.ndarray  # [N, 19] observation of the current state (after any auto-reset)
    reward: jnp.ndarray  # [] reward of the last step
    terminated: jnp.ndarray  # [] bool
    truncated: jnp.ndarray  # [] bool
    final_obs: jnp.ndarray  # [N, 19] true observation after the last step (before reset)

    @property
    def done(self) -> jnp.ndarray:
        return self.terminated | self.truncated

    @property
    def qpos(self) -> jnp.ndarray:
        return self.world.data.qpos

    @property
    def qvel(self) -> jnp.ndarray:
        return self.world.data.qvel


@dataclasses.dataclass(frozen=True, eq=False)
class Env:
    morph: Morphology
    config: EnvConfig
    reset: callable  # (key) -> EnvState
    step: callable  # (EnvState, action [N - 1]) -> EnvState

    @property
    def num_agents(self) -> int:
        return self.morph.num_agents

    @property
    def action_size(self) -> int:
        return self.morph.num_actuators


def make_env(morph: Morphology | str, config: EnvConfig | None = None) -> Env:
    """The task of one robot (a registered name, an MJCF path or a ``Morphology``)."""
    morph = load(morph) if isinstance(morph, str) else morph
    config = config or EnvConfig()
    n = morph.num_agents
    fns = make_world_fns(build_world((morph,), n), config)

    def reset(key: jnp.ndarray) -> EnvState:
        world = fns.reset(key)
        zero = jnp.zeros((), jnp.float32)
        return EnvState(world, world.obs[0], zero, zero > 0, zero > 0, world.obs[0])

    def step(state: EnvState, action: jnp.ndarray) -> EnvState:
        padded = jnp.concatenate([jnp.zeros((1,), action.dtype), action])[None]  # [1, N]
        world, out = fns.step(state.world, padded)
        return EnvState(
            world=world,
            obs=world.obs[0],
            reward=out.reward[0],
            terminated=out.terminated[0] | out.nonfinite[0],
            truncated=out.truncated[0],
            final_obs=out.next_obs[0],
        )

    return Env(morph=morph, config=config, reset=reset, step=step)


def random_rollout(env: Env, steps: int, seed: int) -> dict[str, jnp.ndarray]:
    """Uniform random actions for ``steps`` steps, deterministic for ``seed``.

    Returns per step (leading axis ``steps``): qpos and qvel after the step, the
    unpadded observation the action was taken from, action, reward, terminated,
    truncated. Episodes auto-reset.
    """
    key_reset, key_actions = jax.random.split(jax.random.key(seed))
    actions = jax.random.uniform(key_actions, (steps, env.action_size), minval=-1.0, maxval=1.0)

    def body(state, action):
        new = env.step(state, action)
        record = dict(
            qpos=new.qpos,
            qvel=new.qvel,
            obs=state.obs,
            action=action,
            reward=new.reward,
            terminated=new.terminated,
            truncated=new.truncated,
        )
        return new, record

    _, trajectory = jax.lax.scan(body, env.reset(key_reset), actions)
    return trajectory
