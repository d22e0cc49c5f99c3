import os

import pytest

import solar_jax
from solar_jax import XLA_DISABLED_PASSES, YNN_FUSIONS, xla_flags


def test_importing_the_package_set_its_xla_flags():
    flags = os.environ["XLA_FLAGS"]
    assert XLA_DISABLED_PASSES.split("=")[0] in flags  # the test session's flags beside them
    assert xla_flags(flags, solar_jax._jaxlib) == flags  # nothing left to add


@pytest.mark.parametrize(
    ("version", "ynn"), [("0.9.2", False), ("0.10.2", True), ("0.11.0", True), ("custom", True)]
)
def test_jaxlib_0_10_and_later_run_without_ynnpack_fusions(version, ynn):
    assert xla_flags("", version).split() == [XLA_DISABLED_PASSES, *([YNN_FUSIONS] if ynn else [])]


def test_a_user_s_own_xla_settings_are_kept():
    mine = "--xla_cpu_experimental_ynn_fusion_type=dot --xla_disable_hlo_passes=foo"
    assert xla_flags(mine, "0.10.2") == mine
    assert xla_flags("--xla_foo=1", "0.10.2").split() == [
        "--xla_foo=1",
        XLA_DISABLED_PASSES,
        YNN_FUSIONS,
    ]
