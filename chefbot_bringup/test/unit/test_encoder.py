"""TickUnwrapper over Int16 and Int32 ranges."""
import pytest

from chefbot_bringup.encoder import (
    INT16_RANGE,
    INT32_RANGE,
    EncoderRange,
    TickUnwrapper,
)


@pytest.mark.parametrize("lo,hi", [INT16_RANGE, INT32_RANGE, (-32768, 32768)])
@pytest.mark.parametrize("step", [997, -997])
def test_unwrap_follows_true_position(lo, hi, step):
    rng = EncoderRange(lo, hi)
    span = rng.span
    un = TickUnwrapper(rng)
    start = hi - 5000 if step > 0 else lo + 5000
    true = start
    for _ in range(200):
        raw = (true - lo) % span + lo
        assert un.update(raw) == true
        true += step


def test_default_wrap_thresholds_as_in_book():
    rng = EncoderRange(-32768, 32768)
    assert rng.low_wrap == pytest.approx(-32768 + 0.3 * 65536)
    assert rng.high_wrap == pytest.approx(-32768 + 0.7 * 65536)


def test_bad_range_rejected():
    with pytest.raises(ValueError, match="encoder_max"):
        EncoderRange(10, 10)
