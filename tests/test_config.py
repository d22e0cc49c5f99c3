"""The configuration leaf (``solar_jax.config``): what it declares agrees with the modules
that read it, without importing them (``tests/test_layers.py`` checks the imports)."""

import dataclasses

import pytest

from solar_jax.agent import Hyper
from solar_jax.config import (
    METHODS,
    TD3_TRACED,
    NetworkConfig,
    TD3Config,
    TrainConfig,
    config_from_dict,
    config_to_dict,
)
from solar_jax.networks import registry


def test_the_config_names_exactly_the_registered_methods():
    assert METHODS == registry.METHODS
    with pytest.raises(ValueError, match="method=ppo: expected one of solar, solar_no_pref"):
        TrainConfig(method="ppo")


def test_traced_td3_fields_are_the_learning_rates_and_hyper():
    hyper = {field.name for field in dataclasses.fields(Hyper)}
    assert set(TD3_TRACED) == {"lr", "synergy_lr"} | hyper
    static = {f.name for f in dataclasses.fields(TD3Config)} - set(TD3_TRACED)
    assert {"grad_clip", "batch_size", "policy_delay", "action_penalty"} <= static
    values = Hyper.from_config(TD3Config(tau=0.5, noise_clip=0.25))
    assert float(values.tau) == 0.5 and float(values.noise_clip) == 0.25


def test_a_preset_is_resolved_once_and_survives_a_round_trip():
    tiny = TrainConfig(net="tiny")
    assert tiny.network == NetworkConfig.tiny()
    assert TrainConfig().network == NetworkConfig()  # net=default
    wide = TrainConfig(net="tiny", network=NetworkConfig.tiny(width=32))
    assert wide.network.width == 32  # a given network is kept
    assert config_from_dict(TrainConfig, config_to_dict(wide)) == wide
    with pytest.raises(ValueError, match="net=huge: expected one of default, small, tiny"):
        TrainConfig(net="huge")
    with pytest.raises(ValueError, match="net=huge"):
        TrainConfig(net="huge", network=NetworkConfig.tiny())
