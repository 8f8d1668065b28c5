"""Key -> velocity logic of keyboard_teleop."""
import pytest

from chefbot_bringup.teleop import HELP, KeyTeleop, TeleopConfig


def make(**kw) -> KeyTeleop:
    return KeyTeleop(TeleopConfig(**kw))


@pytest.mark.parametrize("key,sign", [("i", (1, 0)), ("w", (1, 0)), (",", (-1, 0)), ("x", (-1, 0)),
                                      ("j", (0, 1)), ("a", (0, 1)), ("l", (0, -1)), ("d", (0, -1)),
                                      ("u", (1, 1)), ("o", (1, -1))])
def test_move_keys(key, sign):
    tel = make(linear_speed=0.2, angular_speed=1.0)
    assert tel.press(key, 0.0)
    assert tel.poll(0.0) == pytest.approx((0.2 * sign[0], 1.0 * sign[1]))


def test_repeats_at_rate_then_zero_once_after_timeout():
    tel = make(key_timeout=0.7, rate=10.0)
    tel.press("i", 0.0)
    sent = [(round(t * 100) / 100, tel.poll(t)) for t in [k * 0.05 for k in range(40)]]
    moving = [t for t, c in sent if c and c[0] > 0]
    zeros = [t for t, c in sent if c == (0.0, 0.0)]
    assert moving[0] == 0.0 and len(moving) == 7      # 0.0 .. 0.6 every 0.1 s
    assert zeros == [0.7]


def test_key_repeat_keeps_it_going():
    tel = make(key_timeout=0.7)
    for k in range(20):
        tel.press("i", k * 0.04)
        tel.poll(k * 0.04)
    # Last key at 0.76 s: still driving at 1.4 s, stopped at 1.46 s.
    assert tel.poll(1.4) == pytest.approx((0.2, 0.0))
    assert tel.poll(1.47) == (0.0, 0.0)


def test_stop_key_sends_zero_once():
    tel = make()
    tel.press("i", 0.0)
    tel.poll(0.0)
    tel.press(" ", 0.1)
    assert tel.poll(0.1) == (0.0, 0.0)
    assert tel.poll(0.2) is None
    assert tel.poll(5.0) is None


def test_idle_sends_nothing():
    tel = make()
    assert tel.poll(0.0) is None and tel.poll(10.0) is None


def test_speed_limits():
    tel = make(linear_speed=0.3, max_linear=0.35, angular_speed=1.0, max_angular=1.2)
    for _ in range(10):
        tel.press("q", 0.0)
    assert tel.linear_speed == pytest.approx(0.35)
    assert tel.angular_speed == pytest.approx(1.2)
    tel.press("z", 0.0)
    assert tel.linear_speed < 0.35


def test_quit_and_unknown():
    tel = make()
    assert not tel.press("?", 0.0)
    assert tel.press("\x03", 0.0) and tel.quit


def test_next_deadline_bounded():
    tel = make(key_timeout=0.7, rate=10.0)
    assert tel.next_deadline(0.0) == 1.0
    tel.press("i", 0.0)
    tel.poll(0.0)
    assert tel.next_deadline(0.0) == pytest.approx(0.1)


def test_help_mentions_layout():
    assert "i" in HELP and "Ctrl-C" in HELP


def test_bad_config():
    with pytest.raises(ValueError, match="linear_speed"):
        TeleopConfig(linear_speed=1.0, max_linear=0.5)
