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


def test_read_encoder_range_from_params() -> None:
    import pytest

    from chefbot_bringup.encoder import INT16_RANGE, read_encoder_range
    from chefbot_common.params import ParamError

    def getter(d):
        return lambda name, default: d.get(name, default)

    r = read_encoder_range(getter({}), INT16_RANGE)
    assert (r.encoder_min, r.encoder_max) == INT16_RANGE
    r = read_encoder_range(getter({"~encoder_min": -100, "encoder_max": 100, "wheel_low_wrap": -50}))
    assert (r.encoder_min, r.encoder_max, r.low_wrap) == (-100, 100, -50)
    assert read_encoder_range(getter({"encoder_min": 0, "~encoder_min": 5, "encoder_max": 10})).encoder_min == 0
    with pytest.raises(ParamError, match="encoder_max"):
        read_encoder_range(getter({"encoder_max": "big"}))
    with pytest.raises(ParamError, match="must be greater"):
        read_encoder_range(getter({"encoder_min": 10, "encoder_max": 0}))
