#!/usr/bin/env python3
"""The book's simple_navig_goals.py pattern, unchanged in spirit: one goal through SimpleActionClient.

Usage: simple_navig_goals.py X Y   (goal in the map frame, orientation w = 1)
Exit status 0 when move_base reports SUCCEEDED.
"""
import sys

import actionlib
import rospy
from actionlib_msgs.msg import GoalStatus
from move_base_msgs.msg import MoveBaseAction, MoveBaseGoal


def main():
    rospy.init_node("simple_navig_goals")
    x, y = float(sys.argv[1]), float(sys.argv[2])
    ac = actionlib.SimpleActionClient("move_base", MoveBaseAction)
    while not ac.wait_for_server(rospy.Duration.from_sec(5.0)):
        rospy.loginfo("Waiting for the move_base action server to come up")
    goal = MoveBaseGoal()
    goal.target_pose.header.frame_id = "map"
    goal.target_pose.header.stamp = rospy.Time.now()
    goal.target_pose.pose.position.x = x
    goal.target_pose.pose.position.y = y
    goal.target_pose.pose.orientation.w = 1.0
    rospy.loginfo("Sending goal")
    ac.send_goal(goal)
    ac.wait_for_result(rospy.Duration(120))
    if ac.get_state() == GoalStatus.SUCCEEDED:
        rospy.loginfo("You have reached the destination")
        return 0
    rospy.loginfo("The robot failed to reach the destination")
    return 1


if __name__ == "__main__":
    sys.exit(main())
