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
