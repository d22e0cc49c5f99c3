"""Any single morphology as a brax environment: ``BraxEnv("hopper_3")``.

Needs the ``brax`` extra (``pip install -e ".[brax]"``: brax 0.14.2, which runs on the
pinned jax 0.9 and not on 0.10, brax#671). The environment is ours (MJX, the reference's
task, algorithm.md §2) behind brax's ``Env`` interface, flat: the observation is the N
agents' 19 values each, ``[N * 19]``, torso first; the action is one per actuator,
``[N - 1]``, in [-1, 1]. ``done`` is the task's termination only and the state does not
reset itself: brax's wrappers (``brax.envs.training.wrap``: episode length, auto-reset,
vmap) add the time limit and the resets, so brax's training agents run on our robots::

    from brax.training.agents.ppo import train as ppo
    make_policy, params, metrics = ppo.train(environment=BraxEnv("hopper_3"), ...)

Domain randomisation through brax's ``randomization_fn`` is not supported: it replaces a
``PipelineEnv``'s ``sys``, and our physics closes over its MJX model.
"""

import jax.numpy as jnp
from brax.envs.base import Env, State

from solar_jax.config import EnvConfig
from solar_jax.env.physics import make_world_fns
from solar_jax.env.world import OBS_SIZE, build_world
from solar_jax.morphology import Morphology, load


class BraxEnv(Env):
    """One robot (a registered name, an MJCF path or a ``Morphology``) as a brax ``Env``;
    ``config``'s physics settings apply (its ``max_episode_steps`` does not: brax's
    ``EpisodeWrapper`` sets the episode length)."""

    def __init__(self, morph: Morphology | str = "hopper_3", config: EnvConfig | None = None):
        self.morph = load(morph) if isinstance(morph, str) else morph
        n = self.morph.num_agents
        self._fns = make_world_fns(build_world((self.morph,), n), config or EnvConfig(), False)

    def reset(self, rng) -> State:
        world = self._fns.reset(rng)
        zero = jnp.zeros((), jnp.float32)
        return State(world, world.obs[0].reshape(-1), zero, zero)

    def step(self, state: State, action) -> State:
        torso = jnp.zeros((1,), action.dtype)  # the physics ignores the torso's action
        world, out = self._fns.step(state.pipeline_state, jnp.concatenate([torso, action])[None])
        done = (out.terminated[0] | out.nonfinite[0]).astype(jnp.float32)
        return state.replace(
            pipeline_state=world, obs=out.next_obs[0].reshape(-1), reward=out.reward[0], done=done
        )

    @property
    def observation_size(self) -> int:
        return self.morph.num_agents * OBS_SIZE

    @property
    def action_size(self) -> int:
        return self.morph.num_actuators

    @property
    def backend(self) -> str:
        return "mjx"

    @property
    def dt(self) -> float:
        return self.morph.dt
