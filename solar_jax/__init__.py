"""solar_jax: SOLAR (low-rank modular RL via muscle synergy) on JAX and MJX.

Data flows one way: morphology -> env -> replay -> agent and synergy -> trainer.
"""

__version__ = "0.1.0"
