"""ROS 1 adapters. The only subpackage allowed to import rospy, actionlib or generated messages."""
