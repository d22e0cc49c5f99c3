"""TD3 for every method (algorithm.md §5): state, losses and one update iteration.

Written for one morphology's padded batch; the fused update vmaps the losses over a
stacked batch of several morphologies. Replay, rounds and synergy discovery are the
trainer's (``solar_jax.training.trainer``).
"""

from solar_jax.agent.losses import Losses, make_losses
from solar_jax.agent.state import AgentState, Hyper, make_optimizers, with_learning_rates
from solar_jax.agent.update import TD3, make_td3

__all__ = [
    "TD3",
    "AgentState",
    "Hyper",
    "Losses",
    "make_losses",
    "make_optimizers",
    "make_td3",
    "with_learning_rates",
]
