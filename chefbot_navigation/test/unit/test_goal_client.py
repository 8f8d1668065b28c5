"""GoalClient: SimpleActionClient's API without the race in its send_goal.

The fake action client answers inside ``send_goal``, before it returns the handle: the timing of
a server that accepts and finishes (or rejects) a goal at once, which SimpleActionClient drops."""
from __future__ import annotations

import actionlib
import actionlib.simple_action_client
import pytest
from actionlib_msgs.msg import GoalStatus
from move_base_msgs.msg import MoveBaseAction, MoveBaseGoal

from chefbot_navigation.ros_util import GoalClient

CommState = actionlib.CommState


class Handle:
    """The parts of actionlib's ClientGoalHandle that SimpleActionClient uses."""

    def __init__(self, key: int) -> None:
        self.key, self.comm, self.status = key, CommState.WAITING_FOR_GOAL_ACK, GoalStatus.PENDING

    def __eq__(self, other) -> bool:
        return isinstance(other, Handle) and other.key == self.key

    __hash__ = None

    def wrapper(self) -> Handle:
        h = Handle(self.key)
        h.comm, h.status = self.comm, self.status
        return h

    def get_comm_state(self):
        return self.comm

    def get_goal_status(self):
        return self.status

    def get_result(self):
        return None

    def get_goal_status_text(self):
        return ""


class AnswersAtOnce:
    """Stands in for actionlib.ActionClient: calls back before send_goal returns."""

    ns = "move_base"

    def __init__(self, answer: list[tuple[int, int]]) -> None:
        self.answer, self.sent = answer, []

    def send_goal(self, goal, transition_cb, feedback_cb):
        gh = Handle(len(self.sent))
        self.sent.append((gh, transition_cb))
        for comm, status in self.answer:
            gh.comm, gh.status = comm, status
            transition_cb(gh.wrapper())   # a new wrapper of the same goal, as actionlib passes
        return gh


def make(cls, monkeypatch, answer: list[tuple[int, int]]):
    """A client of ``cls`` whose ActionClient is the fake (no master needed)."""
    fake = AnswersAtOnce(answer)
    monkeypatch.setattr(actionlib.simple_action_client, "ActionClient", lambda _ns, _spec: fake)
    return cls("move_base", MoveBaseAction), fake


@pytest.mark.parametrize("cls", [GoalClient, actionlib.SimpleActionClient])
def test_a_goal_rejected_at_once_reaches_done_cb(cls, monkeypatch) -> None:
    client, _ = make(cls, monkeypatch, [(CommState.DONE, GoalStatus.REJECTED)])
    done = []
    client.send_goal(MoveBaseGoal(), done_cb=lambda status, _result: done.append(status))
    if cls is actionlib.SimpleActionClient:   # the race this class exists for
        assert done == [] and client.simple_state != actionlib.SimpleGoalState.DONE
        return
    assert done == [GoalStatus.REJECTED]
    assert client.simple_state == actionlib.SimpleGoalState.DONE
    assert client.get_state() == GoalStatus.REJECTED


def test_active_then_done_in_order_and_late_callbacks_of_an_old_goal_are_ignored(monkeypatch) -> None:
    client, fake = make(GoalClient, monkeypatch, [(CommState.ACTIVE, GoalStatus.ACTIVE)])
    events = []
    client.send_goal(MoveBaseGoal(), done_cb=lambda s, _r: events.append(("done 1", s)),
                     active_cb=lambda: events.append("active 1"))
    assert events == ["active 1"] and client.simple_state == actionlib.SimpleGoalState.ACTIVE
    client.send_goal(MoveBaseGoal(), done_cb=lambda s, _r: events.append(("done 2", s)),
                     active_cb=lambda: events.append("active 2"))
    old_gh, old_cb = fake.sent[0]
    old_gh.comm, old_gh.status = CommState.DONE, GoalStatus.PREEMPTED
    old_cb(old_gh)                 # the first goal's result arrives after the second was sent
    assert events == ["active 1", "active 2"]
    new_gh, new_cb = fake.sent[1]
    new_gh.comm, new_gh.status = CommState.DONE, GoalStatus.SUCCEEDED
    new_cb(new_gh)
    assert events == ["active 1", "active 2", ("done 2", GoalStatus.SUCCEEDED)]


def test_done_cb_may_send_the_next_goal(monkeypatch) -> None:
    client, _ = make(GoalClient, monkeypatch, [(CommState.DONE, GoalStatus.SUCCEEDED)])
    done = []

    def chain(status, _result) -> None:
        done.append(status)
        if len(done) < 3:
            client.send_goal(MoveBaseGoal(), done_cb=chain)

    client.send_goal(MoveBaseGoal(), done_cb=chain)
    assert done == [GoalStatus.SUCCEEDED] * 3


class _Connections:
    def __init__(self, n: int) -> None:
        self.n = n

    def get_num_connections(self) -> int:
        return self.n


class _Seen:
    """A SimpleActionClient whose ActionClient has seen the server's status and goal subscriber."""

    def __init__(self) -> None:
        self.action_client = type("AC", (), {})()
        self.action_client.last_status_msg = object()
        self.action_client.pub_goal = _Connections(1)


def test_wait_for_action_server_waits_for_the_clock(monkeypatch) -> None:
    # a sim-time node before its first /clock: ROS time 0; a goal stamped 0 is cancelled by the
    # server as older than its current one, so the wait must not end before the clock runs
    import rospy

    from chefbot_navigation.ros_util import wait_for_action_server

    monkeypatch.setattr(rospy, "is_shutdown", lambda: False)
    now = [rospy.Time(0)]
    monkeypatch.setattr(rospy, "get_rostime", lambda: now[0])
    assert not wait_for_action_server(_Seen(), 0.2)
    now[0] = rospy.Time(12, 5)
    assert wait_for_action_server(_Seen(), 0.2)
    seen = _Seen()
    seen.action_client.pub_goal = _Connections(0)       # the server does not subscribe to goals yet
    assert not wait_for_action_server(seen, 0.2)
