"""Run directories saved by earlier versions: keys added since resume at the value the run
ran with, keys removed since resume only at the value the code still runs."""

import json

import pytest

from solar_jax.config import ConfigError, TrainConfig, config_to_dict
from solar_jax.training.rundir import check_same_run, saved_config


def _old_run(tmp_path, **env) -> tuple:
    """A run directory whose config predates ``env.layout`` (physics as a model per robot)
    and holds ``env``'s keys besides."""
    config = config_to_dict(TrainConfig(morph="hopper++"))
    del config["env"]["layout"]
    config["env"].update(env)
    (tmp_path / "config.json").write_text(json.dumps({"config": config}))
    return tmp_path, config


def test_a_run_from_before_the_union_resumes_as_a_model_per_robot(tmp_path):
    run_dir, saved = _old_run(tmp_path, robots_per_world=1)
    config = saved_config(run_dir)
    assert config.env.layout == "per_robot" and config.morph == "hopper++"
    check_same_run(run_dir, config, saved)  # the checkpoint's copy reads the same
    with pytest.raises(ConfigError, match="env.layout 'union' \\(checkpoint: 'per_robot'\\)"):
        check_same_run(run_dir, TrainConfig(morph="hopper++"), saved)


def test_a_run_of_merged_worlds_cannot_resume(tmp_path):
    run_dir, _ = _old_run(tmp_path, robots_per_world=3)
    with pytest.raises(ConfigError, match="env.robots_per_world=3 is no longer built"):
        saved_config(run_dir)
