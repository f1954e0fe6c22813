"""simcore.constants holds scipy.constants' values to the last bit, so results do not change."""

import math

import pytest
from scipy import constants as sc

from simcore import constants


@pytest.mark.parametrize(("ours", "theirs"), [("C", "c"), ("Q_E", "e"), ("H", "h"), ("K_B", "k")])
def test_each_constant_is_scipys_to_the_last_bit(ours, theirs):
    value = getattr(constants, ours)
    assert type(value) is float
    assert value.hex() == float(getattr(sc, theirs)).hex()


def test_the_constants_are_the_exact_si_2019_values():
    assert constants.C == 299_792_458.0
    assert constants.Q_E == 1.602176634e-19
    assert constants.H == 6.62607015e-34
    assert constants.K_B == 1.380649e-23
    assert math.isclose(constants.H * constants.C / constants.Q_E, 1.239841984e-6, rel_tol=1e-9)
