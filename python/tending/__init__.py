"""tending: the machine-tending scenario of the SMAPPO paper as a fast Rust simulator.

- :func:`parallel_env`: a PettingZoo ``ParallelEnv`` (agents ``robot_0``.., ``Discrete(5)``
  actions, observations as a ``gymnasium.spaces.Dict`` of per-group arrays or a padded flat
  vector), with live add/remove of robots, machines and storage areas between steps.
- :func:`vector_env`: N environments stepped in Rust in one call, numpy in and out.
- :class:`SimError` (a ``ValueError``): the simulator refused an input.
"""

from ._native import N_ACTIONS, SimError, episode_seed, num_threads
from .env import TendingParallelEnv, parallel_env
from .vector import TendingVectorEnv, vector_env

__all__ = [
    "N_ACTIONS",
    "SimError",
    "TendingParallelEnv",
    "TendingVectorEnv",
    "episode_seed",
    "num_threads",
    "parallel_env",
    "vector_env",
]
