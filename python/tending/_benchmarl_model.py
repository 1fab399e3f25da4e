"""What tending's two BenchMARL models (:mod:`tending.benchmarl_rust`,
:mod:`tending.benchmarl_smappo`) share. It imports nothing, so BenchMARL stays an import of
the modules that need it (``import tending`` never imports it)."""

from __future__ import annotations

# The keyword arguments of ``benchmarl.models.common.Model.__init__``: BenchMARL's
# ``ModelConfig.get_model`` passes them to every model beside its config's own fields.
MODEL_ARGS = (
    "input_spec", "output_spec", "agent_group", "input_has_agent_dim", "n_agents",
    "centralised", "share_params", "device", "action_spec", "model_index", "is_critic",
)


def model_args(kwargs: dict) -> dict:
    """Take BenchMARL's ``Model`` arguments out of a model's ``**kwargs``, for
    ``super().__init__(**model_args(kwargs))``; a missing one is a ``KeyError``."""
    return {name: kwargs.pop(name) for name in MODEL_ARGS}
